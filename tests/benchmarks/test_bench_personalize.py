"""Personalisation speed on the real data: ICT FaceKit (57 shapes, 26,719 vertices) and the 24 pose scans of
``mocap/actor_take`` (Ma et al. 2016 §3; issue 15).

Ma et al. report about 30 s for 86k unknowns; the target here is at least ten times as many unknowns in 30 s
on this 2-core machine. One delta solve of ICT has 3 × 665,761 = 1,997,283 unknowns (every vertex each shape
moves, x, y and z). Figures go into ``benchmark.extra_info`` and are printed with ``-s``; the time asserted is
the delta solve's CPU time (``time.process_time``), which other jobs on the machine do not inflate.
"""
from __future__ import annotations

import numpy as np
import pytest

from model.obj_io import read_obj
from solvers.personalize import personalize


@pytest.fixture(scope="module")
def actor_scans(ict_rig):
    from tests.conftest import DATA, require_data
    folder = require_data(DATA / "mocap" / "actor_take")
    neutral = read_obj(folder / "actor_neutral.obj").vertices
    scans = np.stack([read_obj(p).vertices for p in sorted((folder / "scans").glob("*.obj"))])
    return neutral, scans


def test_bench_personalize_delta_solve(benchmark, ict_rig, actor_scans):
    neutral, scans = actor_scans
    tris = ict_rig.triangles()

    def run():
        return personalize(ict_rig.neutral, ict_rig.deltas, tris, scans, neutral, iterations=1)

    res = benchmark.pedantic(run, rounds=1, iterations=1)
    solve, cpu = min(res.delta_seconds), min(res.delta_cpu_seconds)
    benchmark.extra_info.update(unknowns=res.unknowns, delta_solve_seconds=solve, delta_solve_cpu_seconds=cpu,
                                total_seconds=res.seconds, cg_iterations=res.cg_iterations,
                                unknowns_per_cpu_second=res.unknowns / cpu, times_ma_unknowns=res.unknowns / 86_000)
    print(f"\npersonalize: {res.unknowns:,} unknowns ({res.unknowns / 86_000:.0f}x Ma's 86k) in {cpu:.1f} s CPU "
          f"({solve:.1f} s wall) for the delta solve ({res.cg_iterations[0]} CG iterations), {res.seconds:.1f} s "
          "with weights and set-up; Ma et al.: 86k in 30 s")
    # the target: at least 10x Ma's unknowns in 30 s (CPU time: the wall clock of a shared machine is
    # whatever the other jobs leave)
    assert res.unknowns >= 10 * 86_000
    assert cpu < 30.0
