"""Marker drag speed on ICT FaceKit (ALGORITHMS.md §8): one regional solve, and one drag-to-redraw step."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.markers import Marker, MarkerSet
from solvers.regional_solve import RegionalSolver

LANDMARKS = (30, 48, 54, 19, 24, 8)   # iBUG: nose tip, mouth corners, brows, chin


@pytest.fixture(scope="module")
def ict_drag(ict_rig, ict_dir):
    from model.segmentation import segment_rig
    seg = segment_rig(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, ict_rig.deltas)
    level = seg.levels[(len(seg.levels) - 1) // 2]
    lm = json.loads((ict_dir / "vertex_indices.json").read_text())["idx_to_landmark_verts"]
    ms = MarkerSet.for_rig(ict_rig, [Marker(f"M{i}", vertex=int(lm[i])) for i in LANDMARKS])
    return seg, level, ms


def _drag_solver(rig, level, ms):
    """What a press builds for the drag: the regional solver of the level for the markers (ALGORITHMS §8)."""
    return RegionalSolver([r.vertices for r in level.regions], ms.S, ms.delta_rows(rig.deltas),
                          deltas=rig.deltas, solve_background=True)


def test_bench_one_drag_solve_cold(benchmark, ict_rig, ict_drag):
    """Cold: the press (the level's solver for these markers) and the first move, from the rest pose."""
    _, level, ms = ict_drag
    W = np.zeros((level.n_regions + 1, ict_rig.n_shapes))
    targets = ms.positions(ict_rig.neutral)
    targets[1] += np.array([0.5, 0.4, 0.0])  # pull a mouth corner
    b = (targets - ms.positions(ict_rig.neutral)).reshape(-1)
    out = benchmark(lambda: _drag_solver(ict_rig, level, ms).solve(b, W))
    assert out.min() >= 0 and out.max() <= 1 and out.any()


def test_bench_one_drag_solve(benchmark, ict_rig, ict_drag):
    """Warm: one move of a drag, the press's solver reused and started from the previous move's pose."""
    _, level, ms = ict_drag
    solver = _drag_solver(ict_rig, level, ms)
    W = np.zeros((level.n_regions + 1, ict_rig.n_shapes))
    targets = ms.positions(ict_rig.neutral)
    targets[1] += np.array([0.5, 0.4, 0.0])  # pull a mouth corner
    b = (targets - ms.positions(ict_rig.neutral)).reshape(-1)
    # During a drag each move starts from the pose of the previous move (the controller's warm start).
    W_prev = solver.solve(b, W)
    targets[1] += np.array([0.01, 0.01, 0.0])
    b2 = (targets - ms.positions(ict_rig.neutral)).reshape(-1)
    out = benchmark(solver.solve, b2, W_prev)
    assert out.min() >= 0 and out.max() <= 1 and out.any()
    benchmark.extra_info["regions"] = level.n_regions
    assert benchmark.stats.stats.median < 0.005


def test_bench_drag_to_redraw_step(benchmark, qtbot, tmp_path, ict_rig, ict_drag):
    """Solve + regional evaluation + viewport point update + render, through the window's marker controller."""
    from model.project import Project
    from tests.gui_helpers import make_window
    seg, level, ms = ict_drag
    w = make_window(qtbot, tmp_path, size=(1400, 900))   # the main window's default size
    c = w.markers
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=30000)
    w.document.set_project(Project(rig=ict_rig.copy()), None)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=120000)
    w.segmentation.wait()
    qtbot.waitUntil(lambda: c.panel.level.count() > 1, timeout=120000)
    for m in ms.markers:
        assert c.add_marker_at(m.vertex, name=m.name)
    c.begin_drag(1)
    step = [0]

    def drag_step():
        step[0] += 1
        c.drag_by(np.array([0.02 * (step[0] % 25), 0.015 * (step[0] % 25), 0.0]))
        w.redraw_now()  # viewport point update + render

    import time
    t0 = time.perf_counter()
    for _ in range(10):  # the same step without the render, for the report
        step[0] += 1
        c.drag_by(np.array([0.02 * (step[0] % 25), 0.015 * (step[0] % 25), 0.0]))
        w.viewport.mesh.points = w.document.surface()
    benchmark.extra_info["step_without_render_ms"] = (time.perf_counter() - t0) / 10 * 1000
    benchmark.pedantic(drag_step, rounds=20, iterations=1, warmup_rounds=2)
    c.end_drag()
    benchmark.extra_info["regions"] = w.segmentation.segmentation.levels[c.level].n_regions
    assert benchmark.stats.stats.median < 0.050


@pytest.mark.parametrize("cold", [False, True], ids=["warm", "cold"])
def test_bench_one_drag_move_with_correctives(benchmark, ict_rig, ict_drag, cold):
    """One move of a drag on ICT with four correctives (Smith's brow pair and three mouth and eye pairs):
    the Gauss–Newton solves of ``MarkerController._solve_with_correctives``; cold includes the press."""
    from types import SimpleNamespace

    from app.marker_controller import MarkerController
    from model.correctives import Corrective, set_correctives, solver_correctives
    from solvers.correctives import driver_region
    _, level, ms = ict_drag
    rig = ict_rig.copy()
    cs = []
    for drivers in (["browInnerUp_L", "browInnerUp_R"], ["mouthSmile_L", "jawOpen"], ["mouthSmile_R", "jawOpen"],
                    ["eyeLookUp_L", "eyeWide_L"]):
        d = rig.deltas[[rig.shape_index(n) for n in drivers]]
        cs.append(Corrective(drivers=drivers, delta=-0.2 * driver_region(d)[:, None] * d.sum(axis=0)))
    set_correctives(rig, cs)
    W = np.zeros((level.n_regions + 1, rig.n_shapes))
    W[:, rig.shape_index("jawOpen")] = 0.5
    targets = ms.positions(ict_rig.neutral + 0.5 * rig.deltas[rig.shape_index("jawOpen")])
    targets[1] += np.array([0.5, 0.4, 0.0])  # pull a mouth corner
    b = (targets - ms.positions(rig.neutral)).reshape(-1)

    def press():
        """What a press sets up: the level's solver and the correctives' linearisation at the markers."""
        activate, E, drivers = solver_correctives(rig)
        return SimpleNamespace(W=W, solver=_drag_solver(rig, level, ms),
                               correctives=(activate, ms.delta_rows(E).T, np.asarray(drivers)))

    smiles = [rig.shape_index("mouthSmile_L"), rig.shape_index("mouthSmile_R")]
    if cold:      # the press and the first move
        out = benchmark(lambda: MarkerController._solve_with_correctives(press(), b))
    else:         # a later move: the press's set-up reused, started from the previous move's pose
        dr = press()
        dr.W = MarkerController._solve_with_correctives(dr, b)     # the previous move: the warm start
        b[3:6] += 0.01
        out = benchmark(MarkerController._solve_with_correctives, dr, b)
        assert benchmark.stats.stats.median < 0.02
    assert out.min() >= 0 and out.max() <= 1 and out[:, smiles].any()
