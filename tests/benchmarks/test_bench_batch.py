"""Batch solving on a local Dask cluster: 24 takes on 2 workers against 1 worker, and the cost per take against a
plain solve (issue 21; target: a speed-up of at least 1.7x on 2 cores).

The takes are the shared ICT Live Link take (358 frames) turned and shifted 24 ways, solved with the default
options and the shared marker map, previews on. Each configuration runs in a fresh process in the order the ``batch``
command runs: the local cluster's fork server started first (``app.launch``, ``model.fork_server``: its imports of
what a worker needs run in its own process, on the other core, while this one imports and loads the rig), the rig
loaded, the job prepared and mapped back from the in-memory file the cluster will map (``share_job``), then the
clock started around ``model.batch.run_batch``. Figures per configuration:
the wall time of the whole run (the scheduler and its dashboard started, the workers forked from the fork server --
waiting for its imports if they are not done --, the job scattered, the takes, the cluster's shutdown, the summary),
of the takes alone (from the submits to the last result), and of the whole command (from the script's first line:
its imports, the rig's load and the job's preparation included; the interpreter's start-up not). "Plain solve" is
the same take solved and exported in this process with the rig loaded once (TakeWorkspace.solve, weights CSV and
report): what a loop over ``solve`` costs per take apart from loading the
rig, which every ``solve`` command does again (its time is printed too). Run with -s to see the figures; they are
also in ``benchmark.extra_info``. The machine is shared: the speed-up is noisy, see the README for the spread.
"""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

pytest.importorskip("distributed")

N_TAKES = 24


@pytest.fixture(scope="module")
def bench_takes(tmp_path_factory, take_dir):
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    d = tmp_path_factory.mktemp("bench_takes")
    t = load_take(take_dir / "take.c3d")
    paths = []
    for i in range(N_TAKES):
        a = np.radians(2.0 * i - 20.0)
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        p = d / f"take_{i:02d}.c3d"
        write_c3d(p, MarkerTake(t.positions @ R.T + [i * 3.0, 0.0, 0.0], t.labels, t.rate, t.units))
        paths.append(p)
    return paths


_BATCH = """
import os, time
command_t0 = time.perf_counter()
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")   # as app.launch sets it for every command but the window
from app.batch_preload import BATCH_PRELOAD
from model.fork_server import start_fork_server
start_fork_server(BATCH_PRELOAD)  # as the batch command does (app.launch) before it imports anything else
import argparse, json, os, sys
import psutil
from app.runtime import limit_blas_threads
limit_blas_threads()              # as the command line's main does
from app.cli_batch import prepare_job
from app.cli_solve import add_solve_options
from model.batch import run_batch, share_job
from model.readers import load_rig
rig_dir, map_path, out, workers, *takes = sys.argv[1:]
p = argparse.ArgumentParser()
add_solve_options(p)
job = share_job(prepare_job(load_rig(rig_dir), p.parse_args(["--map", map_path])))   # as the command does


def cpu():
    # CPU seconds of this process and of every process the batch started: the workers are reaped by this process
    # (spawned) or by its fork server (forked), which stays up until this process ends
    t = os.times()
    total = t.user + t.system + t.children_user + t.children_system
    for c in psutil.Process().children():
        if "forkserver" in " ".join(c.cmdline()):
            ct = c.cpu_times()
            total += ct.user + ct.system + ct.children_user + ct.children_system
    return total


last = {}


def progress(p):
    last.setdefault("started", time.perf_counter() - t0)   # the first call: the cluster is up
    last["p"] = p


c0, t0 = cpu(), time.perf_counter()
rows = run_batch(job, takes, out, workers=int(workers), force=True, progress=progress, dashboard_address="127.0.0.1:0")
wall = time.perf_counter() - t0
command = time.perf_counter() - command_t0
time.sleep(0.5)                                  # the fork server reaps the last worker
print(json.dumps({"wall": wall, "takes_s": last["p"].elapsed, "status": [r["status"] for r in rows], "command": command,
                  "frames": sum(r["frames"] for r in rows), "busy": sum(r["seconds"] for r in rows),
                  "cpu": cpu() - c0, "started": last["started"]}))
"""


def _run(take_dir, takes, out, workers):
    """(wall s of ``run_batch``, s of takes alone, frames, s the workers spent on takes added up, CPU s of all the
    batch's processes during ``run_batch``, s of the whole command, s until the cluster was up): one batch in a
    fresh process, as one ``batch`` command runs: the local cluster's fork server started, then the rig loaded and
    the job prepared, then the clock started around ``run_batch``. A fresh process each time, so that no run
    inherits another's warm local cluster machinery (the fork server its workers are forked from)."""
    import json
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-c", _BATCH, str(take_dir.parent.parent / "ict-facekit"),
                           str(take_dir / "marker_map.json"), str(out), str(workers), *map(str, takes)],
                          capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["status"] == ["solved"] * len(takes)
    return r["wall"], r["takes_s"], r["frames"], r["busy"], r["cpu"], r["command"], r["started"]


# Five rounds: single rounds ranged 1.54-2.12x in this machine's noisy minutes, and with three a run's median
# still moved by ~0.1x between runs; two more rounds cost ~12 s and leave the figure's expected value alone.
ROUNDS = 5


def test_bench_batch_speedup(benchmark, take_dir, bench_takes, tmp_path):
    """1 worker and 2 workers, alternated ``ROUNDS`` times (1, 2, 1, 2, ...): this machine's speed drifts by 20% and
    more within a minute, so one run of each can land on a fast and a slow spell. The speed-up is the median run on
    1 worker against the median run on 2; every round's own ratio is printed beside it."""
    import statistics

    def rounds():
        return [(_run(take_dir, bench_takes, tmp_path / "one", 1), _run(take_dir, bench_takes, tmp_path / "two", 2))
                for _ in range(ROUNDS)]

    runs = benchmark.pedantic(rounds, rounds=1, iterations=1)
    ones, twos = [r[0] for r in runs], [r[1] for r in runs]
    med = [{k: statistics.median(run[k] for run in side) for k in range(7)} for side in (ones, twos)]
    one, two = med
    speed_wall, speed_takes, speed_command = one[0] / two[0], one[1] / two[1], one[5] / two[5]
    per_round = [o[0] / t[0] for o, t in zip(ones, twos)]
    fixed = [t[0] - t[1] for t in twos]
    started = [t[6] for t in twos]
    load = os.getloadavg()[0]
    # how many takes were being solved at once on average, and how much slower each became: on a free machine
    # 2 workers give ~2 at once at ~1x; on a shared one the per-take slow-down eats the speed-up
    concurrency, slowdown = two[3] / two[1], (two[3] / len(bench_takes)) / (one[3] / len(bench_takes))
    benchmark.extra_info.update(takes=N_TAKES, rounds=ROUNDS, frames=ones[0][2], one_worker_wall_s=one[0],
                                one_worker_takes_s=one[1], two_workers_wall_s=two[0], two_workers_takes_s=two[1],
                                speedup_wall=speed_wall, speedup_wall_per_round=per_round, speedup_takes=speed_takes,
                                fixed_part_two_workers_s=fixed, cluster_up_two_workers_s=started,
                                load_average=load, concurrency=concurrency, per_take_slowdown_with_two=slowdown,
                                one_worker_cpu_s=one[4], two_workers_cpu_s=two[4], one_worker_command_s=one[5],
                                two_workers_command_s=two[5], speedup_command=speed_command)
    print(f"\nbatch of {N_TAKES} takes ({ones[0][2]} frames), medians of {ROUNDS} alternated rounds: 1 worker "
          f"{one[0]:.2f} s ({one[1]:.2f} s of takes), 2 workers {two[0]:.2f} s ({two[1]:.2f} s of takes): speed-up "
          f"{speed_wall:.2f}x whole run (each round: {', '.join(f'{r:.2f}' for r in per_round)}), {speed_takes:.2f}x "
          f"takes alone; fixed part on 2 workers {', '.join(f'{f:.2f}' for f in fixed)} s (of which the cluster's "
          f"start {', '.join(f'{f:.2f}' for f in started)} s); the whole command (rig load included) {one[5]:.1f} s "
          f"against {two[5]:.1f} s, {speed_command:.2f}x; {concurrency:.2f} takes at once on average, each "
          f"{slowdown:.2f}x as long as on 1 worker; CPU of all the batch's processes {one[4]:.1f} s on 1 worker, "
          f"{two[4]:.1f} s on 2; load average {load:.1f} on {os.cpu_count()} cores")


_PLAIN = """
import json, sys, time
from app.runtime import limit_blas_threads
limit_blas_threads()
from model.marker_map import load_marker_map
from model.readers import load_rig
from model.take_exports import export_report, export_weights_csv
from model.take_workspace import TakeWorkspace
rig_dir, map_path, out, *takes = sys.argv[1:]
t0 = time.perf_counter()
rig = load_rig(rig_dir)
rig_s = time.perf_counter() - t0
mm = load_marker_map(map_path)
t0 = time.perf_counter()
for i, p in enumerate(takes):
    ws = TakeWorkspace(rig)
    ws.load_take(p)
    ws.set_map(mm, strict=False)
    ws.solve({"mode": "global", "residual": None, "calibration_frames": 30, "fixed_head": False})
    export_weights_csv(ws, f"{out}/w{i}.csv")
    export_report(ws, f"{out}/r{i}.json")
print(json.dumps({"rig_s": rig_s, "per_take_s": (time.perf_counter() - t0) / len(takes)}))
"""


def _plain(takes, take_dir, out, env_extra):
    """Seconds per take of a plain solve + export (what a ``solve`` command does after loading the rig), in a
    fresh process, and the rig's load time."""
    import json
    import subprocess
    import sys
    env = dict(os.environ, **env_extra)
    proc = subprocess.run([sys.executable, "-c", _PLAIN, str(take_dir.parent.parent / "ict-facekit"),
                           str(take_dir / "marker_map.json"), str(out), *map(str, takes)],
                          capture_output=True, text=True, env=env, timeout=1800, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_bench_batch_overhead_per_take(benchmark, take_dir, bench_takes, tmp_path):
    """Per take: a plain solve and export in a fresh process, against the batch's take on one worker. The plain
    solve runs twice: as ``solve`` runs (BLAS limited to one thread at run time by threadpoolctl) and as a Dask
    worker runs (its nanny also sets OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=1 before numpy loads)."""
    takes = bench_takes[:8]
    env_one = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    as_solve = _plain(takes, take_dir, tmp_path, {})
    as_worker = _plain(takes, take_dir, tmp_path, env_one)
    wall, takes_s, *_ = benchmark.pedantic(_run, args=(take_dir, takes, tmp_path / "one", 1), rounds=1, iterations=1)
    batch_s = takes_s / len(takes)
    plain_s = as_worker["per_take_s"]
    benchmark.extra_info.update(plain_solve_per_take_s=as_solve["per_take_s"], plain_solve_one_thread_env_s=plain_s,
                                batch_per_take_s=batch_s, overhead_per_take_s=batch_s - plain_s,
                                rig_load_s=as_solve["rig_s"], batch_wall_s=wall)
    print(f"\nper take (358 frames): plain solve + export {plain_s:.2f} s with one BLAS thread from the start "
          f"({as_solve['per_take_s']:.2f} s as `solve` runs today), batch on 1 worker {batch_s:.2f} s "
          f"(overhead {batch_s - plain_s:+.2f} s: preview, set writing, Dask); a `solve` command also loads the rig "
          f"({as_solve['rig_s']:.1f} s) each time; batch run wall {wall:.1f} s for {len(takes)} takes, "
          f"load average {os.getloadavg()[0]:.1f}")


_SIDE_BY_SIDE = """
import argparse, json, os, sys, tempfile, time
import app.batch_worker                         # as the local cluster's fork server: the kernel, the preview's modules
from app.runtime import limit_blas_threads
limit_blas_threads()
from app.cli_batch import prepare_job
from app.cli_solve import add_solve_options
from model.batch import solve_take_file
from model.readers import load_rig
rig_dir, map_path, start, *takes = sys.argv[1:]
p = argparse.ArgumentParser()
add_solve_options(p)
job = prepare_job(load_rig(rig_dir), p.parse_args(["--map", map_path]))
out = tempfile.mkdtemp()
solve_take_file(job, takes[0], out + "/warm")
while time.time() < float(start):
    time.sleep(0.005)
t0 = time.perf_counter()
for i, t in enumerate(takes):
    solve_take_file(job, t, f"{out}/t{i}")
print(json.dumps({"per_take_s": (time.perf_counter() - t0) / len(takes)}))
"""


def test_bench_batch_machine_ceiling(benchmark, take_dir, bench_takes):
    """What two cores give for the batch's own per-take work without Dask: ``solve_take_file`` (solve, outputs,
    preview) in one process, then in two processes side by side; the ratio bounds any 2-worker speed-up here."""
    import json
    import subprocess
    import sys

    def run(n: int) -> float:
        start = time.time() + 25.0            # both processes loaded and warm before the clock starts
        procs = [subprocess.Popen([sys.executable, "-c", _SIDE_BY_SIDE, str(take_dir.parent.parent / "ict-facekit"),
                                   str(take_dir / "marker_map.json"), str(start), *map(str, bench_takes[:8])],
                                  stdout=subprocess.PIPE, text=True) for _ in range(n)]
        outs = [json.loads(p.communicate(timeout=900)[0].strip().splitlines()[-1]) for p in procs]
        return max(o["per_take_s"] for o in outs)

    alone = run(1)
    together = benchmark.pedantic(run, args=(2,), rounds=1, iterations=1)
    ceiling = 2 * alone / together
    benchmark.extra_info.update(per_take_alone_s=alone, per_take_side_by_side_s=together, ceiling=ceiling)
    print(f"\nthe batch's per-take work without Dask: {alone:.3f} s a take alone, {together:.3f} s side by side in two "
          f"processes: two cores give at most {ceiling:.2f}x here; load average {os.getloadavg()[0]:.1f}")
