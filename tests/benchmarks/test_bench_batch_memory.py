"""Memory of a batch on a studio-scale rig (issues 20 and 21): ``blendshape-studio batch`` of 4 takes on the
228-shape studio projects (``test_bench_studio_memory.studio_project``: ICT subdivided once and twice, 106,117 and
422,121 vertices, its shapes split into local ones; 0.54 and 2.15 GiB of float64 deltas) with 2 workers. The command's processes -- the command,
the local cluster's fork server, the driver, the scheduler and the workers -- are sampled every 0.1 s while it runs:
the peak of their summed proportional set size (PSS: a page shared by n processes counts 1/n in each, so the sum
is the batch's physical memory), with their maps of in-memory files taken out and those files (the job's,
``model.batch_driver``) counted whole instead, and each process's peak private memory (USS, without the pages of the
in-memory files: a page of the job's file that one worker has touched before any other is unique to it for a while,
not a copy), against the rig's delta array.

The job reaches the driver and the workers through one memory file they all map (``model.shared_pickle``), so the
rig's arrays are in memory twice (the command's own and the file) whatever the number of workers; before, the
driver and every worker each unpickled a copy of its own.

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_batch_memory.py --benchmark-only -s

The take is the shared marker take (the studio rig keeps ICT's vertex order, so its marker map fits), 358 frames.
The project is built and cached the first time (about a minute).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import time

import pytest

from tests.benchmarks.test_bench_studio_memory import studio_project
from tests.cli_runner import command

pytest.importorskip("distributed")
psutil = pytest.importorskip("psutil")

GiB = 1024 ** 3


def _tree(root: psutil.Process) -> list[psutil.Process]:
    try:
        return [root, *root.children(recursive=True)]
    except psutil.Error:
        return []


def _role(p: psutil.Process, root: psutil.Process) -> str:
    """The command, the resource tracker, the fork server, the driver ("dask-batch"), the scheduler or a worker."""
    if p.pid == root.pid:
        return "command"
    cmd = " ".join(p.cmdline())
    if "resource_tracker" in cmd:
        return "resource tracker"
    if p.ppid() == root.pid:
        return "fork server"
    with open(f"/proc/{p.pid}/comm") as f:
        comm = f.read().strip()
    return comm if comm.startswith("dask-") else "worker"


def _sample(procs: list[psutil.Process], root: psutil.Process) -> tuple[dict[int, tuple[str, int, int]], int]:
    """(pid: (name, PSS without in-memory files, USS without in-memory files) of each process still there; bytes of
    the in-memory files they hold open)."""
    out, files = {}, {}
    for p in procs:
        try:
            m = p.memory_full_info()
            memfd = [mp for mp in p.memory_maps() if mp.path.startswith("/memfd:")]
            in_memfd = sum(mp.pss for mp in memfd)                                    # counted below
            # a page of the job's file that only this process has touched yet is "unique" to it too: not its own
            own = m.uss - sum(mp.private_clean + mp.private_dirty for mp in memfd)
            out[p.pid] = (_role(p, root), m.pss - in_memfd, own)
            for fd in os.listdir(f"/proc/{p.pid}/fd"):
                path = f"/proc/{p.pid}/fd/{fd}"
                if os.readlink(path).startswith("/memfd:"):
                    st = os.stat(path)
                    files[st.st_ino] = st.st_size
        except (psutil.Error, OSError):
            pass
    return out, sum(files.values())


@pytest.mark.parametrize("levels", [1, 2], ids=["106k", "422k"])
def test_bench_batch_memory_on_the_studio_rig(benchmark, take_dir, tmp_path, levels):
    rig = studio_project(levels)
    from model.readers import load_rig
    loaded = load_rig(rig)
    deltas, vertices = loaded.deltas.nbytes, loaded.n_vertices
    del loaded
    takes = []
    for i in range(4):
        takes.append(shutil.copy(take_dir / "take.c3d", tmp_path / f"take_{i}.c3d"))   # four files, one take

    def run():
        proc = subprocess.Popen([*command(), "batch", str(rig), *map(str, takes), "-o", str(tmp_path / "out"),
                                 "--map", str(take_dir / "marker_map.json"), "--workers", "2", "--force"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        root = psutil.Process(proc.pid)
        peak_total, peak_worker, roles, at_peak = 0, {}, {}, ""
        while proc.poll() is None:
            s, in_files = _sample(_tree(root), root)
            total = sum(pss for _, pss, _ in s.values()) + in_files
            if total > peak_total:
                peak_total = total
                at_peak = ", ".join(f"{name} {pss / GiB:.2f}" for name, pss, _ in s.values()) + \
                    f", in-memory files {in_files / GiB:.2f}"
            for pid, (cmd, _, uss) in s.items():
                roles[pid] = cmd
                peak_worker[pid] = max(peak_worker.get(pid, 0), uss)
            time.sleep(0.1)
        out, err = proc.communicate()
        assert proc.returncode == 0, err[-2000:]
        return peak_total, peak_worker, roles, at_peak

    peak_total, peak_uss, roles, at_peak = benchmark.pedantic(run, rounds=1, iterations=1)
    summary = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert summary["solved"] == 4, summary
    ranked = sorted(peak_uss.items(), key=lambda kv: -kv[1])
    benchmark.extra_info.update(deltas_gib=deltas / GiB, peak_pss_total_gib=peak_total / GiB,
                                peak_uss_gib=[(roles[pid], uss / GiB) for pid, uss in ranked[:6]], at_peak=at_peak)
    print(f"\nbatch of 4 takes on 2 workers, {vertices:,}-vertex 228-shape studio rig (deltas {deltas / GiB:.2f} GiB): "
          f"the batch's processes together peaked at {peak_total / GiB:.2f} GiB ({peak_total / deltas:.2f}x the "
          f"deltas; GiB at that moment: {at_peak}); private memory (USS without the job's file) peaks: "
          + ", ".join(f"{roles[pid]} {uss / GiB:.2f}" for pid, uss in ranked[:6]) + " GiB")
    # no worker and not the driver holds a copy of the rig: each one's private memory stays under the deltas' size
    # (before the shared job file: 0.73 GiB a worker and 0.69 GiB the driver here, for 0.54 GiB of deltas)
    for pid, uss in peak_uss.items():
        if roles[pid] in ("worker", "dask-batch"):
            assert uss < deltas, f"a {roles[pid]} holds {uss / GiB:.2f} GiB of its own"
