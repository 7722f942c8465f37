"""An output that cannot fit on its disk is refused before any work (``model.free_space``): one sentence naming the
file, the size it needs and the space free, exit code 2, nothing written. Before, `solve --cache` on a long take
wrote a PC2 of tens of GB with no warning and could fill the disk. Free space is faked with a small
``shutil.disk_usage`` so a normal take is refused; with the real one the same runs pass."""
from __future__ import annotations

import shutil
from collections import namedtuple

import pytest

from app.cli import main
from model.errors import RigInputError
from model.free_space import check_free_space, human_size
from tests.rig_files import write_rig_folder

Usage = namedtuple("Usage", "total used free")


@pytest.fixture
def tiny_disk(monkeypatch):
    """Every disk has 1000 bytes free."""
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9 - 1000, 1000))


def test_human_size():
    assert human_size(80) == "80 bytes"
    assert human_size(512_000) == "512 KB"
    assert human_size(31_900_000_000) == "31.9 GB"
    assert human_size(2.5e12) == "2.5 TB"


def test_check_free_space_sums_the_files_of_one_disk(tmp_path, tiny_disk):
    check_free_space({tmp_path / "a.pc2": 600})
    with pytest.raises(RigInputError) as err:
        check_free_space({tmp_path / "a.pc2": 600, tmp_path / "new" / "b.glb": 500}, lower_bounds=[])
    assert str(err.value) == (f"{tmp_path / 'a.pc2'} and {tmp_path / 'new' / 'b.glb'}: need 1.1 KB together, but "
                              f"the disk of {tmp_path} has 1 KB free; free some space or write to another disk.")


def _rig_and_weights(tmp_path, frames: int = 40):
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    take = tmp_path / "take.csv"
    take.write_text("frame,time,raise,push\n" + "".join(f"{i},{i / 30:.6f},{i / frames:.4f},0.5\n"
                                                       for i in range(frames)))
    return rig, take


def _listing(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_solve_refuses_a_cache_its_disk_has_no_room_for(tmp_path, tiny_disk, capsys):
    rig, take = _rig_and_weights(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    before = _listing(tmp_path)
    code = main(["solve", str(rig), str(take), "-o", str(out / "w.csv"), "--cache", str(out / "c.pc2")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    # 40 frames x 36 vertices x 12 bytes + the 32-byte header
    assert err == (f"error: {out / 'c.pc2'}: needs 17.3 KB, but the disk of {out} has 1 KB free; free some space "
                   "or write to another disk.\n")
    assert _listing(tmp_path) == before


def test_solve_refuses_a_marker_take_before_mapping_or_solving(ict_dir, take_dir, tmp_path, tiny_disk, monkeypatch,
                                                               capsys):
    from model.take_workspace import TakeWorkspace

    def no_work(*a, **k):
        raise AssertionError("solved or mapped although the cache cannot be written")
    monkeypatch.setattr(TakeWorkspace, "solve", no_work)
    monkeypatch.setattr(TakeWorkspace, "set_map", no_work)
    monkeypatch.setattr(TakeWorkspace, "auto_map", no_work)
    code = main(["solve", str(ict_dir), str(take_dir / "take.c3d"), "--map", str(take_dir / "marker_map.json"),
                 "-o", str(tmp_path / "w.csv"), "--gltf", str(tmp_path / "a.glb")])
    err = capsys.readouterr().err
    # at least the neutral (26,719 vertices x 12 bytes), each shape's offsets (the vertices it moves) and a key per
    # frame for each shape (the real file: 27 MB)
    assert code == 2 and err == (f"error: {tmp_path / 'a.glb'}: needs at least 9.72 MB, but the disk of {tmp_path} "
                                 "has 1 KB free; free some space or write to another disk.\n")
    assert _listing(tmp_path) == []


def test_export_refuses_an_animation_its_disk_has_no_room_for(tmp_path, tiny_disk, capsys):
    rig, take = _rig_and_weights(tmp_path, frames=100)
    code = main(["export", str(rig), "-o", str(tmp_path / "a.glb"), "--animation", str(take)])
    err = capsys.readouterr().err
    # at least 36 vertices x 12 bytes + the 30 vertices each shape moves x 14 bytes + 100 frames x (1 + 2) x 4 bytes
    assert code == 2 and err == (f"error: {tmp_path / 'a.glb'}: needs at least 2.47 KB, but the disk of "
                                 f"{tmp_path} has 1 KB free; free some space or write to another disk.\n")
    assert not (tmp_path / "a.glb").exists()


def test_a_normal_run_fits(tmp_path, capsys):
    rig, take = _rig_and_weights(tmp_path)
    assert main(["solve", str(rig), str(take), "-o", str(tmp_path / "w.csv"), "--cache", str(tmp_path / "c.pc2"),
                 "--gltf", str(tmp_path / "a.glb")]) == 0
    assert (tmp_path / "c.pc2").stat().st_size == 32 + 40 * 36 * 12
    assert main(["export", str(rig), "-o", str(tmp_path / "b.glb"), "--animation", str(take)]) == 0


def test_a_batch_take_whose_cache_does_not_fit_fails_before_its_solve(tmp_path, tiny_disk):
    from model.batch import BatchJob, solve_take_file
    from model.readers import load_rig
    rig, take = _rig_and_weights(tmp_path)
    job = BatchJob(rig=load_rig(rig), settings={}, cache=True)
    row = solve_take_file(job, str(take), str(tmp_path / "out" / "take"))
    assert row["status"] == "failed" and "cache.pc2: needs 17.3 KB" in row["error"], row
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("suffix, frames", [(".usdc", 0), (".usd", 100), (".usda", 100)])
def test_export_refuses_a_usd_its_disk_has_no_room_for(tmp_path, tiny_disk, monkeypatch, capsys, suffix, frames):
    """A USD export was written without a look at the disk (``export_size`` was 0 for USD). Now it is sized as a
    least (``model.export.usd_size``): a .usdc (and a .usd, crate) holds the points and the offsets of the vertices
    each shape moves uncompressed, 12 bytes a vector (36 + 2 x 30 here); a .usda writes each at least as
    ``(0, 0, 0), ``. Refused in one sentence, nothing written; on the real disk the file written is no smaller."""
    from model.export import export_size
    from model.readers import load_rig
    rig, take = _rig_and_weights(tmp_path, frames=frames or 40)
    out = tmp_path / f"a{suffix}"
    animation = ["--animation", str(take)] if frames else []
    least = export_size(load_rig(rig), out, frames)
    assert least == 12 * (36 + 2 * 30) if suffix != ".usda" else least > 12 * (36 + 2 * 30)
    code = main(["export", str(rig), "-o", str(out), *animation])
    assert code == 2 and capsys.readouterr().err == (
        f"error: {out}: needs at least {human_size(least)}, but the disk of {tmp_path} has 1 KB free; free some space "
        "or write to another disk.\n")
    assert not out.exists()
    monkeypatch.undo()
    assert main(["export", str(rig), "-o", str(out), *animation]) == 0
    assert out.stat().st_size >= least


def test_the_usd_sizes_are_no_more_than_ict_writes(ict_rig, tmp_path):
    """The least sizes of ICT's USD exports (in cm, turned z-up) are below what usd-core writes (a crate's arrays
    compressed by a newer usd-core would show here first)."""
    from model.export import export_rig, export_size
    for suffix in (".usdc", ".usda"):
        out = tmp_path / f"ict{suffix}"
        least = export_size(ict_rig, out, units="cm", up="z")
        export_rig(ict_rig, out, units="cm", up="z")
        assert 0.3 * out.stat().st_size < least <= out.stat().st_size, suffix


def test_a_batch_whose_caches_do_not_fit_together_is_refused_before_any_take(tmp_path, monkeypatch):
    """Each batch take's cache was checked alone, before its own solve: with room for one of them (20 KB free, 17.3
    KB a cache) every take passed, and the takes together filled the disk. The caches of all the takes to solve are
    summed first: the batch is refused in one sentence before any take is solved, nothing written."""
    from model.batch import BatchJob, run_batch
    from model.readers import load_rig
    rig, take = _rig_and_weights(tmp_path)
    other = tmp_path / "other.csv"
    other.write_bytes(take.read_bytes())
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9 - 20_000, 20_000))
    job = BatchJob.prepare(load_rig(rig), {"mode": "global", "residual": None, "calibration_frames": 30,
                                           "fixed_head": False}, cache=True)
    out = tmp_path / "out"
    with pytest.raises(RigInputError) as err:
        run_batch(job, [take, other], out, workers=1)
    assert str(err.value) == (f"{out}: the caches (cache.pc2) of the 2 takes to solve need 34.6 KB together, but the "
                              f"disk of {tmp_path} has 20 KB free; free some space or write to another disk.")
    assert not out.exists()
    check = BatchJob(rig=job.rig, settings={}, cache=False)     # without --cache nothing large is summed
    from model.batch import check_caches_space
    check_caches_space(check, [take, other], [out / "take", out / "other"], out)


def test_a_batch_counts_only_what_its_caches_add_to_the_old_ones_they_replace(tmp_path, monkeypatch):
    """The old caches of an earlier run are freed as each take's new one replaces it: a batch whose caches are as
    large as the old ones needs room for one at a time, not for all of them again (it is solved), and one whose new
    caches outgrow the old is refused for what they add."""
    from model.batch import BatchJob, check_caches_space, run_batch
    from model.readers import load_rig
    rig, take = _rig_and_weights(tmp_path)
    other = tmp_path / "other.csv"
    other.write_bytes(take.read_bytes())
    out = tmp_path / "out"
    for name in ("take", "other"):
        (out / name).mkdir(parents=True)
        (out / name / "cache.pc2").write_bytes(b"\0" * 17_000)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9 - 20_000, 20_000))
    job = BatchJob.prepare(load_rig(rig), {"mode": "global", "residual": None, "calibration_frames": 30,
                                           "fixed_head": False}, cache=True)
    rows = run_batch(job, [take, other], out, workers=1)
    assert [r["status"] for r in rows] == ["solved", "solved"], rows
    assert (out / "take" / "cache.pc2").stat().st_size == 17_312
    for name in ("take", "other"):
        (out / name / "cache.pc2").write_bytes(b"\0" * 100)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9 - 30_000, 30_000))
    with pytest.raises(RigInputError) as err:
        check_caches_space(job, [take, other], [out / "take", out / "other"], out)
    assert str(err.value) == (f"{out}: the caches (cache.pc2) of the 2 takes to solve, beyond the old ones they "
                              f"replace, need 34.4 KB together, but the disk of {out / 'take'} has 30 KB free; "
                              "free some space or write to another disk.")
