"""Personalisation speed on the real data: ICT FaceKit (57 shapes, 26,719 vertices) and the 24 pose scans of
``mocap/actor_take`` (Ma et al. 2016 §3; issue 15).

Ma et al. report about 30 s for 86k unknowns; the target here is at least ten times as many unknowns in 30 s
on this 2-core machine. One delta solve of ICT has 3 × 665,761 = 1,997,283 unknowns (every vertex each shape
moves, x, y and z). Figures go into ``benchmark.extra_info`` and are printed with ``-s``.
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
    solve = min(res.delta_seconds)
    benchmark.extra_info.update(unknowns=res.unknowns, delta_solve_seconds=solve, total_seconds=res.seconds,
                                cg_iterations=res.cg_iterations, unknowns_per_second=res.unknowns / solve)
    print(f"\npersonalize: {res.unknowns:,} unknowns in {solve:.2f} s for the delta solve "
          f"({res.cg_iterations[0]} CG iterations), {res.seconds:.1f} s with weights and set-up; "
          f"Ma et al.: 86k in 30 s")
    assert res.unknowns >= 860_000
    assert solve < 30.0
