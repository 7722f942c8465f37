"""``blendshape-studio batch`` on Dask (issue 21): twelve takes made from the shared ones on a local cluster of two
workers, each solved exactly as ``solve`` solves it; a truncated take reported, not fatal; a second run solves
nothing; a worker killed mid-run changes nothing; a separate scheduler and worker (``--scheduler``).

Takes are short (60-90 frames, one full shared take) to keep the run modest on a 2-core CI machine.
"""
from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.cli_runner import command, run_cli

pytestmark = pytest.mark.data

if not os.environ.get("CI"):      # the [batch] extra; CI installs it with [test], so there it must be present
    pytest.importorskip("distributed")


def _rotation_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


@pytest.fixture(scope="module")
def takes(tmp_path_factory, take_dir):
    """The shared ICT take as it is, ten variations of the ICT and actor takes (trimmed, offset, rotated,
    resampled, in other units and formats) and one truncated C3D: 12 files, 11 of them solvable."""
    from model.take_c3d import write_c3d
    from model.take_csv import write_marker_csv
    from model.takes import MarkerTake, load_take
    d = tmp_path_factory.mktemp("takes")
    ict = load_take(take_dir / "take.c3d")
    actor = load_take(take_dir.parent / "actor_take" / "take.c3d")

    def take(src, positions, rate=None, units=None):
        return MarkerTake(positions, src.labels, rate or src.rate, units or src.units)

    made = {
        "ict_trim.c3d": take(ict, ict.positions[:90]),
        "ict_late.c3d": take(ict, np.concatenate([ict.positions[:30], ict.positions[150:210]])),
        "ict_offset.csv": take(ict, ict.positions[:80] + [40.0, -15.0, 5.0]),
        "ict_half_rate.c3d": take(ict, ict.positions[:180:2], rate=ict.rate / 2),
        "ict_turned.c3d": take(ict, ict.positions[:80] @ _rotation_y(12).T),
        "ict_cm.c3d": take(ict, ict.positions[:70] / 10.0, units="cm"),
        "actor_trim.c3d": take(actor, actor.positions[:90]),
        "actor_offset.csv": take(actor, actor.positions[:80] + [0.0, 20.0, -30.0]),
        "actor_half_rate.c3d": take(actor, actor.positions[:160:2], rate=actor.rate / 2),
        "actor_late.c3d": take(actor, np.concatenate([actor.positions[:30], actor.positions[250:300]])),
    }
    paths = [take_dir / "take.c3d"]
    for name, t in made.items():
        p = d / name
        (write_marker_csv if p.suffix == ".csv" else write_c3d)(p, t)
        paths.append(p)
    raw = (d / "ict_trim.c3d").read_bytes()
    (d / "ict_cut.c3d").write_bytes(raw[:3000])     # cut after its first frame: refused as truncated
    paths.append(d / "ict_cut.c3d")
    return paths


@pytest.fixture(scope="module")
def references(takes, ict_rig, take_dir, tmp_path_factory):
    """Each solvable take's weights CSV from the ``solve`` command (run in this process, on the session's rig)."""
    from app import cli, cli_solve
    out = tmp_path_factory.mktemp("solve")
    mp = pytest.MonkeyPatch()
    mp.setattr(cli_solve, "load_rig_arg", lambda args: copy.deepcopy(ict_rig))
    refs = {}
    try:
        for p in takes[:-1]:
            csv = out / f"{p.parent.name}_{p.name}.csv"
            assert cli.main(["solve", str(take_dir.parent.parent / "ict-facekit"), str(p), "--map",
                             str(take_dir / "marker_map.json"), "-o", str(csv)]) == 0
            refs[p] = csv.read_bytes()
    finally:
        mp.undo()
    return refs


def _batch(ict_dir, take_dir, takes, out, *extra, check=False, **kw):
    return run_cli("batch", ict_dir, *takes, "--map", take_dir / "marker_map.json", "-o", out, *extra,
                   check=check, **kw)


def _summary(out: Path) -> dict:
    return {r["take"]: r for r in json.loads((out / "batch.json").read_text())["takes"]}


def _names(takes) -> list[str]:
    from model.batch import take_names
    return take_names(takes)


def test_take_names_tell_takes_apart(tmp_path):
    from model.batch import find_takes, take_names
    a, b = tmp_path / "day1" / "actor" / "take.c3d", tmp_path / "day1" / "other" / "take.c3d"
    c = tmp_path / "day1" / "actor" / "take.trc"
    for p in (a, b, c):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"x")
    assert take_names([a, b]) == ["actor_take", "other_take"]
    assert take_names([a, c]) == ["take_c3d", "take_trc"]
    assert take_names([tmp_path / "x.c3d"]) == ["x"]
    # folders, globs and files, each take once, in the order given
    assert find_takes([str(a.parent), str(tmp_path / "day1" / "*" / "*.c3d")]) == [a, c, b]
    # a batch's own outputs are never taken for takes
    (tmp_path / "day1" / "out" / "take").mkdir(parents=True)
    (tmp_path / "day1" / "out" / "take" / "weights.csv").write_text("frame,time\n")
    assert find_takes([str(tmp_path / "day1" / "**" / "*.c3d"), str(tmp_path / "day1" / "**" / "*.csv")],
                      exclude=tmp_path / "day1" / "out") == [a, b]
    from model.errors import RigInputError
    with pytest.raises(RigInputError, match="matches no take"):
        find_takes([str(tmp_path / "*.nothing")])


def test_a_take_named_in_the_output_folder_is_solved_and_a_batchs_own_output_named_is_said_to_be_left_out(
        tmp_path):
    """A take named by its file inside the batch's output folder was left out of the solve without a word (the
    folder's files are left out so that a batch's own outputs are not read as takes). A take file named is solved;
    what a folder or a pattern finds there is still left out; a batch's own output named as a take (the summary, a
    take's weights CSV: a shell's expansion of day1/**/*.csv names them) is left out and said so, in one sentence."""
    from model.batch import find_takes
    out = tmp_path / "out"
    (out / "take01").mkdir(parents=True)
    inside, outside = out / "extra.csv", tmp_path / "take02.csv"
    for p in (inside, outside, out / "take01" / "weights.csv", out / "batch.csv", out / "take01" / "notes.csv"):
        p.write_text("frame,raise\n0,0.5\n")
    notes: list[str] = []
    assert find_takes([str(inside), str(outside)], exclude=out, notes=notes) == [inside, outside] and notes == []
    assert find_takes([str(out), str(out / "**" / "*.csv"), str(outside)], exclude=out, notes=notes) == [outside]
    assert notes == []
    given = [str(out / "batch.csv"), str(out / "take01" / "weights.csv"), str(out / "take01" / "notes.csv"),
             str(outside)]
    assert find_takes(given, exclude=out, notes=notes) == [out / "take01" / "notes.csv", outside]
    assert notes == [f"{out / 'batch.csv'} and 1 more file given: are a batch's own outputs in the output folder "
                     f"{out}, not takes to solve; left out (copy them elsewhere to solve them)."]
    notes.clear()
    assert find_takes(given[1:], exclude=out, notes=notes) == [out / "take01" / "notes.csv", outside]
    assert notes == [f"{out / 'take01' / 'weights.csv'}: is a batch's own output in the output folder {out}, not a "
                     "take to solve; left out (copy it elsewhere to solve it)."]


def test_batch_solves_a_take_named_in_its_output_folder(tmp_path):
    """`batch RIG out/take01.csv take02.csv -o out` solved take02 only and said nothing of take01 (and with take01
    alone: "every take given is in the output folder"). Both are solved now; an earlier batch's weights named too
    are left out with a warning saying why."""
    from tests.rig_files import write_rig_folder
    write_rig_folder(tmp_path / "rig")
    out = tmp_path / "out"
    (out / "old").mkdir(parents=True)
    for p in (out / "take01.csv", tmp_path / "take02.csv", out / "old" / "weights.csv"):
        p.write_text("frame,raise\n0,0.5\n1,1\n")
    proc = run_cli("batch", tmp_path / "rig", out / "take01.csv", tmp_path / "take02.csv", out / "old" / "weights.csv",
                   "-o", out, "--workers", "1", check=False)
    assert proc.returncode == 0, proc.stderr
    assert (f"warning: {out / 'old' / 'weights.csv'}: is a batch's own output in the output folder {out}, not a "
            "take to solve; left out (copy it elsewhere to solve it).") in proc.stderr.splitlines(), proc.stderr
    rows = json.loads((out / "batch.json").read_text())["takes"]
    assert [(r["take"], r["status"]) for r in rows] == [("take01", "solved"), ("take02", "solved")]
    assert (out / "take01" / "weights.csv").is_file()
    assert (out / "take01.csv").read_text() == "frame,raise\n0,0.5\n1,1\n"


def test_a_batch_whose_output_folder_holds_every_take_is_refused(tmp_path):
    """`batch RIG day1 -o day1`: every take in day1 was left out as one of the batch's own outputs, and the command
    said "0 take(s)", solved nothing and exited 0. It is one sentence, exit 2, nothing written."""
    from tests.rig_files import write_rig_folder
    write_rig_folder(tmp_path / "rig")
    day = tmp_path / "day1"
    day.mkdir()
    (day / "take.csv").write_text("frame,raise\n0,0.5\n1,1\n")
    proc = run_cli("batch", tmp_path / "rig", day, "-o", day, "--workers", "1", check=False)
    assert (proc.returncode, proc.stdout, proc.stderr) == (
        2, "", f"error: {day}: every take given is in the output folder, where a batch's own outputs are left out; "
               "give -o a folder of its own.\n")
    assert [p.name for p in day.iterdir()] == ["take.csv"]


def test_a_batch_summary_reads_back_as_written_and_anything_else_is_one_sentence(tmp_path, monkeypatch):
    """``read_summary`` (the dialog's Open Results…): what ``write_summary`` wrote comes back row for row, from the
    file or its folder; a file that is not a summary is one sentence naming it; a value that is not a number is
    shown as none; previews are found by the take's name inside the batch's folder only."""
    from model.batch import ROW_KEYS, preview_path, read_summary, write_summary
    from model.errors import RigInputError
    rows = [dict(dict.fromkeys(ROW_KEYS), take="a", status="solved", frames=358, rate=60.0, marker_rmse=0.0334612,
                 motion_explained=0.997, path="/takes/a.c3d", output=str(tmp_path / "out" / "a")),
            dict(dict.fromkeys(ROW_KEYS), take="b", status="failed", error="/takes/b.c3d: the file is truncated.",
                 path="/takes/b.c3d")]
    write_summary(tmp_path / "out", rows, {"rig": "ict-facekit", "rig_units": "cm", "marker_map": "/maps/m.json"})
    for where in (tmp_path / "out", tmp_path / "out" / "batch.json"):
        folder, summary = read_summary(where)
        assert folder == tmp_path / "out" and summary["takes"] == rows
        assert summary["rig"] == "ict-facekit" and summary["rig_units"] == "cm"
    (tmp_path / "out" / "a").mkdir()
    (tmp_path / "out" / "a" / "preview.png").write_bytes(b"png")
    assert preview_path(tmp_path / "out", "a") == tmp_path / "out" / "a" / "preview.png"
    assert preview_path(tmp_path / "out", "b") is None                    # failed: none written
    (tmp_path / "out" / "preview.png").write_bytes(b"png")
    for name in ("..", ".", "", "a/..", "../a"):          # never outside the chosen folder (each names a preview)
        assert preview_path(tmp_path / "out" / "a", name) is None
    # a row's number that is not one is shown as none; the rest of the row stays
    doc = json.loads((tmp_path / "out" / "batch.json").read_text())
    doc["takes"][0].update(marker_rmse="0.03", frames=True, rate=float("nan"), path=7)
    (tmp_path / "odd.json").write_text(json.dumps(doc))
    row = read_summary(tmp_path / "odd.json")[1]["takes"][0]
    assert (row["marker_rmse"], row["frames"], row["rate"], row["path"]) == (None, None, None, None)
    assert row["motion_explained"] == 0.997 and row["take"] == "a"
    bad = {"not JSON": b'{"takes": [1, 2', "not text": b"\xff\xfe\x00", "a list": b"[]",
           "no takes": b'{"rig": "x"}', "takes not a list": b'{"takes": {"a": 1}}',
           "a row without a status": b'{"takes": [{"take": "a"}]}',
           "a status of its own": b'{"takes": [{"take": "a", "status": "done"}]}',
           "deep": b"[" * 100000 + b"]" * 100000, "empty": b""}
    for what, data in bad.items():
        (tmp_path / "bad.json").write_bytes(data)
        with pytest.raises(RigInputError) as info:
            read_summary(tmp_path / "bad.json")
        message = str(info.value)
        assert message.startswith(f"{tmp_path / 'bad.json'}: ") and "\n" not in message, (what, message)
    with pytest.raises(RigInputError, match="does not exist"):
        read_summary(tmp_path / "nowhere")
    import model.batch
    (tmp_path / "big.json").write_bytes(b" " * 3_000_000 + b"{}")          # larger than any summary may be
    monkeypatch.setattr(model.batch, "SUMMARY_MAX_BYTES", 2 << 20)
    with pytest.raises(RigInputError, match=r"big.json: is not a batch summary \(3 MB\)"):
        read_summary(tmp_path / "big.json")


def test_files_dropped_on_the_batch_dialog_are_sorted_by_what_they_are(tmp_path):
    """``sort_dropped``: takes and folders of takes in the order dropped, a .json the marker map, a batch.json or
    a folder holding one the results; anything else, or two maps, one sentence naming the paths."""
    from model.batch import sort_dropped
    from model.errors import RigInputError
    for name in ("a.c3d", "b.TRC", "c.csv", "map.json", "face.obj", "other.json"):
        (tmp_path / name).write_text("x")
    (tmp_path / "takes").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "batch.json").write_text("{}")
    items = sort_dropped([tmp_path / "b.TRC", tmp_path / "takes", tmp_path / "map.json", tmp_path / "a.c3d"])
    assert items.takes == [tmp_path / "b.TRC", tmp_path / "takes", tmp_path / "a.c3d"]
    assert items.marker_map == tmp_path / "map.json" and items.results is None
    assert sort_dropped([tmp_path / "out"]).results == tmp_path / "out"
    summary = tmp_path / "out" / "batch.json"
    assert sort_dropped([summary, tmp_path / "c.csv"]).results == summary
    for paths, says in (([tmp_path / "face.obj"], "is not a take"), ([tmp_path / "nowhere.c3d"], "does not exist"),
                        ([tmp_path / "map.json", tmp_path / "other.json"], "two marker maps"),
                        ([tmp_path / "out", tmp_path / "out" / "batch.json"], "two batch results")):
        with pytest.raises(RigInputError, match=says) as info:
            sort_dropped(paths)
        assert str(info.value).startswith(str(paths[0])), info.value


def test_batch_on_a_local_cluster_matches_solve_resumes_and_survives_a_killed_worker(
        tmp_path, ict_dir, take_dir, takes, references):
    out = tmp_path / "out"
    names = _names(takes)
    assert len(takes) == 12 and len(set(names)) == 12
    proc = _batch(ict_dir, take_dir, takes, out, "--workers", "2", timeout=600)
    assert proc.returncode == 2, proc.stderr                    # one take failed: said on stderr, exit 2
    assert "ict_cut.c3d" in proc.stderr and "truncated" in proc.stderr
    assert "dashboard: http" in proc.stdout
    rows = _summary(out)
    assert set(rows) == set(names)
    for p, name in zip(takes, names):
        r = rows[name]
        if p.name == "ict_cut.c3d":
            assert r["status"] == "failed" and "truncated" in r["error"] and str(p) in r["error"]
            assert not (out / name / "done.json").exists()
            continue
        assert r["status"] == "solved", r
        assert (out / name / "weights.csv").read_bytes() == references[p], f"{name} differs from solve"
        report = json.loads((out / name / "report.json").read_text())
        assert r["frames"] == report["frames"] and r["marker_rmse"] == report["marker_rmse"]
        assert r["rate"] == report["rate"] and r["frames_per_second"] == report["frames_per_second"]
        assert r["error"] is None and r["motion_explained"] == report.get("motion_explained")
        assert (out / name / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert not list((out / name).glob(".*")), "temporaries left behind"
    from tests.image_compare import load_png
    img = load_png(out / "ict_turned" / "preview.png")
    assert img.shape[:2] == (360, 480)
    assert (np.abs(img.astype(int) - img[:, :1].astype(int)).max(axis=2) > 30).mean() > 0.2   # a face on it
    assert rows["ict_half_rate"]["rate"] == 30.0 and rows["ict_half_rate"]["frames"] == 90
    assert names[0] == "take" and rows["take"]["frames"] == 358
    assert rows["ict_cm"]["marker_rmse"] == pytest.approx(rows["ict_trim"]["marker_rmse"], rel=0.5)
    lines = (out / "batch.csv").read_text().splitlines()
    assert lines[0].split(",")[:3] == ["take", "status", "error"] and len(lines) == 13

    # Run again: nothing is solved again; the truncated take (it may have been fixed) is tried and fails again.
    stamps = {n: (out / n / "done.json").stat().st_mtime_ns for n in names if (out / n / "done.json").exists()}
    again = _batch(ict_dir, take_dir, takes, out, "--workers", "2", timeout=300)
    assert again.returncode == 2 and "solved 0, skipped 11 (complete), failed 1" in again.stdout
    rows2 = _summary(out)
    assert sorted(r["status"] for r in rows2.values()) == ["failed"] + ["skipped"] * 11
    assert {n: (out / n / "done.json").stat().st_mtime_ns for n in stamps} == stamps
    assert rows2["ict_trim"]["marker_rmse"] == rows["ict_trim"]["marker_rmse"]

    # --force with a worker killed mid-run: its take goes to another worker and every take still finishes.
    import psutil
    for n in stamps:
        (out / n / "done.json").unlink()      # to see when the forced run completes its first take
    env = dict(os.environ)
    p = subprocess.Popen(command() + ["batch", str(ict_dir), *map(str, takes), "--map", str(take_dir / "marker_map.json"),
                                      "-o", str(out), "--workers", "2", "--force"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 300
        while not any((out / n / "done.json").exists() for n in stamps):
            assert p.poll() is None and time.monotonic() < deadline, "no take finished"
            time.sleep(0.2)
        # the workers: forked from the command's fork server (spawned, where there is no fork server)
        tree = psutil.Process(p.pid).children(recursive=True)
        servers = [c for c in tree if "forkserver" in " ".join(c.cmdline())
                   and "forkserver" not in " ".join(c.parent().cmdline())]
        if sys.platform.startswith("linux"):
            assert len(servers) == 1, "the local cluster's workers are forked from one fork server"
        forked = servers[0].children() if servers else []
        if sys.platform.startswith("linux"):   # beside the workers, the scheduler (model.batch_scheduler) and the
            #                                    driver, which runs the cluster for the command (model.batch_driver)
            assert [c.name() for c in forked].count("dask-scheduler") == 1
            assert [c.name() for c in forked].count("dask-batch") == 1
        workers = ([c for c in forked if c.name() not in ("dask-scheduler", "dask-batch")] if servers else
                   [c for c in tree if "spawn_main" in " ".join(c.cmdline())])
        assert len(workers) == 2
        finished = sum((out / n / "done.json").exists() for n in stamps)
        assert finished < 11, "the run was over before a worker could be killed"
        os.kill(workers[0].pid, signal.SIGKILL)
        stdout, stderr = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 2, stderr
    rows3 = _summary(out)
    assert sorted(r["status"] for r in rows3.values()) == ["failed"] + ["solved"] * 11, stderr
    for path, name in zip(takes[:-1], names[:-1]):
        assert (out / name / "weights.csv").read_bytes() == references[path]


def test_a_take_that_does_not_fit_the_map_fails_alone(tmp_path, ict_rig, take_dir):
    """A map naming markers the take lacks: that take's row says so in one sentence; the job is not stopped."""
    from model.batch import BatchJob, solve_take_file
    from model.marker_map import load_marker_map
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    other = MarkerTake(t.positions[:40], [f"X{i}" for i in range(t.n_markers)], t.rate, t.units)
    write_c3d(tmp_path / "other.c3d", other)
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False}, marker_map=load_marker_map(take_dir / "marker_map.json"))
    row = solve_take_file(job, str(tmp_path / "other.c3d"), str(tmp_path / "out" / "other"))
    assert row["status"] == "failed" and row["output"] is None
    assert row["error"].count(". ") == 0 and "marker" in row["error"], row["error"]
    assert not (tmp_path / "out" / "other").exists()


def test_the_job_sent_to_the_workers_carries_the_deltas_once_and_rebuilds_the_same_evaluator(ict_rig, take_dir):
    """What ``run_batch`` scatters to every worker: the job pickled without the evaluator's matrix (pickled, the
    rig's deltas again), and where it is unpickled -- also after being passed on unused, as Dask's broadcast
    passes it from one worker to the next -- an evaluator bit for bit the one the client would build (which it
    does not: only where a take needs it), reading the received rig's deltas in place (no copy in a worker)."""
    import pickle

    from model.batch import BatchJob
    from model.marker_map import load_marker_map
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False}, marker_map=load_marker_map(take_dir / "marker_map.json"))
    assert "evaluator" not in vars(job)       # not built by the command, which never solves (a studio rig's is GBs)
    built = job.evaluator
    assert built._D.nbytes > ict_rig.deltas.nbytes / 2       # worth leaving out: most of the rig's size again
    data = pickle.dumps(job, protocol=5)
    assert len(data) < ict_rig.deltas.nbytes * 1.1, len(data)
    received = pickle.loads(data)
    passed_on = pickle.loads(pickle.dumps(received, protocol=5))   # before the first worker used it
    for other in (received, passed_on):
        rebuilt = other.evaluator
        assert rebuilt is not built and rebuilt.dtype is built.dtype is np.float64
        arrays = {k: v for k, v in vars(built).items() if isinstance(v, np.ndarray)}
        assert {"_D", "_neutral", "moving_vertices"} <= set(arrays)
        assert np.shares_memory(rebuilt._D, other.rig.deltas) and not np.shares_memory(rebuilt._D, job.rig.deltas)
        for name, array in arrays.items():
            got = getattr(rebuilt, name)
            assert got.dtype == array.dtype and got.shape == array.shape and got.tobytes() == array.tobytes(), name
        assert other.signature == job.signature and other.antagonists == job.antagonists
    assert pickle.loads(pickle.dumps(passed_on, protocol=5)).evaluator._D.tobytes() == built._D.tobytes()


def _wait_for(path: Path, proc: subprocess.Popen, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, f"{path} did not appear within {seconds} s"
        time.sleep(0.2)


def test_the_job_carries_the_take_solvers_preparation_and_a_workers_first_take_uses_it(tmp_path, ict_rig,
                                                                                       take_dir, monkeypatch):
    """The residual's preparation (phantom ring, kernel matrix) is made once with the job and scattered with it: a
    worker's first take of a take with every marker of the map makes none and writes the same weights, byte for
    byte, as a take that made its own; a take with a marker missing in most frames (left out) makes its own (other
    marker points)."""
    import pickle

    import solvers.take_solve
    from model.batch import BatchJob, solve_take_file
    from model.marker_map import load_marker_map
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    settings = {"mode": "global", "residual": None, "calibration_frames": 30, "fixed_head": False}
    mm = load_marker_map(take_dir / "marker_map.json")
    job = BatchJob.prepare(ict_rig, settings, marker_map=mm)
    assert len(job.solver_prep) == 1
    made = []
    real = solvers.take_solve.phantom_points
    monkeypatch.setattr(solvers.take_solve, "phantom_points", lambda *a: made.append(1) or real(*a))
    received = pickle.loads(pickle.dumps(job, protocol=5))            # as a worker receives it
    row = solve_take_file(received, str(take_dir / "take.c3d"), str(tmp_path / "with"))
    assert row["status"] == "solved" and not made and len(received.prepared) == 1
    own = pickle.loads(pickle.dumps(BatchJob.prepare(ict_rig, settings, marker_map=mm), protocol=5))
    own.solver_prep = None                                            # as before: the first take makes it
    made.clear()
    solve_take_file(own, str(take_dir / "take.c3d"), str(tmp_path / "own"))
    assert made == [1]
    assert (tmp_path / "with" / "weights.csv").read_bytes() == (tmp_path / "own" / "weights.csv").read_bytes()
    t = load_take(take_dir / "take.c3d")
    positions = t.positions.copy()
    positions[: 2 * t.n_frames // 3, t.labels.index(mm.labels[0])] = np.nan     # left out: missing in most frames
    write_c3d(tmp_path / "lacking.c3d", MarkerTake(positions, t.labels, t.rate, t.units))
    row = solve_take_file(received, str(tmp_path / "lacking.c3d"), str(tmp_path / "lacking"))
    assert row["status"] == "solved", row["error"]
    assert made == [1, 1] and len(received.prepared) == 2


def test_batch_against_a_separate_scheduler_and_worker(tmp_path, ict_dir, take_dir, takes, references):
    """``dask scheduler`` and ``dask worker`` as their own processes on 127.0.0.1; ``batch --scheduler`` uses them."""
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen([str(Path(sys.executable).parent / "dask"), "scheduler", "--host", "127.0.0.1",
                                       "--port", "0", "--no-dashboard", "--scheduler-file", str(sched_file)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                      cwd=tmp_path))
        _wait_for(sched_file, procs[0], 60)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen([str(Path(sys.executable).parent / "dask"), "worker", address,
                                       "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard", "--death-timeout", "60"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path))
        out = tmp_path / "out"
        chosen = [takes[1], takes[7]]
        proc = _batch(ict_dir, take_dir, chosen, out, "--scheduler", address, timeout=300)
        assert proc.returncode == 0, proc.stderr
        rows = _summary(out)
        for p, name in zip(chosen, _names(chosen)):
            assert rows[name]["status"] == "solved"
            assert (out / name / "weights.csv").read_bytes() == references[p]
    finally:
        for pr in reversed(procs):
            if pr.poll() is None:
                pr.terminate()
                try:
                    pr.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    pr.kill()
                    pr.wait()


def test_batch_says_when_no_scheduler_answers(tmp_path, ict_dir, take_dir, takes):
    import socket
    with socket.socket() as s:      # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = _batch(ict_dir, take_dir, [takes[1]], tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}",
                  env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "3s"}, timeout=120)
    assert proc.returncode == 2
    assert "--scheduler" in proc.stderr and proc.stderr.count("\n") == 1


def test_a_map_that_does_not_fit_the_rig_stops_the_batch_before_any_take_in_one_sentence(tmp_path, ict_dir, take_dir,
                                                                                          takes):
    """A marker map bound to a vertex the rig does not have fits no take: the command says so in one sentence naming
    the map before it starts a cluster (the job's solver preparation binds the map), exit 2, and writes nothing."""
    doc = json.loads((take_dir / "marker_map.json").read_text())
    label = next(iter(doc["markers"]))
    doc["markers"][label] = 10 ** 6
    bad = tmp_path / "map.json"
    bad.write_text(json.dumps(doc))
    proc = run_cli("batch", ict_dir, takes[1], "--map", bad, "-o", tmp_path / "out", "--workers", "1", check=False,
                   timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and str(bad) in proc.stderr and label in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and "take(s)" not in proc.stdout
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_ctrl_c_stops_a_batch_without_tracebacks_and_leaves_no_process(tmp_path, ict_dir, take_dir, takes):
    """Ctrl-C in a terminal sends SIGINT to the command's whole process group: the command closes the cluster, writes
    the summary of what was done and says 'interrupted' (exit 130); the workers and the scheduler forked from the fork server print nothing (they each
    printed a KeyboardInterrupt traceback), and no process of the batch is left running."""
    import psutil
    out = tmp_path / "out"
    p = subprocess.Popen(command() + ["batch", str(ict_dir), *map(str, takes[:-1]), "--map",
                                      str(take_dir / "marker_map.json"), "-o", str(out), "--workers", "2"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not list(out.glob("*/done.json")):
            assert p.poll() is None and time.monotonic() < deadline, "no take finished"
            time.sleep(0.1)
        group = [c for c in psutil.Process(p.pid).children(recursive=True)]
        assert len(group) >= 4          # the fork server, the scheduler, two workers (and Python's resource tracker)
        os.killpg(p.pid, signal.SIGINT)
        stdout, stderr = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
    assert p.returncode == 130 and "interrupted" in stderr, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    gone, alive = psutil.wait_procs(group, timeout=10)
    assert not alive, [c.cmdline() for c in alive]
    # the summary says what was done: every complete take solved, every other one interrupted, nothing else
    rows = {r["take"]: r for r in json.loads((out / "batch.json").read_text())["takes"]}
    assert len(rows) == len(takes) - 1
    complete = {d.parent.name for d in out.glob("*/done.json")}
    assert complete and {t for t, r in rows.items() if r["status"] == "solved"} == complete, rows
    for take, r in rows.items():
        if take not in complete:
            assert r["status"] == "failed" and r["error"].endswith("interrupted before it was solved."), r
    assert len((out / "batch.csv").read_text().splitlines()) == len(takes)


def test_a_killed_writers_leftovers_are_removed_by_the_next_write(tmp_path, ict_rig, take_dir):
    """A worker killed while writing a take leaves its temporaries in OUTDIR/<take>/ (or, from earlier versions, a
    private folder); the next writer of that take removes them (their process is gone) and leaves a live writer's
    alone. The take's files are written straight into their temporaries, each once: none is left afterwards."""
    from model.atomic import TEMP_MARK
    from model.batch import BatchJob, solve_take_file
    from model.marker_map import load_marker_map
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    out = tmp_path / "out" / "take"
    stale = out / f".bs-batch-{gone.pid}-x1"
    live = out / f".bs-batch-{os.getppid()}-x2"
    for d in (stale, live):
        d.mkdir(parents=True)
        (d / "weights.csv").write_text("half a file")
    stale_file = out / f".weights.csv{TEMP_MARK}{gone.pid}.ab12cd34.csv"
    live_file = out / f".preview.png{TEMP_MARK}{os.getppid()}.ab12cd34.png"
    for f in (stale_file, live_file):
        f.write_text("half a file")
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False}, marker_map=load_marker_map(take_dir / "marker_map.json"))
    row = solve_take_file(job, str(take_dir / "take.c3d"), str(out))
    assert row["status"] == "solved", row
    assert not stale.exists() and not stale_file.exists(), "the dead writer's leftovers were left behind"
    assert live.exists() and live_file.exists(), "a live writer's files were removed"
    assert sorted(p.name for p in out.iterdir() if TEMP_MARK in p.name or p.name.startswith(".")) == sorted(
        [live.name, live_file.name]), list(out.iterdir())
    assert (out / "weights.csv").read_text().startswith("frame,time,")
    # the rig's own pairs, found once for the batch, are reported as solve reports them: not as a project's list
    assert job.antagonists and json.loads((out / "report.json").read_text())["antagonists"] is None


def test_a_weight_take_in_a_batch_writes_what_solve_writes(tmp_path, ict_dir, ict_rig, llf_csv, take_dir):
    """A Live Link Face CSV among the takes is played on the rig, as ``solve`` does with it: the same weights CSV
    byte for byte, a report of kind 'weights', a PC2 of the posed rig and a preview; not a failure."""
    from model.batch import BatchJob, solve_take_file
    from model.marker_map import load_marker_map
    from model.pc2 import read_pc2
    from model.pose import PoseEvaluator
    ref = tmp_path / "solve.csv"
    run_cli("solve", ict_dir, llf_csv, "-o", ref, check=True)
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False}, marker_map=load_marker_map(take_dir / "marker_map.json"),
                           cache=True)
    row = solve_take_file(job, str(llf_csv), str(tmp_path / "out" / "llf"))
    assert row["status"] == "solved" and row["error"] is None, row
    assert row["marker_rmse"] is None and row["frames"] == 328
    out = tmp_path / "out" / "llf"
    assert (out / "weights.csv").read_bytes() == ref.read_bytes()
    assert json.loads((out / "report.json").read_text())["kind"] == "weights"
    W = np.loadtxt(ref, delimiter=",", skiprows=1)[:, 2:]
    frames = read_pc2(out / "cache.pc2")[0]
    k = 200
    assert np.abs(frames[k] - PoseEvaluator(ict_rig, dtype=np.float64).pose(W[k])).max() < 1e-4


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_a_scheduler_that_cannot_start_is_one_sentence_and_no_process_is_left():
    """The local cluster's scheduler runs in a process forked from the fork server (``model.batch_scheduler``): when
    it cannot start (here: an address no machine has), its error comes back as one sentence and its process is
    gone; a good one answers with its address and ends when it is closed."""
    import asyncio

    from model.batch_scheduler import ForkedScheduler
    from model.fork_server import start_fork_server
    assert start_fork_server()

    async def run():
        bad = ForkedScheduler(host="256.0.0.1", port=0, dashboard=False)
        with pytest.raises(RuntimeError, match=r"^The local cluster's scheduler did not start on 256\.0\.0\.1: \w+"):
            await bad.start()
        assert bad.process.exitcode is not None
        good = ForkedScheduler(host="127.0.0.1", port=0, dashboard=False)
        await good.start()
        assert good.address.startswith("tcp://127.0.0.1:") and good.process.is_alive()
        from contextlib import suppress

        from distributed.core import rpc
        async with rpc(good.address) as comm:   # as SpecCluster closes it: the comm closes before any answer
            with suppress(OSError):
                await comm.terminate()
        await good.close()
        assert good.process.exitcode == 0

    asyncio.run(run())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_local_workers_leave_what_the_fork_server_imported_out_of_garbage_collection():
    """(And the local cluster's dashboard answers.) The local cluster's workers come from the fork server with everything it imported frozen for the garbage
    collector (``model.batch_preloaded``): a full collection in a worker walks only what the worker made itself, not
    the ~220,000 objects of Dask, numpy, VTK and the solver (85-180 ms with the GIL held, taken from a take)."""
    import gc

    import dask
    import distributed  # noqa: F401  (before the configuration block, as run_batch does)

    from model.batch import local_cluster_config, start_client
    from tests.test_pages import numpy_asks_for_huge_pages_now
    with dask.config.set(local_cluster_config()):
        client, cluster = start_client(2, dashboard_address="127.0.0.1:0")
        try:
            frozen = client.run(gc.get_freeze_count)
            walked = client.run(lambda: len(gc.get_objects()))
            huge_pages = client.run(numpy_asks_for_huge_pages_now)
            dashboard = _fetch_dashboard(client.dashboard_link)
        finally:
            client.close()
            cluster.close()
    assert len(frozen) == 2
    # and numpy in the workers leaves transparent huge pages alone (model.batch_env: their compaction on first touch
    # doubled a take's kernel time with two workers side by side)
    assert list(huge_pages.values()) == [False, False]
    for worker, n in frozen.items():
        assert n > 50_000, f"{worker}: only {n} objects frozen"    # Dask, numpy, scipy, the solver (no VTK here)
        assert walked[worker] < n / 2, f"{worker}: a full collection still walks {walked[worker]} objects"
    # the dashboard link answers with Dask's status page, built when first asked for (``model.batch_scheduler``:
    # bokeh is not imported before the workers can start); the scheduler's own routes answer as before
    health, status, workers = dashboard
    assert health == (200, "ok")
    assert status[0] == 200 and status[1].endswith("/status") and "bokeh" in status[2] and "Dask" in status[2]
    assert workers[0] == 200 and workers[2].count("tcp://127.0.0.1:") >= 2


def _installation_described(conn) -> None:
    """Run in a process forked from the fork server: whether Dask's description of the installation is there, and
    Dask's defaults as the fork server read them (with libyaml) beside what PyYAML's own parser reads from the same
    files, and whether ``yaml.safe_load`` is PyYAML's own again."""
    import os
    import platform

    import dask
    import distributed
    import yaml
    from distributed.versions import _version_cached
    files = [os.path.join(os.path.dirname(m.__file__), f"{m.__name__}.yaml") for m in (dask, distributed)]
    pure = []
    for f in files:
        with open(f) as stream:
            pure.append(yaml.load(stream, Loader=yaml.SafeLoader))
    conn.send(("processor" in vars(platform.uname()), _version_cached.cache_info().currsize, pure,
               dask.config.defaults, yaml.safe_load.__module__))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_processes_forked_for_a_batch_find_dasks_description_of_the_installation_read():
    """The scheduler, each worker and the client describe the installation to each other when they meet (package
    versions read from the disk, the processor's name from a ``uname -p`` subprocess): the fork server read it once
    (``model.batch_preloaded``), so a process forked from it has it before Dask asks, and runs no subprocess. Dask's
    defaults, which the fork server's imports read with libyaml (``model.batch_env.fast_yaml``), are the values
    PyYAML's own parser reads from those files, and the workers' ``yaml.safe_load`` is PyYAML's own."""
    import multiprocessing

    from app.batch_preload import BATCH_PRELOAD
    from model.fork_server import start_fork_server
    assert start_fork_server(BATCH_PRELOAD)
    ctx = multiprocessing.get_context("forkserver")
    ours, theirs = ctx.Pipe()
    child = ctx.Process(target=_installation_described, args=(theirs,))
    child.start()
    try:
        assert ours.poll(120)
        processor, versions, pure, defaults, safe_load = ours.recv()
    finally:
        child.join(30)
    assert processor, "the processor's name is not cached: each process would run uname -p"
    assert versions >= 6, f"only {versions} package versions cached"     # Dask's required packages at least
    for read in pure:     # dask.yaml's and distributed.yaml's values, each among the defaults the fork server read
        assert read in defaults
    assert safe_load == "yaml"


_NO_DASK_HERE = """
import json, sys
from app.launch import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "dask": sorted(m for m in ("dask", "distributed") if m in sys.modules)}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_the_batch_command_solves_on_a_local_cluster_without_importing_dask_itself(tmp_path, ict_dir, take_dir):
    """The local cluster is driven from a process forked from the fork server (``model.batch_driver``), which has
    Dask imported already: the ``batch`` command's own process never imports it (~0.3 s), and the takes are solved."""
    takes = _short_takes(tmp_path, take_dir, 2)
    proc = subprocess.run([sys.executable, "-c", _NO_DASK_HERE, "batch", str(ict_dir), *map(str, takes), "--map",
                           str(take_dir / "marker_map.json"), "-o", str(tmp_path / "out"), "--workers", "1"],
                          capture_output=True, text=True, timeout=300)
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r == {"code": 0, "dask": []}, proc.stderr[-3000:]
    assert [t["status"] for t in _summary(tmp_path / "out").values()] == ["solved", "solved"]


def _fetch_dashboard(link: str):
    """(code, text) of the scheduler's /health, then (code, final address, page) of the dashboard's link and of its
    workers page: what a browser opening the printed link gets."""
    import urllib.request
    root = link.rsplit("/", 1)[0]
    with urllib.request.urlopen(root + "/health", timeout=60) as r:
        health = (r.status, r.read().decode())
    pages = []
    for address in (link, root + "/info/main/workers.html"):
        with urllib.request.urlopen(address, timeout=60) as r:
            pages.append((r.status, r.geturl(), r.read().decode(errors="replace")))
    return health, *pages


def test_the_longest_takes_are_solved_first_and_the_summary_keeps_the_given_order(tmp_path, ict_rig, take_dir):
    """Takes go to the workers longest first (``model.batch.longest_first``: the largest files), so that the last takes
    to start are the shortest and a worker out of takes waits less for the last one; the summary's rows stay in the
    order the takes were given. On one worker the takes end in the order they were submitted."""
    import argparse

    from app.cli_batch import prepare_job
    from app.cli_solve import add_solve_options
    from model.batch import run_batch
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    takes = []
    for name, n in (("a_short", 40), ("b_long", 160), ("c_mid", 90)):
        takes.append(tmp_path / f"{name}.c3d")
        write_c3d(takes[-1], MarkerTake(t.positions[:n], t.labels, t.rate, t.units))
    p = argparse.ArgumentParser()
    add_solve_options(p)
    job = prepare_job(ict_rig, p.parse_args(["--map", str(take_dir / "marker_map.json")]))
    ended = []
    rows = run_batch(job, takes, tmp_path / "out", workers=1, dashboard_address="127.0.0.1:0",
                     progress=lambda pr: pr.row is not None and ended.append(pr.row["take"]))
    assert ended == ["b_long", "c_mid", "a_short"]
    assert [r["take"] for r in rows] == ["a_short", "b_long", "c_mid"]
    assert [r["frames"] for r in rows] == [40, 160, 90]
    summary = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert [r["take"] for r in summary["takes"]] == ["a_short", "b_long", "c_mid"]


@pytest.mark.parametrize("where", ["driver", "in-process"])
def test_a_second_batch_in_the_same_process_runs(tmp_path, ict_rig, take_dir, monkeypatch, where):
    """The GUI runs every Batch Solve in its own process: a second batch there must find Dask's settings intact (the
    first one's configuration block used to take distributed's defaults out with it: KeyError 'comm'), whether the
    cluster runs from a driver process forked from the same fork server each time or in this process."""
    import argparse

    from model import batch_driver
    if where == "in-process":
        monkeypatch.setattr(batch_driver, "available", lambda preload=(): False)

    from app.cli_batch import prepare_job
    from app.cli_solve import add_solve_options
    from model.batch import run_batch
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    take = tmp_path / "short.c3d"
    write_c3d(take, MarkerTake(t.positions[:40], t.labels, t.rate, t.units))
    p = argparse.ArgumentParser()
    add_solve_options(p)
    job = prepare_job(ict_rig, p.parse_args(["--map", str(take_dir / "marker_map.json")]))
    for out in ("first", "second"):
        rows = run_batch(job, [take], tmp_path / out, workers=1, dashboard_address="127.0.0.1:0")
        assert [r["status"] for r in rows] == ["solved"], rows


def _short_takes(tmp_path, take_dir, n: int, frames: int = 40) -> list:
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    paths = []
    for k in range(n):
        paths.append(tmp_path / f"short_{k}.c3d")
        write_c3d(paths[-1], MarkerTake(t.positions[k:k + frames], t.labels, t.rate, t.units))
    return paths


def _job(rig, take_dir):
    import argparse

    from app.cli_batch import prepare_job
    from app.cli_solve import add_solve_options
    p = argparse.ArgumentParser()
    add_solve_options(p)
    return prepare_job(rig, p.parse_args(["--map", str(take_dir / "marker_map.json")]))


def test_each_takes_row_reaches_the_client_with_the_news_that_it_is_done(tmp_path, ict_rig, take_dir, monkeypatch):
    """A take's row travels as a Dask event ahead of its task's completion (``solve_and_report``): the client never
    asks a worker for a task's result (a round trip through the scheduler per take), and the rows are the ones the
    takes wrote (done.json), a failed take's included. In this process, where the calls can be counted."""
    import distributed

    from model import batch_driver
    from model.batch import run_batch
    monkeypatch.setattr(batch_driver, "available", lambda preload=(): False)
    asked = []
    result = distributed.Future.result
    monkeypatch.setattr(distributed.Future, "result",
                        lambda self, *a, **k: asked.append(self.key) or result(self, *a, **k))
    takes = _short_takes(tmp_path, take_dir, 3)
    (tmp_path / "cut.c3d").write_bytes(takes[0].read_bytes()[:3000])
    rows = run_batch(_job(ict_rig, take_dir), [*takes, tmp_path / "cut.c3d"], tmp_path / "out", workers=1,
                     dashboard_address="127.0.0.1:0")
    assert asked == [], "the client asked the workers for results"
    assert [r["status"] for r in rows] == ["solved"] * 3 + ["failed"]
    assert "cut.c3d" in rows[3]["error"]
    for take, row in zip(takes, rows):
        assert row == json.loads((tmp_path / "out" / take.stem / "done.json").read_text())["row"]


def test_a_row_that_cannot_travel_as_an_event_is_asked_for(tmp_path, ict_rig, take_dir, monkeypatch):
    """Where a take's row cannot be sent as an event (here: every event refused, as msgpack refuses a type it does
    not know), the take still stands: the client asks its worker for the result, as it did before the events. On a
    cluster of this process's threads, where the workers' ``log_event`` can be replaced."""
    import dataclasses

    import distributed

    from model.batch import run_batch
    asked = []
    result = distributed.Future.result
    monkeypatch.setattr(distributed.Future, "result",
                        lambda self, *a, **k: asked.append(self.key) or result(self, *a, **k))

    def refuse(self, topic, msg):
        raise TypeError("Message must be msgpack serializable.")

    monkeypatch.setattr(distributed.Worker, "log_event", refuse)
    takes = _short_takes(tmp_path, take_dir, 2)
    job = dataclasses.replace(_job(ict_rig, take_dir), preview=None)   # no OpenGL window in this process's threads
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        rows = run_batch(job, takes, tmp_path / "out", scheduler=c.scheduler_address)
    assert [r["status"] for r in rows] == ["solved", "solved"]
    assert len(asked) == 2
    for take, row in zip(takes, rows):
        assert row == json.loads((tmp_path / "out" / take.stem / "done.json").read_text())["row"]


@pytest.mark.parametrize("where", ["driver", "in-process"])
def test_a_cancelled_batch_ends_the_takes_in_hand_and_fails_the_rest_as_cancelled(tmp_path, ict_rig, take_dir,
                                                                                 monkeypatch, where):
    """Cancel (the GUI's button: ``cancel()`` turns true) after the first take: the queued takes are not solved and
    say 'cancelled', every take complete on disk is 'solved', the summary says the same; whether the local cluster
    runs from its driver process (``model.batch_driver``: the cancel is passed on to it) or in this process."""
    from model import batch_driver
    from model.batch import run_batch
    if where == "in-process":
        monkeypatch.setattr(batch_driver, "available", lambda preload=(): False)
    elif not batch_driver.available():
        pytest.skip("no fork server a driver could adopt here")
    # takes that end more often than every 0.1 s, the driver's wait for news: the cancel must still be asked after
    # each (it was asked only when that wait timed out, so a run of quick takes went on to its end)
    takes = _short_takes(tmp_path, take_dir, 16, frames=300)
    first = []
    rows = run_batch(_job(ict_rig, take_dir), takes, tmp_path / "out", workers=1, dashboard_address="127.0.0.1:0",
                     progress=lambda p: p.row is not None and first.append(p.row), cancel=lambda: bool(first))
    complete = {d.parent.name for d in (tmp_path / "out").glob("*/done.json")}
    assert first and first[0]["status"] == "solved" and first[0]["take"] in complete
    assert {r["take"] for r in rows if r["status"] == "solved"} == complete
    cancelled = [r for r in rows if r["status"] == "failed"]
    assert len(cancelled) + len(complete) == 16
    assert len(cancelled) >= 8, f"{len(complete)} takes solved after the cancel"      # 2-3 are in hand
    assert all(r["error"] == f"{r['path']}: cancelled before it was solved." for r in cancelled), cancelled
    summary = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert [r["status"] for r in summary["takes"]] == [r["status"] for r in rows]
    assert summary["solved"] == len(complete) and summary["failed"] == len(cancelled)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster's fork server (Linux)")
def test_a_batch_whose_driver_is_killed_still_writes_its_summary_and_leaves_no_process(tmp_path, ict_rig, take_dir):
    """The local cluster runs from a driver process (``model.batch_driver``): killed mid-run, the batch still ends
    with a summary (the takes complete on disk solved, the others failed with one sentence saying why), and the
    scheduler and the workers it started end with it."""
    import threading

    import psutil

    from model.batch import run_batch
    from model.batch_driver import PROCESS_NAME
    out = tmp_path / "out"
    takes = _short_takes(tmp_path, take_dir, 10, frames=120)
    killed = []

    def kill_the_driver() -> None:
        deadline = time.monotonic() + 300
        while not list(out.glob("*/done.json")) and time.monotonic() < deadline:
            time.sleep(0.02)
        tree = psutil.Process().children(recursive=True)
        drivers = [c for c in tree if c.name() == PROCESS_NAME]
        server = drivers[0].parent() if drivers else None
        killed.append([c for c in (server.children() if server else []) if c.pid != drivers[0].pid])
        for d in drivers:
            d.kill()
        killed.append(len(drivers))

    threading.Thread(target=kill_the_driver, daemon=True).start()
    rows = run_batch(_job(ict_rig, take_dir), takes, out, workers=2, dashboard_address="127.0.0.1:0")
    assert killed and killed[1] == 1, "the batch ran without a driver to kill"
    complete = {d.parent.name for d in out.glob("*/done.json")}
    assert complete and {r["take"] for r in rows if r["status"] == "solved"} == complete
    stopped = [r for r in rows if r["status"] == "failed"]
    assert stopped, "every take was solved before the driver was killed"
    assert all(r["error"] == f"{r['path']}: stopped unexpectedly (the batch's driver process ended) before it was "
               f"solved." for r in stopped), stopped
    assert json.loads((out / "batch.json").read_text())["failed"] == len(stopped)
    started = killed[0]               # the scheduler and the two workers, forked from the fork server for the driver
    assert len(started) == 3
    gone, alive = psutil.wait_procs(started, timeout=30)
    assert not alive, [c.cmdline() for c in alive]


_PREVIEW_AND_RENDER = """
import sys
import numpy as np
from pathlib import Path
import solvers.mesh
from app.cli_batch import preview_png
from model.batch import PREVIEW_SIZE, preview_focus
from model.parts import drawn_faces
from model.pose import PoseEvaluator
from model.readers import load_rig
from model.rig_prep import default_view
rig = load_rig(sys.argv[1])
ev, focus = PoseEvaluator(rig), preview_focus(rig)
counts, indices = drawn_faces(rig)[1:]          # the faces a batch's preview draws (BatchJob.preview_faces)
view = default_view(rig)                        # their hidden back sides and normals, as the batch's job carries them
poses = [ev.pose(np.array([float(n in names) for n in rig.shape_names]))
         for names in (["jawOpen"], ["mouthSmile_L", "mouthSmile_R"], ["jawOpen"])]
found, real = [], solvers.mesh.hidden_back_faces
solvers.mesh.hidden_back_faces = lambda *a: found.append(1) or real(*a)
for k, pts in enumerate(poses):
    Path(f"{sys.argv[2]}/preview{k}.png").write_bytes(preview_png(pts, counts, indices, focus=focus, view=view))
assert not found, "a preview searched the hidden back sides the job brought"
solvers.mesh.hidden_back_faces = real
drew_with = sorted(m for m in ("vtkmodules", "pyvista") if m in sys.modules)
assert not drew_with, f"a preview imported {drew_with}"
from widgets.scene import render_png
for k, pts in enumerate(poses):
    render_png(pts, counts, indices, f"{sys.argv[2]}/render{k}.png", focus=focus, size=PREVIEW_SIZE, camera="front")
"""


def test_a_preview_is_the_picture_render_draws_without_opengl(tmp_path, ict_dir, ict_rig):
    """A worker draws each take's preview on the CPU (``preview_png``: ``solvers.raster``, no VTK, no OpenGL
    context to make), with the faces' hidden back sides and normals the job brought (``default_view``), as the
    picture ``render`` draws of the same pose through VTK on OpenGL (``render_png``): the same but for a level or
    two at the edges of the silhouette (multisampling's coverage; OpenGL's arithmetic) and a level of VTK's dither
    in the background gradient, and never the previous take's pose. On ICT's rig, in a process of its own, as a
    worker's."""
    from model.batch import PREVIEW_SIZE
    from tests.image_compare import load_png, pixel_difference
    assert {"jawOpen", "mouthSmile_L", "mouthSmile_R"} <= set(ict_rig.shape_names)
    proc = subprocess.run([sys.executable, "-c", _PREVIEW_AND_RENDER, str(ict_dir), str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    previews = [load_png(tmp_path / f"preview{k}.png") for k in range(3)]
    renders = [load_png(tmp_path / f"render{k}.png") for k in range(3)]
    for k in range(3):
        assert previews[k].shape[:2] == (PREVIEW_SIZE[1], PREVIEW_SIZE[0])
        d = pixel_difference(previews[k], renders[k])
        assert d.mean() < 0.6 and np.percentile(d, 99) <= 2 and (d > 2).mean() < 0.01, (k, d.mean())
    assert np.array_equal(previews[0], previews[2])      # the same pose, the same picture, after another pose
    # the nearest wrong answer, the previous take's pose, is far outside those bounds
    wrong = pixel_difference(previews[1], renders[0])
    assert wrong.mean() > 1.0 and (wrong > 2).mean() > 0.02 and (wrong > 30).sum() > 500


_LAUNCH = """
import json, sys
import model.fork_server
seen = []
model.fork_server.start_fork_server = lambda preload: seen.append(["numpy" in sys.modules, list(preload)]) or True
from app.launch import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:        # argparse's --help
    code = exc.code
print(json.dumps({"seen": seen, "code": code}))
"""


@pytest.mark.parametrize("argv, starts", [
    (["batch", "RIG", "TAKE.c3d", "-o", "OUT"], True),
    (["batch", "RIG", "TAKE.c3d", "-o", "OUT", "--scheduler", "tcp://127.0.0.1:9"], False),
    (["batch", "--help"], False),
    (["solve", "RIG", "TAKE.c3d", "-o", "OUT.csv"], False),
])
def test_the_batch_command_starts_its_fork_server_before_it_imports_numpy(tmp_path, argv, starts):
    """``blendshape-studio batch`` on the local cluster starts the fork server first (``app.launch``), so that its
    ~2 s of imports overlap the command's own; a batch on a scheduler, help, and other commands start none. The
    command then runs as before (here: a rig that does not exist, exit 2)."""
    from app.batch_preload import BATCH_PRELOAD
    argv = [str(tmp_path / a) if a in ("RIG", "TAKE.c3d", "OUT", "OUT.csv") else a for a in argv]
    proc = subprocess.run([sys.executable, "-c", _LAUNCH, *argv], capture_output=True, text=True, timeout=120)
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["seen"] == ([[False, list(BATCH_PRELOAD)]] if starts else [])
    assert r["code"] == (0 if "--help" in argv else 2), proc.stderr[-2000:]


def test_a_preview_that_cannot_be_drawn_costs_the_take_its_picture_only(tmp_path, ict_rig, take_dir):
    """A surface the preview cannot draw (here: a point that is not a finite number, which the rasteriser refuses
    before its compiled loop runs) leaves the take solved with its weights, report and done-marker, no preview, and
    the reason in its row."""
    import dataclasses

    import numpy as np

    from model.batch import solve_take_file
    job = _job(ict_rig, take_dir)
    real = job.preview

    def broken_surface(points, *args, **kwargs):
        points = np.array(points)
        points[0, 0] = np.nan
        return real(points, *args, **kwargs)

    take = _short_takes(tmp_path, take_dir, 1)[0]
    row = solve_take_file(dataclasses.replace(job, preview=broken_surface), str(take), str(tmp_path / "out"))
    assert row["status"] == "solved"
    assert row["preview_error"] == ("the preview could not be rendered (ValueError: the surface to draw has points "
                                    "that are not finite numbers)")
    written = {p.name for p in (tmp_path / "out").iterdir()}
    assert "preview.png" not in written and {"weights.csv", "report.json", "done.json"} <= written
    assert json.loads((tmp_path / "out" / "done.json").read_text())["row"]["preview_error"] == row["preview_error"]


def test_a_takes_reader_warnings_reach_its_report_its_row_and_the_summary(tmp_path, ict_dir, ict_rig, take_dir):
    """A take cut short (a C3D at 90% of its bytes: read to its last whole frame, with a warning) is solved in a
    batch as `solve` solves it, and what its reader decided is in its report.json, its row (batch.json's
    ``warnings``, an extra key beside DESIGN.md's) and on the command's stderr (before: nowhere); a take whose reader
    said nothing has an empty list. Where a file stands in the way of a take's folder, or a folder where one of its
    files goes, that take fails in one sentence naming it; nothing is written for it."""
    from model.batch import BatchJob, read_summary, solve_take_file, write_summary
    from model.marker_map import load_marker_map
    raw = (take_dir / "take.c3d").read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(raw[: int(len(raw) * 0.9)])
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False}, marker_map=load_marker_map(take_dir / "marker_map.json"))
    row = solve_take_file(job, str(cut), str(tmp_path / "out" / "cut"))
    assert row["status"] == "solved" and len(row["warnings"]) == 1, row
    assert "the file ends early" in row["warnings"][0] and str(cut) in row["warnings"][0]
    assert json.loads((tmp_path / "out" / "cut" / "report.json").read_text())["warnings"] == row["warnings"]
    plain = solve_take_file(job, str(take_dir / "take.c3d"), str(tmp_path / "out" / "take"))
    assert plain["status"] == "solved" and plain["warnings"] == []
    write_summary(tmp_path / "out", [row, plain])
    assert [r["warnings"] for r in read_summary(tmp_path / "out")[1]["takes"]] == [row["warnings"], []]

    (tmp_path / "out" / "blocked").write_text("mine")                       # a file where the take's folder goes
    failed = solve_take_file(job, str(cut), str(tmp_path / "out" / "blocked"))
    assert failed["status"] == "failed" and failed["error"] == \
        f"{tmp_path / 'out' / 'blocked'}: is a file, not a folder."
    (tmp_path / "out" / "odd" / "report.json").mkdir(parents=True)        # a folder where one of its files goes
    failed = solve_take_file(job, str(cut), str(tmp_path / "out" / "odd"))
    assert failed["status"] == "failed" and failed["error"] == \
        f"{tmp_path / 'out' / 'odd' / 'report.json'}: is a folder, not a file."
    assert (tmp_path / "out" / "blocked").read_text() == "mine"
    assert sorted(p.name for p in (tmp_path / "out" / "odd").iterdir()) == ["report.json"]

    proc = _batch(ict_dir, take_dir, [cut], tmp_path / "cli", "--workers", "1", check=True)
    assert f"warning: {row['warnings'][0]}\n" in proc.stderr
    assert _summary(tmp_path / "cli")["cut"]["warnings"] == row["warnings"]


def test_a_take_that_fails_unexpectedly_fails_once_without_worker_tracebacks(tmp_path, ict_rig, take_dir, capfd,
                                                                            monkeypatch):
    """An error nobody expected (a bug, here settings the solver cannot read) fails the take on its first try: no
    worker prints a traceback, the take is not retried on every worker (before: three tries a take, a worker's
    "Compute Failed" traceback for each), its row says it in one sentence, and the front end writes the traceback
    to a crash log that the row's error then names."""
    import dataclasses

    from app.crash import log_unexpected_rows
    from model.batch import run_batch
    job = _job(ict_rig, take_dir)
    broken = dataclasses.replace(job, settings={**job.settings, "stable": 5})
    takes = _short_takes(tmp_path, take_dir, 2)
    capfd.readouterr()
    rows = run_batch(broken, takes, tmp_path / "out", workers=1, dashboard_address="127.0.0.1:0")
    printed = capfd.readouterr()
    assert "Compute Failed" not in printed.err and "Traceback" not in printed.err + printed.out
    assert [r["status"] for r in rows] == ["failed", "failed"]
    for take, row in zip(takes, rows):
        assert row["error"] == f"{take}: the solve stopped unexpectedly (TypeError: 'int' object is not iterable)."
        assert "Traceback" in row["traceback"] and "TypeError" in row["traceback"]
    summary = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert all("traceback" not in r for r in summary["takes"])
    monkeypatch.setenv("BLENDSHAPE_STUDIO_LOGS", str(tmp_path / "logs"))
    log_unexpected_rows(rows, "solving the take")
    logs = sorted((tmp_path / "logs").glob("crash-*.log"))
    assert len(logs) == 2 and all("TypeError" in p.read_text() for p in logs)
    assert all("traceback" not in r for r in rows)
    assert {r["error"].split("; the details are in ")[1] for r in rows} == {f"{p}." for p in logs}


def test_a_preview_frames_the_whole_model_where_the_shapes_act_across_it():
    """A batch's preview frames what the window's cameras and ``render`` frame (``model.rig_prep.focus_vertices``):
    the third-party glTF cube, whose one shape moves one side of it, whole. Its own rule (the vertices a shape moves
    over 5% of the largest displacement) framed that side alone: half the cube was out of the picture."""
    import numpy as np

    from app.cli_batch import preview_image
    from model.batch import preview_focus
    from model.parts import drawn_faces
    from model.pose import PoseEvaluator
    from model.readers import load_rig
    from tests.conftest import DATA, require_data
    from tests.image_compare import assert_large_and_whole
    rig = load_rig(require_data(DATA / "thirdparty" / "gltf" / "singleBlendshapeCube_sparse.glb"))
    points = PoseEvaluator(rig).pose(np.ones(rig.n_shapes))
    counts, indices = drawn_faces(rig)[1:]
    assert_large_and_whole(preview_image(points, counts, indices, focus=preview_focus(rig), size=(400, 300)))
