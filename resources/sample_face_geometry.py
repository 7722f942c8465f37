"""Procedural geometry of the bundled sample face: a lofted head mask with features, cut eye and mouth
openings, lid margins tucked into the sockets, a mouth cavity and two eyeballs.

Everything is generated from the numbers in this file (nothing is copied from a scanned or modelled
head). Coordinates are centimetres, Y up, looking down +Z, the character's left on +X (the orientation of
ICT FaceKit). The surface is built in this order:

1. A grid of rows x columns. Each row is a horizontal cross-section (superellipse) of the head at a point
   of a midline profile spline running from under the chin over the forehead; columns are angles around
   the vertical axis. The grid is symmetric about x = 0 (odd column count, mirrored angles).
2. Three slits are cut along grid rows (two eyes, the mouth): the vertices strictly between the slit's
   corner columns are duplicated so the rows above and below separate, and the slit is opened by a
   smooth vertical warp (an almond for the eyes, a small gap for the lips).
3. Features are added as smooth height offsets in Z (brow ridge, sockets, nose, cheekbones, lips, chin).
   Around each eye the lids are wrapped over an ellipsoidal shell around the eyeball (smooth maximum).
4. Rings of vertices continue each opening inward: two for each eye (the lid thickness, hidden behind the
   eyeball) and a closed bag for the mouth (its interior).
5. Two UV-sphere eyeballs with a cornea bulge and a recessed pupil are appended (separate components).

UVs (``sample_uvs``): the skin is unrolled around the vertical axis (``u`` from the angle about Y, ``v`` from
the height), one UV per vertex (the mask has no seam); each eyeball is a disc island below the skin, seen
from the front.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator

# --- layout constants (cm) ---------------------------------------------------------------------------
N_COLS = 95                      # odd: one column on the midline
THETA_MAX = np.radians(100.0)     # the mask reaches just behind the ears
ROW_SPACING = 0.23                # arc length between rows along the midline profile
EYE_X, EYE_Y = 3.15, 3.5          # eye centre targets (y is snapped to a grid row)
EYE_INNER, EYE_OUTER = 1.65, 4.65  # corner targets |x| (snapped to grid columns)
MOUTH_Y, MOUTH_HALF = -3.6, 2.45  # mouth line and half width targets
EYEBALL_RADIUS = 1.2
LID_SHELL = (1.75, 1.34, 1.34)    # ellipsoid the lids wrap, semi-axes (x, y, z), around the eye centre
EYE_OPEN_UP, EYE_OPEN_DOWN = 0.62, 0.45  # almond opening above / below the slit at its widest
LIP_GAP = 0.12                    # half the neutral gap between the lips at the centre

# Midline profile (y, z_front) from under the chin, over the face, to the top of the forehead.
PROFILE = np.array([
    (-10.3, 3.6), (-9.7, 5.6), (-9.1, 7.4), (-8.4, 8.7), (-7.4, 9.5), (-6.0, 9.6), (-4.6, 9.9),
    (-3.6, 10.2), (-2.0, 10.3), (-0.5, 10.0), (1.5, 9.4), (3.5, 9.2), (4.6, 9.5), (6.0, 10.1),
    (7.5, 10.1), (9.0, 9.4), (10.2, 7.9), (11.0, 5.8),
])
# Half width of the head at height y, and the superellipse exponent (2 = ellipse, lower = narrower front).
WIDTH = np.array([(-10.3, 4.6), (-8.5, 4.7), (-6.5, 5.5), (-4.0, 6.4), (-1.0, 6.95), (2.0, 7.2),
                  (5.0, 7.05), (8.0, 6.7), (11.0, 5.9)])
EXPONENT = np.array([(-10.3, 2.0), (-8.5, 1.5), (-7.0, 1.6), (-4.0, 2.0), (0.0, 2.45), (4.0, 2.6),
                     (11.0, 2.4)])
EYE_SIDES = {"L": 1.0, "R": -1.0}


@dataclass
class Slit:
    """An opening cut along grid row ``row`` between corner columns ``c0`` < ``c1``."""
    row: int
    c0: int
    c1: int
    upper: np.ndarray            # margin vertices above the slit, c0..c1 (corners included)
    lower: np.ndarray            # margin vertices below, c0..c1 (corners shared with ``upper``)
    dup: dict = field(default_factory=dict)  # column -> duplicated (lower-side) vertex


@dataclass
class FaceGeometry:
    """The neutral surface and what the shape builders need to know about it."""
    points: np.ndarray           # (V, 3)
    face_counts: np.ndarray      # (F,)
    face_indices: np.ndarray     # (sum counts,)
    n_grid: int                  # vertices 0..n_grid-1 are the lofted skin grid (row-major)
    n_rows: int
    n_cols: int
    row_of: np.ndarray           # (V,) grid row of every skin vertex (duplicates: their slit row), -1 else
    eyes: dict                   # "L"/"R" -> Slit
    mouth: Slit
    eye_centre: dict             # "L"/"R" -> (3,) eyeball centre
    ring_parent: np.ndarray      # (V,) for ring/bag vertices: the margin vertex they follow, else -1
    ring_follow: np.ndarray      # (V,) how much of the parent's motion they take (1 near the margin)
    eyeball: dict                # "L"/"R" -> vertex index array of that eyeball
    mouth_bag: np.ndarray        # vertex indices of the mouth interior (bag rings and its centre)
    eye_rings: dict              # "L"/"R" -> vertex indices of the lid-thickness rings
    skin: np.ndarray             # (V,) bool: part of the connected skin surface (not an eyeball)
    eye_y: float = 0.0
    mouth_y: float = 0.0


# --- small smooth functions ----------------------------------------------------------------------------
def compact(d2: np.ndarray) -> np.ndarray:
    """Smooth falloff (1 - d²)³ on d² < 1, zero outside (C² at the border)."""
    t = np.clip(1.0 - d2, 0.0, None)
    return t * t * t


def ellipse_d2(x, y, cx, cy, rx, ry):
    return ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2


def gauss(x, y, cx, cy, sx, sy):
    return np.exp(-0.5 * (((x - cx) / sx) ** 2 + ((y - cy) / sy) ** 2))


def smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def almond(x: np.ndarray, x0: float, x1: float, peak: float) -> np.ndarray:
    """A smooth bump on [x0, x1] (zero outside, zero slope nowhere inside), its maximum 1 at ``peak``."""
    t = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    a = peak / (1.0 - peak)
    f = t ** a * (1.0 - t)
    fmax = peak ** a * (1.0 - peak)
    return np.where((t > 0) & (t < 1), f / fmax, 0.0) ** 0.8


def eye_opening(x: np.ndarray, side: float, slit_x: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Almond heights (above, below) of one eye's opening at x (zero outside its corners)."""
    inner, outer = slit_x
    u = side * x  # the character's left eye has x > 0
    up = EYE_OPEN_UP * almond(u, inner, outer, 0.42)
    down = EYE_OPEN_DOWN * almond(u, inner, outer, 0.55)
    return up, down


def mouth_opening(x: np.ndarray, half: float) -> np.ndarray:
    t = np.clip(1.0 - (x / half) ** 2, 0.0, None)
    return LIP_GAP * t ** 1.5


def lip_span(x: np.ndarray, half: float, power: float = 1.0) -> np.ndarray:
    """1 in the middle of the lips, falling smoothly to 0 at the mouth corners."""
    return np.clip(1.0 - (x / half) ** 2, 0.0, None) ** power


def smooth_max(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return a * (1 - h) + b * h + k * h * (1 - h)


# --- construction ---------------------------------------------------------------------------------------
def _profile_rows() -> tuple[np.ndarray, np.ndarray]:
    """Rows (y, z_front) sampled at even arc length along the midline profile."""
    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(PROFILE, axis=0), axis=1))]
    spline_y = PchipInterpolator(d, PROFILE[:, 0])
    spline_z = PchipInterpolator(d, PROFILE[:, 1])
    fine = np.linspace(0.0, d[-1], 4000)
    fy, fz = spline_y(fine), spline_z(fine)
    arc = np.r_[0.0, np.cumsum(np.hypot(np.diff(fy), np.diff(fz)))]
    n = int(round(arc[-1] / ROW_SPACING)) + 1
    s = np.interp(np.linspace(0.0, arc[-1], n), arc, fine)
    return spline_y(s), spline_z(s)


def _interp(table: np.ndarray, y: np.ndarray) -> np.ndarray:
    return PchipInterpolator(table[:, 0], table[:, 1])(np.clip(y, table[0, 0], table[-1, 0]))


def _grid() -> tuple[np.ndarray, int, int]:
    row_y, row_z = _profile_rows()
    theta = np.linspace(-THETA_MAX, THETA_MAX, N_COLS)
    theta = 0.5 * (theta - theta[::-1])  # exactly mirror-symmetric
    width = _interp(WIDTH, row_y)[:, None]
    expo = _interp(EXPONENT, row_y)[:, None]
    s, c = np.sin(theta)[None, :], np.cos(theta)[None, :]
    sx = np.sign(s) * np.abs(s) ** (2.0 / expo)
    cz = np.sign(c) * np.abs(c) ** (2.0 / expo)
    x = width * sx
    z = row_z[:, None] * cz
    y = np.broadcast_to(row_y[:, None], x.shape)
    pts = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    return pts, len(row_y), N_COLS


def _nearest_row(points, n_cols, y_target) -> int:
    mid = points[N_COLS // 2::n_cols]
    return int(np.argmin(np.abs(mid[:, 1] - y_target) + 1e3 * (mid[:, 2] < 5)))


def _nearest_col(points, row, n_cols, x_target) -> int:
    xs = points[row * n_cols:(row + 1) * n_cols, 0]
    return int(np.argmin(np.abs(xs - x_target)))


def _features(x: np.ndarray, y: np.ndarray, ye: float, ym: float, mh: float) -> np.ndarray:
    """Height offsets (Z) of the facial features at layout position (x, y)."""
    ax = np.abs(x)
    f = np.zeros_like(x)
    # Forehead and brows: a ridge over each eye, the glabella between, temples hollow.
    f += 0.55 * compact(ellipse_d2(ax, y, 3.0, ye + 2.45, 3.3, 1.15))
    f += 0.25 * compact(ellipse_d2(x, y, 0.0, ye + 2.1, 1.4, 1.1))
    f -= 0.45 * compact(ellipse_d2(ax, y, 6.3, ye + 1.6, 1.6, 2.4))
    # Eye sockets (the lids are wrapped over the eyeball afterwards).
    f -= 1.1 * compact(ellipse_d2(ax, y, EYE_X, ye + 0.1, 2.0, 1.6))
    f -= 0.12 * np.exp(-0.5 * ((y - ye - 0.95 - 0.2 * compact(((ax - EYE_X) / 1.6) ** 2)) / 0.12) ** 2) \
        * compact(((ax - EYE_X - 0.2) / 1.7) ** 2)                     # upper lid crease
    # Cheekbones and cheeks.
    f += 0.55 * compact(ellipse_d2(ax, y, 4.6, ye - 2.0, 2.1, 1.7))
    f += 0.35 * compact(ellipse_d2(ax, y, 3.4, ym + 1.4, 1.6, 1.6))
    # Nose: bridge from the nasion to the tip, tip, wings (alae), nostrils, columella.
    yn, yt, ysn = ye + 0.9, 0.35, -1.05
    t = np.clip((yn - y) / (yn - yt), 0.0, 1.0)
    bridge_h = 0.15 + 1.85 * t ** 1.3
    bridge_w = 0.5 + 0.35 * t
    above = smoothstep((yn + 0.9 - y) / 0.9)                  # fades in below the glabella
    below = smoothstep((y - ysn) / (yt - ysn)) ** 0.6          # underside of the tip down to the lip
    f += bridge_h * np.exp(-0.5 * (x / bridge_w) ** 2) * above * below
    f += 0.5 * gauss(x, y, 0.0, yt, 0.62, 0.55) * below
    f += 0.75 * compact(ellipse_d2(ax, y, 1.2, -0.35, 0.75, 0.72))
    f -= 0.55 * gauss(ax, y, 0.62, -0.72, 0.22, 0.17)
    f -= 0.12 * compact(ellipse_d2(ax, y, 1.85, -0.3, 0.35, 0.9))   # crease around each wing
    # Muzzle, philtrum, nasolabial folds.
    f += 0.75 * gauss(x, y, 0.0, ym + 0.3, 2.4, 1.9)
    f -= 0.10 * gauss(x, y, 0.0, ym + 1.45, 0.28, 0.55)
    fold_t = np.clip((y - (ym - 0.2)) / 3.0, 0.0, 1.0)
    fold_x = mh + 0.45 - 1.0 * fold_t
    f -= 0.16 * np.exp(-0.5 * ((ax - fold_x) / 0.3) ** 2) * compact(((y - (ym + 1.4)) / 1.9) ** 2)
    # Lips: upper with a cupid's bow, fuller lower, rolled into the mouth line.
    bow = 0.09 * np.exp(-0.5 * ((ax - 0.42) / 0.25) ** 2) - 0.06 * np.exp(-0.5 * (x / 0.2) ** 2)
    up_c = ym + 0.38 + bow
    f += 0.42 * lip_span(x, mh + 0.1, 0.7) * np.exp(-0.5 * ((y - up_c) / 0.3) ** 2)
    f += 0.55 * lip_span(x, mh + 0.05, 0.8) * np.exp(-0.5 * ((y - (ym - 0.52)) / 0.36) ** 2)
    f -= 0.42 * lip_span(x, mh + 0.45, 1.0) * np.exp(-0.5 * ((y - ym) / 0.16) ** 2)
    # Chin and the groove above it.
    f -= 0.30 * gauss(x, y, 0.0, ym - 1.75, 1.7, 0.42)
    f += 0.55 * gauss(x, y, 0.0, ym - 3.4, 1.5, 1.0)
    return f


def build_face_geometry() -> FaceGeometry:
    grid, n_rows, n_cols = _grid()
    n_grid = len(grid)
    gid = np.arange(n_grid).reshape(n_rows, n_cols)
    row_e = _nearest_row(grid, n_cols, EYE_Y)
    row_m = _nearest_row(grid, n_cols, MOUTH_Y)
    ye, ym = float(grid[gid[row_e, 0], 1]), float(grid[gid[row_m, 0], 1])

    pts = [grid]
    row_of = [np.repeat(np.arange(n_rows), n_cols)]
    n_next = n_grid

    def cut(row, c0, c1):
        nonlocal n_next
        cols = np.arange(c0 + 1, c1)
        dup = {int(c): n_next + i for i, c in enumerate(cols)}
        pts.append(grid[gid[row, cols]])
        row_of.append(np.full(len(cols), row))
        n_next += len(cols)
        upper = gid[row, c0:c1 + 1]
        lower = np.array([gid[row, c0]] + [dup[int(c)] for c in cols] + [gid[row, c1]])
        return Slit(row, c0, c1, upper, lower, dup)

    eyes, eye_x = {}, {}
    for side, s in EYE_SIDES.items():
        ca = _nearest_col(grid, row_e, n_cols, s * EYE_INNER)
        cb = _nearest_col(grid, row_e, n_cols, s * EYE_OUTER)
        eyes[side] = cut(row_e, min(ca, cb), max(ca, cb))
        eye_x[side] = (abs(grid[gid[row_e, ca], 0]), abs(grid[gid[row_e, cb], 0]))
    cm0 = _nearest_col(grid, row_m, n_cols, -MOUTH_HALF)
    mouth = cut(row_m, cm0, n_cols - 1 - cm0)
    mh = abs(float(grid[gid[row_m, cm0], 0]))

    # Faces of the grid; quads below a slit row use the duplicated vertices.
    r, c = np.meshgrid(np.arange(n_rows - 1), np.arange(n_cols - 1), indexing="ij")
    a, b = gid[r, c], gid[r, c + 1]
    d_, e_ = gid[r + 1, c], gid[r + 1, c + 1]
    top_l, top_r = d_.copy(), e_.copy()
    for slit in [*eyes.values(), mouth]:
        below = r == slit.row - 1
        for col, v in slit.dup.items():
            top_l[below & (c == col)] = v
            top_r[below & (c + 1 == col)] = v
    quads = np.stack([a, b, top_r, top_l], axis=-1).reshape(-1, 4)
    faces = [quads]

    p = np.concatenate(pts)
    row_of = np.concatenate(row_of)
    n_skin_grid = len(p)

    # Open the slits: warp y above/below each slit row.
    x, y = p[:, 0].copy(), p[:, 1].copy()
    for side, s in EYE_SIDES.items():
        slit = eyes[side]
        up, down = eye_opening(x, s, eye_x[side])
        lower_side = (row_of < slit.row) | np.isin(np.arange(len(p)), list(slit.dup.values()))
        upper_side = (row_of >= slit.row) & ~lower_side
        dy_up = y - ye
        dy_dn = ye - y
        p[:, 1] += np.where(upper_side & (dy_up >= 0), up * (1 - np.clip(dy_up / 1.5, 0, 1) ** 2) ** 2, 0)
        p[:, 1] -= np.where(lower_side & (dy_dn >= 0), down * (1 - np.clip(dy_dn / 1.2, 0, 1) ** 2) ** 2, 0)
    gap = mouth_opening(x, mh)
    m_lower = (row_of < mouth.row) | np.isin(np.arange(len(p)), list(mouth.dup.values()))
    m_upper = (row_of >= mouth.row) & ~m_lower
    p[:, 1] += np.where(m_upper & (y >= ym), gap * (1 - np.clip((y - ym) / 0.6, 0, 1) ** 2) ** 2, 0)
    p[:, 1] -= np.where(m_lower & (y <= ym), gap * (1 - np.clip((ym - y) / 0.6, 0, 1) ** 2) ** 2, 0)

    # Features in Z, faded out towards the sides and back of the head.
    frontness = smoothstep((p[:, 2] - 1.0) / 4.0)
    p[:, 2] += frontness * _features(p[:, 0], p[:, 1], ye, ym, mh)

    # Wrap the lids over a shell around each eyeball.
    eye_centre = {}
    ax_, by_, cz_ = LID_SHELL
    for side, s in EYE_SIDES.items():
        cx = s * EYE_X
        cz = float(_row_front_z(p, gid, row_e, cx)) - 1.25
        centre = np.array([cx, ye, cz])
        eye_centre[side] = centre
        dx, dy = (p[:, 0] - cx) / ax_, (p[:, 1] - ye) / by_
        q = 1.0 - dx ** 2 - dy ** 2
        shell = np.where(q > 0, cz + cz_ * np.sqrt(np.clip(q, 0, None)), -1e3)
        near = (q > -0.6) & (p[:, 2] > 2.0)
        p[near, 2] = smooth_max(p[near, 2], shell[near], 0.35)

    points = [p]
    ring_parent = [np.full(len(p), -1)]
    ring_follow = [np.zeros(len(p))]
    n_next = len(p)

    # Lid thickness: two rings from each eye's margin loop into the socket.
    eye_rings = {}
    for side, slit in eyes.items():
        loop = np.concatenate([slit.upper, slit.lower[-2:0:-1]])
        centre = eye_centre[side]
        rel = p[loop] - centre
        dist = np.linalg.norm(rel, axis=1, keepdims=True)
        ring1 = centre + rel * (1.0 - 0.07)
        ring2 = centre + rel / dist * (EYEBALL_RADIUS * 0.93)
        ids = []
        prev = loop
        for ring in (ring1, ring2):
            new = n_next + np.arange(len(loop))
            points.append(ring)
            ring_parent.append(loop)
            ring_follow.append(np.ones(len(loop)))
            n_next += len(loop)
            faces.append(_loop_quads(prev, new, faces))
            prev = new
            ids.append(new)
        eye_rings[side] = np.concatenate(ids)

    # Mouth bag: rings going back from the lips, closed by a fan.
    loop = np.concatenate([mouth.upper, mouth.lower[-2:0:-1]])
    lp = p[loop]
    sign = np.where(np.arange(len(loop)) <= (mouth.c1 - mouth.c0), 1.0, -1.0)
    sign[0] = sign[mouth.c1 - mouth.c0] = 0.0
    span = lip_span(lp[:, 0], mh, 0.5)
    prev = loop
    bag = []
    depths = (0.35, 0.9, 1.7, 2.6, 3.4)
    heights = (0.25, 0.75, 1.1, 1.15, 0.8)
    widths = (0.97, 0.95, 0.9, 0.8, 0.62)
    follow = (0.95, 0.85, 0.7, 0.5, 0.3)
    for dz, hgt, wd, fol in zip(depths, heights, widths, follow):
        ring = np.stack([lp[:, 0] * wd, ym + sign * (np.abs(lp[:, 1] - ym) + hgt * span),
                         lp[:, 2] - dz], axis=1)
        new = n_next + np.arange(len(loop))
        points.append(ring)
        ring_parent.append(loop)
        ring_follow.append(np.full(len(loop), fol))
        n_next += len(loop)
        faces.append(_loop_quads(prev, new, faces))
        prev = new
        bag.append(new)
    centre = np.array([[0.0, ym, float(lp[:, 2].mean()) - 3.9]])
    points.append(centre)
    ring_parent.append(np.array([-1]))
    ring_follow.append(np.zeros(1))
    c_id = n_next
    n_next += 1
    bag.append(np.array([c_id]))
    tri = np.stack([prev, np.roll(prev, -1), np.full(len(prev), c_id)], axis=1)
    last = faces[-1]
    uses_forward = ((last == prev[0]) & (np.roll(last, -1, axis=1) == prev[1])).any()
    faces.append(tri[:, ::-1] if uses_forward else tri)
    mouth_bag = np.concatenate(bag)

    n_skin = n_next
    eyeball = {}
    for side in EYE_SIDES:
        ball_pts, ball_faces = _eyeball(eye_centre[side])
        eyeball[side] = n_next + np.arange(len(ball_pts))
        points.append(ball_pts)
        ring_parent.append(np.full(len(ball_pts), -1))
        ring_follow.append(np.zeros(len(ball_pts)))
        faces.extend(part + n_next for part in ball_faces)
        n_next += len(ball_pts)

    allp = np.concatenate(points)
    # Centre the bounding box on the origin.
    allp -= 0.5 * (allp.min(axis=0) + allp.max(axis=0)) * np.array([0.0, 1.0, 1.0])
    shift_y = allp[0, 1] - p[0, 1]
    shift_z = allp[0, 2] - p[0, 2]
    for side in eye_centre:
        eye_centre[side] = eye_centre[side] + np.array([0.0, shift_y, shift_z])

    counts = np.concatenate([np.full(len(f), f.shape[1]) for f in faces]).astype(np.int32)
    indices = np.concatenate([f.reshape(-1) for f in faces]).astype(np.int32)
    V = len(allp)
    row_full = np.full(V, -1)
    row_full[:n_skin_grid] = row_of
    skin = np.zeros(V, bool)
    skin[:n_skin] = True
    return FaceGeometry(points=allp, face_counts=counts, face_indices=indices, n_grid=n_grid,
                        n_rows=n_rows, n_cols=n_cols, row_of=row_full, eyes=eyes, mouth=mouth,
                        eye_centre=eye_centre, ring_parent=np.concatenate(ring_parent),
                        ring_follow=np.concatenate(ring_follow), eyeball=eyeball, mouth_bag=mouth_bag,
                        eye_rings=eye_rings, skin=skin, eye_y=ye + shift_y, mouth_y=ym + shift_y)


def _row_front_z(p, gid, row, x):
    ids = gid[row]
    return np.interp(x, p[ids, 0], p[ids, 2])


def _loop_quads(a: np.ndarray, b: np.ndarray, faces: list) -> np.ndarray:
    """Quads joining loop ``a`` (already part of ``faces``) to a new loop ``b`` of equal length,
    wound so every edge is used once in each direction (consistent orientation)."""
    q = np.stack([a, np.roll(a, -1), np.roll(b, -1), b], axis=1)
    a0, a1 = int(a[0]), int(a[1])
    for f in faces:
        nxt = np.roll(f, -1, axis=1)
        if ((f == a0) & (nxt == a1)).any():
            return q[:, ::-1]
    return q


def _eyeball(centre: np.ndarray, n_lat: int = 14, n_lon: int = 24) -> tuple[np.ndarray, list]:
    """A UV sphere facing +Z with a cornea bulge and a recessed pupil; quads with triangle fans at poles."""
    lat = np.linspace(0.0, np.pi, n_lat + 1)[1:-1]          # angle from the front pole
    lon = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    r = EYEBALL_RADIUS * (1.0 + 0.07 * compact((L / 0.75) ** 2) - 0.02 * compact((L / 0.25) ** 2))
    ring = np.stack([r * np.sin(L) * np.cos(O), r * np.sin(L) * np.sin(O), r * np.cos(L)], axis=-1)
    front = np.array([[0.0, 0.0, EYEBALL_RADIUS * (1.07 - 0.02) * 0.995]])
    back = np.array([[0.0, 0.0, -EYEBALL_RADIUS]])
    pts = np.concatenate([front, ring.reshape(-1, 3), back]) + centre
    idx = 1 + np.arange(len(lat) * n_lon).reshape(len(lat), n_lon)
    faces = []
    nxt = np.roll(idx, -1, axis=1)
    tri_f = np.stack([np.zeros(n_lon, int), idx[0], nxt[0]], axis=1)
    quads = np.stack([idx[:-1], idx[1:], nxt[1:], nxt[:-1]], axis=-1).reshape(-1, 4)
    last = len(pts) - 1
    tri_b = np.stack([idx[-1], np.full(n_lon, last), nxt[-1]], axis=1)
    return pts, [tri_f, quads, tri_b]


# --- UVs ------------------------------------------------------------------------------------------------
SKIN_U = (0.02, 0.98)      # the skin's island: u from the angle about Y, v from the height
SKIN_V = (0.15, 0.99)
EYE_ISLAND = {"L": (0.75, 0.075), "R": (0.25, 0.075)}   # (u, v) centre of each eyeball's disc
EYE_ISLAND_RADIUS = 0.06


def sample_uvs(g: FaceGeometry) -> np.ndarray:
    """(V, 2) UV per vertex of the sample face."""
    p = g.points
    uv = np.zeros((len(p), 2))
    theta = np.arctan2(p[:, 0], p[:, 2])
    y = p[:, 1]
    ylo, yhi = y[g.skin].min(), y[g.skin].max()
    uv[:, 0] = SKIN_U[0] + (SKIN_U[1] - SKIN_U[0]) * (0.5 + theta / (2 * THETA_MAX * 1.02))
    uv[:, 1] = SKIN_V[0] + (SKIN_V[1] - SKIN_V[0]) * (y - ylo) / (yhi - ylo)
    for side, ids in g.eyeball.items():
        rel = p[ids] - g.eye_centre[side]
        r = np.linalg.norm(rel, axis=1).max()
        cu, cv = EYE_ISLAND[side]
        uv[ids, 0] = cu + EYE_ISLAND_RADIUS * rel[:, 0] / r
        uv[ids, 1] = cv + EYE_ISLAND_RADIUS * rel[:, 1] / r
    return np.clip(uv, 0.0, 1.0)
