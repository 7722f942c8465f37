"""A picture of a lit triangle mesh drawn on the CPU, without OpenGL: a batch's previews (``app.cli_batch``).

The picture is the viewport's (``widgets.scene``): a perspective camera, white directional lights, per-vertex
lighting interpolated across each triangle (Gouraud 1971) with the diffuse and Phong (1975) specular terms of
``widgets.scene._vertex_lighting``'s shader (``d = max(0, n·-l)``; ``s = [d > 0] max(1e-5, reflect(l, n)·e)^p``;
colour = ambient + Σd·diffuse + Σs·specular, each light's terms times its intensity), faces seen from behind lit
with their normal reversed where their back can show and not drawn where it cannot (``hidden_back_faces``), a
vertical gradient behind. Triangles are scan-converted with edge functions (Pineda 1988) at 4 samples a pixel, in
the standard 4x multisample pattern (the one llvmpipe and Direct3D use), each sample depth-tested (1/w, linear in the
picture); a pixel's colour is computed once, at its centre, with perspective-correct weights (Heckbert & Moreton
1991), and written to the samples it covers, then the samples are averaged: what OpenGL's multisampling does. On ICT
FaceKit at 480x360 the picture is within a level or two of VTK's on llvmpipe at a few edge pixels and the same
elsewhere (``tests/test_batch.py``; ``tests/test_raster.py`` tests the method against references worked out by
hand: coverage, projection, depth order, lighting, culling).

Why not OpenGL: a batch worker drew its previews through VTK on Mesa's llvmpipe, which cost each worker ~0.2 s of
imports (VTK and the GL driver), ~0.1 s to make its context and compile its shaders before its first preview, and
~35 ms a preview (4x multisampling in software); and a render node without EGL or a display drew no preview. The
loop is compiled ahead of time with the take solver's kernel (``solvers.raster_kernel_jit``, ``solvers.take_kernel``).
"""
from __future__ import annotations

import numpy as np

# where a pixel's 4 samples lie in it (x right, y down; the standard 4x pattern, y mirrored for a picture whose first
# row is its top)
SAMPLES_4X = np.array([[0.375, 0.875], [0.875, 0.625], [0.125, 0.375], [0.625, 0.125]])


def _kernel():
    """The compiled ``draw_mesh``: from the ahead-of-time module when it is built, else numba's."""
    from . import take_kernel
    module = take_kernel.built()
    if module is not None and hasattr(module, "draw_mesh"):
        return module.draw_mesh
    from .raster_kernel_jit import draw_mesh
    return draw_mesh


def camera_rows(center, position, up) -> np.ndarray:
    """(3, 3) the view's axes as rows (x right, y up, z from the focal point towards the eye), as VTK's camera
    makes them from its focal point, position and view up."""
    z = np.asarray(position, np.float64) - np.asarray(center, np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(np.asarray(up, np.float64), z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def draw(points: np.ndarray, normals: np.ndarray, triangles: np.ndarray, both_sides: np.ndarray, *, size,
         camera, view_angle: float, lights, ambient, diffuse, specular, specular_power: float,
         background_bottom, background_top) -> np.ndarray:
    """(h, w, 3) uint8, top row first: ``triangles`` (T, 3) of ``points`` (V, 3) with unit vertex ``normals``,
    seen by ``camera`` (focal point, position, view up; ``view_angle`` degrees, vertical) in a picture of ``size``
    (w, h). ``both_sides`` (T,) bool: the triangle's back can show (else a triangle facing away is not drawn).
    ``lights``: (direction in view coordinates, intensity) of each white directional light; ``ambient``,
    ``diffuse``, ``specular``: RGB colours (0-1) already scaled by the material's coefficients; the background a
    vertical gradient from ``background_bottom`` to ``background_top`` (RGB 0-1)."""
    w, h = (int(v) for v in size)
    points = np.ascontiguousarray(points, dtype=np.float32)
    if not np.isfinite(points).all():
        raise ValueError("the surface to draw has points that are not finite numbers")
    triangles = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(points)):
        raise ValueError("the triangles to draw name points the surface does not have")
    if np.shape(normals) != points.shape or len(both_sides) != len(triangles) or w < 1 or h < 1:
        raise ValueError("the normals, the triangles' sides or the picture's size do not fit the surface")
    center, position, up = camera
    rows = camera_rows(center, position, up)
    cam = np.concatenate([rows.ravel(), np.asarray(position, np.float64),
                          [1.0 / np.tan(np.radians(view_angle) / 2), w / h]])
    light_rows = np.array([[*(np.asarray(d, np.float64) / np.linalg.norm(d)), float(i)] for d, i in lights],
                          dtype=np.float64).reshape(-1, 4)
    material = np.array([ambient, diffuse, specular, [specular_power, 0.0, 0.0]], dtype=np.float64)
    # the gradient as VTK draws it: the colour interpolated between the bottom and top edges, at each row's centre
    t = (h - (np.arange(h) + 0.5)) / h
    bottom, top = np.asarray(background_bottom, np.float64), np.asarray(background_top, np.float64)
    rows_rgb = np.floor(np.clip(bottom + (top - bottom) * t[:, None], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    image = np.empty((h, w, 3), dtype=np.uint8)
    _kernel()(points, np.ascontiguousarray(np.nan_to_num(normals), dtype=np.float32),
              triangles, np.ascontiguousarray(both_sides, dtype=np.uint8),
              cam, light_rows, material, rows_rgb, SAMPLES_4X, image)
    return image
