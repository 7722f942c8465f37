"""Sculpt brushes for authoring correctives (solvers/sculpt.py), on the ICT FaceKit neutral."""
from __future__ import annotations

import numpy as np
import pytest

from model.errors import RigInputError
from solvers.sculpt import (FALLOFFS, GrabStroke, SculptMesh, brush_weights, deflate, falloff, grab, inflate,
                            laplacian_energy, mirror_map, smooth)

R = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def face(ict_rig):
    mesh = SculptMesh.build(ict_rig.neutral, ict_rig.triangles(), symmetric=True)
    cheek = int(np.argmax(np.linalg.norm(ict_rig.deltas[ict_rig.shape_index("mouthSmile_L")], axis=1)))
    return ict_rig.neutral, mesh, cheek


def test_falloff_profiles_are_monotone_from_one_to_zero():
    t = np.linspace(0.0, 1.5, 301)
    for kind in FALLOFFS:
        f = falloff(t, kind)
        assert f[0] == 1.0
        assert np.all(np.diff(f) <= 0), kind
        assert np.all(f[t >= 1.0] == 0.0)
        assert np.all(f[t < 0.99] > 0.0)
    with pytest.raises(RigInputError, match="falloff"):
        falloff(t, "gaussian")


def test_grab_moves_only_vertices_inside_the_radius(face):
    neutral, mesh, cheek = face
    c, r, drag = neutral[cheek], 1.5, np.array([0.3, 0.2, 0.4])
    for kind in FALLOFFS:
        out = grab(neutral, c, drag, r, kind, strength=1.0, mesh=mesh)
        moved = np.linalg.norm(out - neutral, axis=1)
        dist = np.linalg.norm(neutral - c, axis=1)
        assert np.all(moved[dist >= r] == 0.0)
        assert np.all(moved[dist < 0.95 * r] > 0.0)
        assert np.allclose(out[cheek] - neutral[cheek], drag, rtol=0, atol=1e-12)
        # displacement falls off monotonically with distance from the centre
        inside = np.flatnonzero(dist < r)
        order = inside[np.argsort(dist[inside], kind="stable")]
        assert np.all(np.diff(moved[order]) <= 1e-12)
    assert np.array_equal(neutral, face[0])  # the input is not modified


def test_mirror_map_pairs_the_two_sides_of_the_face(face):
    neutral, mesh, _ = face
    m = mesh.mirror
    assert np.array_equal(m, mirror_map(neutral))
    involution = m[m] == np.arange(m.size)
    assert involution.mean() > 0.95
    err = np.linalg.norm(neutral[m] - neutral * R, axis=1)
    assert np.median(err) < 1e-3  # ICT FaceKit is built symmetric (cm)


def test_symmetric_grab_mirrors_the_stroke(face):
    neutral, mesh, cheek = face
    c, r, drag = neutral[cheek], 1.5, np.array([0.3, 0.2, 0.4])
    one = grab(neutral, c, drag, r, mesh=mesh) - neutral
    both = grab(neutral, c, drag, r, mesh=mesh, symmetric=True) - neutral
    m = mesh.mirror
    ok = m[m] == np.arange(m.size)
    # exactly mirror-symmetric: Δ(m(v)) = R Δ(v)
    assert np.allclose(both[m[ok]], both[ok] * R, rtol=0, atol=1e-12)
    # the stroke side is unchanged (the cheek is far from the plane), the other side got the mirror image
    assert np.allclose(both[cheek], drag, atol=1e-12)
    assert np.allclose(both[m[cheek]], drag * R, atol=1e-12)
    near = np.linalg.norm(one, axis=1) > 0
    assert np.allclose(both[near], one[near], atol=1e-12)
    assert np.count_nonzero(np.linalg.norm(both, axis=1)) == 2 * np.count_nonzero(near)
    # a stroke across the mirror plane is not doubled
    mid = int(np.argmin(np.abs(neutral[:, 0]) + 10 * (neutral[:, 2] < neutral[:, 2].max() - 1)))
    up = np.array([0.0, 0.0, 0.5])
    across = grab(neutral, neutral[mid], up, 1.0, mesh=mesh, symmetric=True) - neutral
    assert np.linalg.norm(across, axis=1).max() <= 0.5 + 1e-9


def test_a_grab_stroke_gives_exactly_what_grab_gives_at_each_drag(face):
    """GrabStroke (the weights found once at the press, the reached vertices only at each move) against ``grab`` on
    the whole surface as the sculpt tool called it every move: the same numbers, bit for bit, one-sided and
    symmetric, across the mirror plane, every falloff, with and without an offset before the stroke."""
    neutral, mesh, cheek = face
    rng = np.random.default_rng(5)
    points = neutral + rng.normal(0, 0.01, neutral.shape)          # a sculpted surface, not the neutral
    mid = int(np.argmin(np.abs(neutral[:, 0]) + 10 * (neutral[:, 2] < neutral[:, 2].max() - 1)))
    before = np.zeros_like(points)
    before[rng.integers(0, len(points), 500)] = rng.normal(0, 0.1, (500, 3))
    before[:3] = -0.0
    for centre in (points[cheek], points[mid]):
        for symmetric in (False, True):
            for kind, strength in zip(FALLOFFS, (1.0, 0.35, -0.6)):
                stroke = GrabStroke(points, centre, 1.7, kind, strength, mesh=mesh, symmetric=symmetric)
                assert 0 < stroke.reach.size < len(points) // 10
                for drag in (np.array([0.3, -0.2, 0.05]), np.array([-1e-3, 0.0, 2.5]), np.zeros(3)):
                    pulled = grab(points, centre, drag, 1.7, kind, strength, mesh=mesh, symmetric=symmetric,
                                  reference=points)
                    for old in (None, before):
                        want = (np.zeros_like(points) if old is None else old) + (pulled - points)
                        got = stroke.offset(drag, old, len(points))
                        assert got.dtype == want.dtype and np.array_equal(got, want)
                        assert np.array_equal(np.signbit(got), np.signbit(want))
    with pytest.raises(RigInputError, match="mirror map"):
        GrabStroke(points, points[cheek], 1.0, mesh=SculptMesh.build(neutral, mesh.triangles, symmetric=False),
                   symmetric=True)


def test_smooth_reduces_laplacian_energy_inside_the_brush_only(face):
    neutral, mesh, cheek = face
    rng = np.random.default_rng(0)
    c, r = neutral[cheek], 2.0
    dist = np.linalg.norm(neutral - c, axis=1)
    noisy = neutral + (dist < r)[:, None] * rng.normal(scale=0.05, size=neutral.shape)
    out = smooth(noisy, c, r, mesh, strength=0.8, iterations=3)
    core = np.flatnonzero(dist < 0.5 * r)
    assert laplacian_energy(out, mesh.average, core) < 0.2 * laplacian_energy(noisy, mesh.average, core)
    assert laplacian_energy(out, mesh.average) < laplacian_energy(noisy, mesh.average)
    assert np.array_equal(out[dist >= r], noisy[dist >= r])
    sym = smooth(noisy, c, r, mesh, strength=0.8, iterations=3, symmetric=True)
    assert laplacian_energy(sym, mesh.average, core) < 0.2 * laplacian_energy(noisy, mesh.average, core)


def test_inflate_and_deflate_move_along_the_normals(face):
    neutral, mesh, cheek = face
    c, r = neutral[cheek], 1.0
    normals = mesh.normals(neutral)
    up = inflate(neutral, c, r, mesh, 0.2, normals=normals)
    down = deflate(neutral, c, r, mesh, 0.2, normals=normals)
    assert np.allclose(up[cheek] - neutral[cheek], 0.2 * normals[cheek], atol=1e-12)
    assert np.allclose(down - neutral, -(up - neutral), atol=1e-12)
    dist = np.linalg.norm(neutral - c, axis=1)
    assert np.all(up[dist >= r] == neutral[dist >= r])
    # outward on a face: the cheek normal points forward (+z) on ICT FaceKit
    assert normals[cheek, 2] > 0.3
    sym = inflate(neutral, c, r, mesh, 0.2, normals=normals, symmetric=True)
    m = mesh.mirror
    assert np.allclose(sym[m[cheek]] - neutral[m[cheek]], (0.2 * normals[cheek]) * R, atol=1e-12)


def test_brush_rejects_a_bad_radius(face):
    neutral, _, cheek = face
    with pytest.raises(RigInputError, match="radius"):
        brush_weights(neutral, neutral[cheek], 0.0)
    with pytest.raises(RigInputError, match="mirror"):
        grab(neutral, neutral[cheek], [0, 0, 1], 1.0, symmetric=True)
