"""The compiled loop of ``solvers.raster.draw``: one lit, depth-tested, multisampled picture of a triangle mesh.

Compiled ahead of time with the take solver's kernel (``solvers.take_kernel``), so a process that draws with it never
imports numba; ``solvers.raster`` documents the method.
"""
from __future__ import annotations

import math

import numpy as np

from numba import njit

# reassociation and contraction (so that sums vectorise and multiply-adds fuse), without fastmath's no-NaN and
# no-infinity assumptions (``solvers.raster.draw`` refuses points that are not finite anyway)
_FAST = {"reassoc", "contract", "nsz", "arcp", "afn"}


@njit(cache=True, nogil=True)
def draw_mesh(points, normals, tris, both_sides, camera, lights, material, background, samples, image):
    """``_draw_mesh`` (its docstring tells the arguments): the function the ahead-of-time module exports, which
    compiles the function it calls with that function's own options (``_FAST``)."""
    return _draw_mesh(points, normals, tris, both_sides, camera, lights, material, background, samples, image)


@njit(cache=True, nogil=True, fastmath=_FAST)
def _draw_mesh(points, normals, tris, both_sides, camera, lights, material, background, samples, image):
    """Draw the triangles ``tris`` (T, 3) of ``points`` (V, 3) into ``image`` (H, W, 3) uint8; returns the number
    of triangles drawn (facing the camera, or facing away where ``both_sides[t]``, and in front of it).

    ``normals`` (V, 3) unit vertex normals; ``camera`` (14,): the view's rows (x right, y up, z towards the eye:
    9 values), the eye's position (3), 1 / tan(half the vertical view angle), and the width / height ratio;
    ``lights`` (L, 4): each directional light's direction in view coordinates and its intensity; ``material``
    (4, 3): the ambient, diffuse and specular colours (each the material's colour times its coefficient) and the
    specular power (first value of the last row); ``background`` (H, 3) uint8: each row's colour; ``samples`` (S, 2):
    where each of a pixel's samples lies in it (x right, y down, 0-1)."""
    H, W = image.shape[0], image.shape[1]
    S = samples.shape[0]
    V = points.shape[0]
    sx = np.empty(V)
    sy = np.empty(V)
    iw = np.empty(V)
    lit = np.zeros((2, V, 2))
    power = material[3, 0]
    for v in range(V):
        px = points[v, 0] - camera[9]
        py = points[v, 1] - camera[10]
        pz = points[v, 2] - camera[11]
        vx = camera[0] * px + camera[1] * py + camera[2] * pz
        vy = camera[3] * px + camera[4] * py + camera[5] * pz
        vz = camera[6] * px + camera[7] * py + camera[8] * pz
        w = -vz
        if w <= 0.0:
            iw[v] = -1.0           # behind the eye: its triangles are not drawn
            continue
        iw[v] = 1.0 / w
        sx[v] = (camera[12] / camera[13] * vx / w + 1.0) * 0.5 * W
        sy[v] = (1.0 - camera[12] * vy / w) * 0.5 * H
        nx0, ny0, nz0 = normals[v, 0], normals[v, 1], normals[v, 2]
        nx = camera[0] * nx0 + camera[1] * ny0 + camera[2] * nz0
        ny = camera[3] * nx0 + camera[4] * ny0 + camera[5] * nz0
        nz = camera[6] * nx0 + camera[7] * ny0 + camera[8] * nz0
        el = math.sqrt(vx * vx + vy * vy + vz * vz)
        ex, ey, ez = -vx / el, -vy / el, -vz / el
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            mx, my, mz = sign * nx, sign * ny, sign * nz
            for k in range(lights.shape[0]):
                lx, ly, lz, intensity = lights[k, 0], lights[k, 1], lights[k, 2], lights[k, 3]
                d = -(mx * lx + my * ly + mz * lz)
                if d > 0.0:
                    lit[side, v, 0] += d * intensity
                    nl = mx * lx + my * ly + mz * lz                  # reflect(l, m) = l - 2 (m . l) m
                    rx, ry, rz = lx - 2.0 * nl * mx, ly - 2.0 * nl * my, lz - 2.0 * nl * mz
                    lit[side, v, 1] += max(1e-5, rx * ex + ry * ey + rz * ez) ** power * intensity
    depth = np.zeros((H, W, S), dtype=np.float32)        # 1 / w: larger is nearer; 0 is the far background
    color = np.empty((H, W, S, 3), dtype=np.uint8)
    for y in range(H):
        for x in range(W):
            for s in range(S):
                for c in range(3):
                    color[y, x, s, c] = background[y, c]
    drawn = 0
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        if iw[a] <= 0.0 or iw[b] <= 0.0 or iw[c] <= 0.0:
            continue
        x0, y0, x1, y1, x2, y2 = sx[a], sy[a], sx[b], sy[b], sx[c], sy[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area < 0.0:
            side = 0                              # counter-clockwise as the eye sees it (y up): its front
        elif area > 0.0 and both_sides[t]:
            side = 1
        else:
            continue
        # the pixels whose samples may lie inside (every sample of pixel p lies in [p, p + 1)), clamped to the
        # picture before they become integers (a corner near the eye's plane projects far outside it)
        fx0, fx1 = max(min(x0, x1, x2), 0.0), min(max(x0, x1, x2), W - 0.5)
        fy0, fy1 = max(min(y0, y1, y2), 0.0), min(max(y0, y1, y2), H - 0.5)
        if not (fx0 <= fx1 and fy0 <= fy1):
            continue
        xmin, xmax = int(math.floor(fx0)), int(math.floor(fx1))
        ymin, ymax = int(math.floor(fy0)), int(math.floor(fy1))
        drawn += 1
        inv = 1.0 / area
        # barycentric weights as edge functions l_i(x, y) = A_i x + B_i y + C_i (Pineda 1988), l_2 = 1 - l_0 - l_1
        a0, b0, c0 = (y1 - y2) * inv, (x2 - x1) * inv, (x1 * y2 - x2 * y1) * inv
        a1, b1, c1 = (y2 - y0) * inv, (x0 - x2) * inv, (x2 * y0 - x0 * y2) * inv
        w0, w1, w2 = iw[a], iw[b], iw[c]
        d0, d1, d2 = lit[side, a, 0], lit[side, b, 0], lit[side, c, 0]
        s0, s1, s2 = lit[side, a, 1], lit[side, b, 1], lit[side, c, 1]
        for py in range(ymin, ymax + 1):
            for px in range(xmin, xmax + 1):
                shaded = False
                r = g = bl = 0
                for s in range(S):
                    qx = px + samples[s, 0]
                    qy = py + samples[s, 1]
                    l0 = a0 * qx + b0 * qy + c0
                    l1 = a1 * qx + b1 * qy + c1
                    l2 = 1.0 - l0 - l1
                    if l0 < 0.0 or l1 < 0.0 or l2 < 0.0:
                        continue
                    z = l0 * w0 + l1 * w1 + l2 * w2
                    if z <= depth[py, px, s]:
                        continue
                    if not shaded:
                        # lit at the pixel's centre (once a pixel, as multisampling shades), interpolated in
                        # perspective: weights l_i / w_i renormalised
                        cx, cy = px + 0.5, py + 0.5
                        m0 = (a0 * cx + b0 * cy + c0) * w0
                        m1 = (a1 * cx + b1 * cy + c1) * w1
                        m2 = (1.0 - (a0 * cx + b0 * cy + c0) - (a1 * cx + b1 * cy + c1)) * w2
                        ms = m0 + m1 + m2
                        dif = (m0 * d0 + m1 * d1 + m2 * d2) / ms
                        spe = (m0 * s0 + m1 * s1 + m2 * s2) / ms
                        r = _unorm8(material[0, 0] + dif * material[1, 0] + spe * material[2, 0])
                        g = _unorm8(material[0, 1] + dif * material[1, 1] + spe * material[2, 1])
                        bl = _unorm8(material[0, 2] + dif * material[1, 2] + spe * material[2, 2])
                        shaded = True
                    depth[py, px, s] = z
                    color[py, px, s, 0] = r
                    color[py, px, s, 1] = g
                    color[py, px, s, 2] = bl
    half = S // 2
    for y in range(H):
        for x in range(W):
            for c in range(3):
                total = 0
                for s in range(S):
                    total += color[y, x, s, c]
                image[y, x, c] = (total + half) // S
    return drawn


@njit(cache=True, nogil=True, inline="always", fastmath=_FAST)
def _unorm8(v):
    """A colour channel in 0-1 as an 8-bit value, rounded to nearest (OpenGL's conversion to a normalised byte)."""
    return int(math.floor(min(max(v, 0.0), 1.0) * 255.0 + 0.5))
