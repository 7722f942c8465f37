"""``solvers.raster.draw``, the CPU rasteriser of a batch's previews, against references worked out independently:
the area a triangle covers (its shoelace area), the pinhole projection of a point, which of two surfaces is nearer,
the lighting equation at a face turned to the lights, and which faces are culled. ``tests/test_batch.py`` compares
its pictures of ICT FaceKit with VTK's on OpenGL."""
from __future__ import annotations

import numpy as np
import pytest

from solvers.raster import draw

SIZE = (64, 48)
CAMERA = (np.zeros(3), np.array([0.0, 0.0, 10.0]), np.array([0.0, 1.0, 0.0]))   # looking down -z from z = 10
BLACK = (0.0, 0.0, 0.0)


def _draw(points, triangles, both=None, *, lights=(), ambient=(1.0, 1.0, 1.0), diffuse=BLACK, specular=BLACK,
          power=20.0, normals=None, size=SIZE, camera=CAMERA, bottom=BLACK, top=BLACK):
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if normals is None:
        normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    if both is None:
        both = np.zeros(len(triangles), dtype=bool)
    return draw(points, normals, triangles, both, size=size, camera=camera, view_angle=30.0, lights=list(lights),
                ambient=ambient, diffuse=diffuse, specular=specular, specular_power=power,
                background_bottom=bottom, background_top=top)


def _project(p, size=SIZE, distance=10.0):
    """Where a point lands in the picture (x right, y down, in pixels) through a pinhole 10 units away with a
    vertical view angle of 30 degrees: worked out here from the angle, not from the rasteriser's camera."""
    w, h = size
    half_height = distance - p[2]
    half_height *= np.tan(np.radians(15.0))
    return (w / 2 + p[0] / half_height * h / 2, h / 2 - p[1] / half_height * h / 2)


def test_a_triangle_covers_its_area_and_lands_where_a_pinhole_puts_it():
    """White on black, each pixel's level is the share of its 4 samples the triangle covers: summed over the
    picture, the triangle's area in pixels (shoelace formula of its projected corners) to within a few pixels of
    sampling error along its edges; and its corners' projections bound what is drawn."""
    tri = np.array([[-2.0, -1.5, 0.0], [2.5, -1.0, 0.0], [0.3, 2.2, 0.0]])
    img = _draw(tri, [[0, 1, 2]])
    corners = np.array([_project(p) for p in tri])
    (x0, y0), (x1, y1), (x2, y2) = corners
    area = abs((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)) / 2
    covered = img[..., 0].astype(float).sum() / 255
    perimeter = sum(np.hypot(*(corners[i] - corners[i - 1])) for i in range(3))
    assert abs(covered - area) < 0.1 * perimeter, (covered, area)
    assert area > 300                      # not a toy: a few hundred pixels
    ys, xs = np.nonzero(img[..., 0])
    assert xs.min() >= np.floor(corners[:, 0].min()) and xs.max() <= np.floor(corners[:, 0].max())
    assert ys.min() >= np.floor(corners[:, 1].min()) and ys.max() <= np.floor(corners[:, 1].max())
    assert np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])


def test_the_nearer_surface_hides_the_farther_whatever_the_order():
    """Two squares overlapping in the picture, one nearer the eye: drawn in either order, the nearer one's colour
    shows where they overlap (each sample keeps the nearest surface), the farther one's only outside it."""
    near = [[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [1.0, 1.0, 2.0], [-1.0, 1.0, 2.0]]
    far = [[-0.5, -0.5, -1.0], [2.5, -0.5, -1.0], [2.5, 2.5, -1.0], [-0.5, 2.5, -1.0]]
    quads = [[0, 1, 2], [0, 2, 3]]

    def picture(first, second):
        pts = np.array(first + second)
        normals = np.tile([0.0, 0.0, 1.0], (8, 1))
        # the square given first is lit by the headlight (red over the ambient green); the second's normals point
        # away from it (ambient green only), so the two squares show different colours
        normals[4:] = [0.0, 0.0, -1.0]
        return draw(pts, normals, np.array(quads + [[a + 4 for a in q] for q in quads]), np.zeros(4, bool),
                    size=SIZE, camera=CAMERA, view_angle=30.0, lights=[((0.0, 0.0, -1.0), 1.0)],
                    ambient=(0.0, 0.5, 0.0), diffuse=(1.0, 0.0, 0.0), specular=BLACK, specular_power=1.0,
                    background_bottom=BLACK, background_top=BLACK)

    a, b = picture(near, far), picture(far, near)
    cx, cy = (int(v) for v in _project(np.array([0.5, 0.5, 2.0])))      # inside both squares
    assert tuple(a[cy, cx]) == (255, 128, 0)      # the near square: lit by the light, red over the ambient green
    assert tuple(b[cy, cx]) == (0, 128, 0)        # now the near square is the unlit one
    fx, fy = (int(v) for v in _project(np.array([2.0, 2.0, -1.0])))     # inside the far square only
    assert tuple(a[fy, fx]) == (0, 128, 0) and tuple(b[fy, fx]) == (255, 128, 0)


def _lit(p, n, lights, power):
    """(diffuse, specular) sums of the lighting equation at a point ``p`` with unit normal ``n``, the eye at
    (0, 0, 10): Σ intensity·max(0, n·-l) and Σ intensity·max(1e-5, reflect(l, n)·e)^p where n·-l > 0."""
    e = (np.array([0.0, 0.0, 10.0]) - p) / np.linalg.norm(np.array([0.0, 0.0, 10.0]) - p)
    d = s = 0.0
    for l, i in lights:
        l = np.asarray(l, float) / np.linalg.norm(l)
        if n @ -l > 0:
            d += i * (n @ -l)
            s += i * max(1e-5, (l - 2 * (n @ l) * n) @ e) ** power
    return d, s


def test_a_face_turned_to_the_lights_has_the_lighting_equations_colour():
    """Ambient + Σ intensity·(n·-l)·diffuse + Σ intensity·(reflect(l, n)·e)^p·specular, per channel, at each
    vertex (Gouraud), rounded to 8 bits: at the picture's middle, halfway between two opposite corners of a square
    turned to the eye (at the same depth: their plain average), lit by a headlight and by a light from 60 degrees
    above; the eye is near, so each corner sees its own highlight."""
    quad = np.array([[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [3.0, 3.0, 0.0], [-3.0, 3.0, 0.0]])
    lights = [((0.0, 0.0, -1.0), 0.6), ((0.0, -np.sin(np.radians(60.0)), -np.cos(np.radians(60.0))), 0.5)]
    ambient, diffuse, specular = np.array([0.1, 0.05, 0.0]), np.array([0.4, 0.3, 0.2]), np.array([0.2, 0.2, 0.2])
    img = _draw(quad, [[0, 1, 2], [0, 2, 3]], lights=lights, ambient=ambient, diffuse=diffuse, specular=specular,
                power=4.0, size=(65, 49))            # odd: a pixel's centre is the picture's middle
    n = np.array([0.0, 0.0, 1.0])
    (d0, s0), (d2, s2) = _lit(quad[0], n, lights, 4.0), _lit(quad[2], n, lights, 4.0)
    expected = ambient + (d0 + d2) / 2 * diffuse + (s0 + s2) / 2 * specular
    assert abs(s0 - s2) > 0.1                          # the corners' highlights differ: the eye's direction counts
    assert np.abs(img[24, 32].astype(int) - np.floor(expected * 255 + 0.5)).max() <= 1


def test_a_face_turned_away_is_drawn_only_where_its_back_can_show_lit_as_its_back():
    """A face wound clockwise as the eye sees it is turned away: not drawn (culled) unless its back can show, and
    then lit with its normal reversed (the back of a face whose normal points away from a headlight is lit)."""
    tri = np.array([[-2.0, -1.5, 0.0], [0.3, 2.2, 0.0], [2.5, -1.0, 0.0]])       # clockwise from the eye
    away = np.tile([0.0, 0.0, -1.0], (3, 1))
    culled = _draw(tri, [[0, 1, 2]], lights=[((0.0, 0.0, -1.0), 1.0)], ambient=BLACK, diffuse=(1.0, 1.0, 1.0),
                   normals=away)
    shown = _draw(tri, [[0, 1, 2]], both=[True], lights=[((0.0, 0.0, -1.0), 1.0)], ambient=BLACK,
                  diffuse=(1.0, 1.0, 1.0), normals=away)
    assert not culled.any()
    cx, cy = (int(v) for v in _project(tri.mean(axis=0)))
    assert tuple(shown[cy, cx]) == (255, 255, 255)


def test_the_background_runs_from_the_bottom_colour_to_the_top_colour():
    img = _draw(np.zeros((3, 3)), np.zeros((0, 3)), bottom=(0.0, 0.0, 0.0), top=(1.0, 0.5, 0.0))
    h = img.shape[0]
    col = img[:, 0].astype(float)
    assert col[0, 0] > 250 and col[-1, 0] < 5 and np.all(np.diff(col[:, 0]) <= 0)
    t = (h - (np.arange(h) + 0.5)) / h                          # each row's centre, from the bottom
    assert np.abs(col[:, 0] - t * 255).max() <= 0.5 + 1e-9 and np.abs(col[:, 1] - t * 127.5).max() <= 0.5 + 1e-9


@pytest.mark.parametrize("bad", ["nan", "index", "normals"])
def test_what_it_cannot_draw_is_refused_before_the_compiled_loop_runs(bad):
    """Points that are not finite, triangles naming a point the surface lacks and normals of another surface are a
    ValueError, not memory read out of bounds in compiled code."""
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    tris, normals = np.array([[0, 1, 2]]), None
    if bad == "nan":
        pts[1, 0] = np.nan
    elif bad == "index":
        tris = np.array([[0, 1, 3]])
    else:
        normals = np.zeros((2, 3))
    with pytest.raises(ValueError):
        _draw(pts, tris, normals=normals)


def test_a_triangle_reaching_the_eyes_plane_is_drawn_clipped_to_the_picture():
    """A corner a hair in front of the eye projects ~1e7 pixels away: the triangle is drawn where it covers the
    picture (its bounds clamped to the picture before they become pixel indices), and a corner behind the eye
    leaves its triangle out."""
    tri = np.array([[-2.0, -2.0, 0.0], [-2.0, 2.0, 0.0], [1.0, 0.0, 10.0 - 1e-5]])   # float32 keeps the 1e-5
    img = _draw(tri, [[0, 2, 1]], both=[True])
    assert img.shape == (SIZE[1], SIZE[0], 3)
    x_left = _project(tri[0])[0]
    assert img[SIZE[1] // 2, int(x_left) + 2:].min() == 255         # from its near edge to the picture's right
    assert img[SIZE[1] // 2, :int(x_left) - 1].max() == 0
    behind = tri.copy()
    behind[2, 2] = 11.0
    assert not _draw(behind, [[0, 2, 1]], both=[True]).any()
