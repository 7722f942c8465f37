"""Marker maps: which rig surface point each take marker sits on.

JSON: ``{"rig_units": "cm", "take_units": "mm", "markers": {"M00": 1234, "M01": {"face": f, "bary": [a, b, c]}}}``.
A value is a vertex index, or a polygon index (file order) with barycentric weights: one per polygon corner,
or three for the polygon's first three corners. ``binding(rig)`` turns a map into a sparse (M, V) matrix
whose rows give each marker's rest position as a weighted sum of vertices, so every solver sees markers
as plain rows of the rig.

``auto_marker_map`` builds a map from the neutral calibration frames of a take: a similarity alignment
of the mean calibration marker cloud to the rig (Umeyama 1991 inside an ICP loop, Besl & McKay 1992),
then a smooth non-rigid warp of the rig's neutral toward the markers (ALGORITHMS.md §12 (b)), each marker
bound to its nearest point of the warped surface, and that point re-fitted from the take's motion (which rig point's
motion under the solved weights explains the marker's), alternating with the solve.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError, shown
from .rig import Rig
from .units import UNIT_IN_METRES, length, take_solver_options, unit_scale
from .takes import MarkerTake


@dataclass
class MarkerMap:
    """Marker label -> vertex index (int) or ``{"face": f, "bary": [...]}``, in the order of ``labels``."""

    markers: dict[str, int | dict]
    rig_units: str = "cm"
    take_units: str | None = None
    source: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return list(self.markers)

    def __post_init__(self) -> None:
        where = self.source or "marker map"
        for u in (self.rig_units, self.take_units):
            if u is not None and (not isinstance(u, str) or u not in UNIT_IN_METRES):
                raise RigInputError(f"{where}: unknown units '{shown(u, 20)}' (use mm, cm or m).")
        if not self.markers:
            raise RigInputError(f"{where}: maps no markers.")
        for label, v in self.markers.items():
            self.markers[label] = _checked_entry(v, f"{where}: marker {shown(label, 40)}")

    # --- binding to a rig ------------------------------------------------------------------------
    def binding(self, rig: Rig, labels: list[str] | None = None) -> sp.csr_matrix:
        """(M, V) sparse matrix: row i gives marker ``labels[i]`` as a weighted sum of rig vertices."""
        where = self.source or "marker map"
        labels = self.labels if labels is None else labels
        V = rig.n_vertices
        starts = np.concatenate(([0], np.cumsum(rig.face_counts)))
        rows, cols, vals = [], [], []
        for i, label in enumerate(labels):
            if label not in self.markers:
                raise RigInputError(f"{where}: has no marker labelled '{shown(label, 40)}'.")
            v = self.markers[label]
            if isinstance(v, dict):
                f = int(v["face"])
                if not 0 <= f < rig.n_faces:
                    raise RigInputError(f"{where}: marker {shown(label, 40)} is on face {f}, but the rig has {rig.n_faces} faces.")
                corners = rig.face_indices[starts[f]:starts[f + 1]]
                bary = np.asarray(v["bary"], dtype=np.float64)
                if bary.size not in (3, corners.size) or not np.isfinite(bary).all():
                    raise RigInputError(f"{where}: marker {shown(label, 40)} needs 3 or {corners.size} barycentric weights.")
                if abs(bary.sum() - 1.0) > 1e-3:
                    raise RigInputError(f"{where}: marker {shown(label, 40)}'s barycentric weights must sum to 1.")
                rows += [i] * bary.size
                cols += list(corners[:bary.size])
                vals += list(bary)
            else:
                if not 0 <= int(v) < V:
                    raise RigInputError(f"{where}: marker {shown(label, 40)} is bound to vertex {int(v)}, "
                                        f"but the rig has {V} vertices.")
                rows.append(i)
                cols.append(int(v))
                vals.append(1.0)
        return sp.csr_matrix((vals, (rows, cols)), shape=(len(labels), V))

    def match(self, take: MarkerTake) -> tuple[list[str], np.ndarray]:
        """(labels in both, their column in the take). Raises if the take and the map share no label."""
        where = self.source or "marker map"
        common = [label for label in self.labels if label in take.labels]
        if not common:
            raise RigInputError(f"{where}: none of its {len(self.labels)} marker labels appear in the take "
                                f"{take.source or ''} (the take has {', '.join(take.labels[:5])}...).".replace("  ", " "))
        return common, np.array([take.labels.index(label) for label in common], dtype=np.int64)

    def missing_from(self, take: MarkerTake) -> list[str]:
        """Labels of the map that the take does not have."""
        return [label for label in self.labels if label not in take.labels]

    def validate(self, rig: Rig, take: MarkerTake | None = None, *, min_markers: int = 3) -> list[str]:
        """Check the map against a rig (and a take); returns warnings (labels absent from the take).

        Raises RigInputError for vertices beyond the rig or a take that shares too few markers.
        """
        self.binding(rig)
        warnings = []
        if take is not None:
            common, _ = self.match(take)
            if len(common) < min_markers:
                raise RigInputError(f"{self.source or 'marker map'}: only {len(common)} of its markers appear in "
                                    f"{take.source or 'the take'}; a solve needs at least {min_markers}.")
            absent = self.missing_from(take)
            if absent:
                warnings.append(f"{len(absent)} mapped markers are not in the take: {', '.join(absent)}.")
            unmapped = [label for label in take.labels if label not in self.markers]
            if unmapped:
                warnings.append(f"{len(unmapped)} take markers are not mapped: {', '.join(unmapped)}.")
        return warnings

    # --- files -----------------------------------------------------------------------------------
    def to_json(self) -> dict:
        out = {"rig_units": self.rig_units}
        if self.take_units:
            out["take_units"] = self.take_units
        out["markers"] = {k: (int(v) if not isinstance(v, dict) else
                              {"face": int(v["face"]), "bary": [float(x) for x in v["bary"]]})
                          for k, v in self.markers.items()}
        return out

    def save(self, path: str | Path) -> None:
        from .atomic import atomic_write
        atomic_write(path, (json.dumps(self.to_json(), indent=1) + "\n").encode())


def load_marker_map(path: str | Path) -> MarkerMap:
    """Read a marker map JSON file."""
    from .json_file import read_json_file
    path = Path(path)
    d = read_json_file(path)
    if not isinstance(d, dict) or not isinstance(d.get("markers"), dict):
        raise RigInputError(f"{path}: a marker map needs a 'markers' object of label: vertex.")
    extra = {k: v for k, v in d.items() if k not in ("rig_units", "take_units", "markers")}
    return MarkerMap(markers=d["markers"], rig_units=d.get("rig_units", "cm"), take_units=d.get("take_units"),
                     source=str(path), extra=extra)


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def _checked_entry(v, what: str):
    """A map entry as the binding uses it: a vertex index, or {"face": f, "bary": [3 or more finite numbers]}."""
    if _is_int(v):
        if not -2**62 < int(v) < 2**62:
            raise RigInputError(f"{what} is bound to vertex {shown(v, 24)}, which no rig has.")
        return int(v)
    if not isinstance(v, dict):
        raise RigInputError(f"{what} must map to a vertex index or {{'face', 'bary'}}.")
    if "face" not in v or "bary" not in v:
        raise RigInputError(f"{what} needs both 'face' and 'bary'.")
    f, bary = v["face"], v["bary"]
    if not _is_int(f) or not -2**62 < int(f) < 2**62:
        raise RigInputError(f"{what}: 'face' must be a face number, not {shown(f, 24)}.")
    if (not isinstance(bary, list) or not 3 <= len(bary) <= 64
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in bary)
            or not np.isfinite(np.asarray(bary, dtype=np.float64)).all()):
        raise RigInputError(f"{what}: 'bary' must be 3 or more finite barycentric weights.")
    return {**v, "face": int(f), "bary": [float(x) for x in bary]}


# --- automatic mapping ---------------------------------------------------------------------------
def calibration_cloud(take: MarkerTake, frames: int | slice = 30, units: str | None = None, *,
                      allow_unseen: bool = False) -> np.ndarray:
    """(M, 3) mean marker positions over the calibration frames (NaN-aware), optionally converted. A marker never
    seen in them is refused, or NaN with ``allow_unseen``."""
    sl = slice(0, frames) if isinstance(frames, int) else frames
    pos = take.positions[sl]
    with np.errstate(invalid="ignore"):
        seen = np.isfinite(pos).all(axis=2).sum(axis=0)
    if (seen == 0).any() and not allow_unseen:
        bad = [take.labels[i] for i in np.flatnonzero(seen == 0)]
        raise RigInputError(f"{take.source or 'take'}: markers {', '.join(bad)} are missing in every calibration frame.")
    with np.errstate(invalid="ignore"):
        cloud = np.nanmean(pos, axis=0)
    return cloud * unit_scale(take.units, units) if units else cloud


# The registration warp of automatic mapping (solvers.retarget.SmoothWarp): Gaussian length (cm; scaled to the rig's
# units) and Tikhonov λ, and the alternations of nearest points and warp. On the actor take (another face, up to
# 2 cm from ICT) the mapped vertices were 2.8 mm (mean) from the true ones after the similarity alone; the warp
# brought them to 1.4 mm (measured over lengths 2–12 cm and λ 0.1–100: 8 cm, λ 10 was best).
WARP_SCALE_CM, WARP_LAMBDA, WARP_ITERATIONS = 8.0, 10.0, 10
# Markers farther than this from the warped face (cm; e.g. a head band's) are not mapped.
OFF_FACE_CM = 1.0
# A take whose markers do not look like a face on the rig is refused rather than mapped: the registration's scale
# (the rig's face over the markers' size) outside this range, or the markers' median distance from the rig's face
# after it, at the take's own size, beyond OFF_FACE_CM. A similarity with a free scale fits any cloud onto the face:
# the 60 third-party body takes (C3D, TRC; gait, sports, whole bodies) register at scales 0.10-0.36 and lie a
# median 0.6-4.8 cm off the face at their own size; the shared face takes (the rig's own face and another actor's)
# at 0.99-1.0 and 0.01-0.14 cm.
FACE_SCALE_RANGE = (0.4, 2.5)
# Fewer markers than this cannot be told from a face at all: the similarity and the 10% trim lay a handful of points
# on any surface. Of random subsets of the third-party body takes' markers (every third file), 5 markers passed the
# face check on ICT in 4 of 24 takes, 8 in 1 of 23, 10 or more in none (on the sample face: 6 in 1 of 23, 8 in none);
# Sample17 of C3D.org (5 markers seen, a body 5 m across) was mapped onto the sample face and "solved" (RMSE 15 cm).
MIN_AUTO_MARKERS = 10
# A registration whose scale fell below this shrank the markers onto one point of the rig (ICP on a rig with a few
# small moving parts: MorphStressTest's bars took the actor take at 4.5e-30): its scale and distances mean nothing.
COLLAPSED_SCALE = 1e-3
# Markers whose calibration positions all lie within this of their centroid (cm, RMS) do not span a face (a take
# whose points are all written at the origin).
MIN_SPREAD_CM = 0.1
# Re-fitting each marker's rig point from the take's motion (``solvers.retarget.refit_points``): rounds of solve and
# re-fit (it stops early when no point moves), the search radius around the registered point (cm), the prior's λ,
# the uncertainty floor (cm) and how many frames besides the neutral the rounds solve (every n-th frame of a longer
# take). The uncertainty σ_j of a registered point is how far the registration had to move it (the warp's offset
# plus the distance left): about 0.1 mm on the rig's own face, where no point moves, 1–5 mm on the actor take.
# Measured on the actor take (automatic mapping, then the default solve): no re-fit 0.137 weights RMS / 0.80 mm,
# λ 0 0.073 / 0.44 mm (but 14 of the same-face take's 59 exact points moved: 0.236 mm dense RMS instead of 0.205),
# λ 0.05 0.072 / 0.40 mm with the same-face points kept, λ 0.2 0.082 / 0.40 mm. Solving every 2nd frame gave
# 0.076 / 0.44 mm; all 358 frames, 6 rounds: 4 s of CPU (2 s and 3 rounds on the same-face take).
REFINE_ROUNDS, REFINE_RADIUS_CM, REFINE_LAMBDA, REFINE_SIGMA_FLOOR_CM, REFINE_FRAMES = 8, 0.8, 0.05, 0.005, 1000


def auto_marker_map(rig: Rig, take: MarkerTake, *, calibration_frames: int | slice = 30,
                    vertices: np.ndarray | None = None,
                    landmarks: dict[str, int] | None = None, iterations: int = 60,
                    surface_points: bool = False, warp: bool = True,
                    exclude: list[str] | None = None, refine: int = REFINE_ROUNDS) -> tuple[MarkerMap, dict]:
    """Bind each take marker to the rig from the neutral calibration frames (a count from the start or a slice).

    The mean calibration cloud (converted to rig units) is similarity-aligned to the rig: from
    ``landmarks`` ({label: vertex}) by Umeyama 1991 if given, else by ICP (Besl & McKay 1992) with a
    per-iteration Umeyama similarity fit to the nearest rig points, tried from a few start rotations.
    With ``warp`` (ALGORITHMS.md §12 (b)) the rig's neutral is then warped toward the markers by a smooth RBF +
    affine warp (``solvers.retarget.SmoothWarp``), alternating with nearest points, so that an actor of other
    proportions is mapped to the corresponding places. Each marker is bound to its nearest vertex of
    ``vertices`` (default: every vertex a shape moves, i.e. the deforming face), or with ``surface_points`` to the
    nearest point on a polygon (face + bary). With ``refine`` (rounds; vertex binding only) each vertex is then
    re-fitted from the take's motion (``refine_by_motion``): the registration cannot tell where along the surface a
    marker of another face sits, the shapes' motion can. Markers never seen in the calibration frames, the
    ``exclude`` labels and markers off the face (farther than ``OFF_FACE_CM`` from the warped surface, e.g. a head
    band) are not mapped: info["left_out"] lists them. Returns (map, info) with info = {"scale", "rotation",
    "translation", "rms", "distances", "left_out", "warp_offset", "refined"} (rig units; "refined": the labels
    whose vertex the motion moved, "refine_rounds": the rounds run).
    """
    from scipy.spatial import cKDTree
    from solvers.retarget import SmoothWarp
    from solvers.rigid import umeyama

    full = calibration_cloud(take, calibration_frames, rig.units, allow_unseen=True)
    usable = np.isfinite(full).all(axis=1) & ~np.isin(take.labels, exclude or [])
    if not usable.any():
        raise RigInputError(f"{take.source or 'take'}: no marker is seen in the calibration frames, so none can be "
                            "mapped automatically.")
    if usable.sum() < MIN_AUTO_MARKERS:
        raise RigInputError(f"{take.source or 'take'}: only {int(usable.sum())} markers are seen in the calibration "
                            f"frames, too few to tell whether they are on a face ({MIN_AUTO_MARKERS} or more are "
                            "mapped automatically); give a marker map.")
    labels_used = [lab for lab, u in zip(take.labels, usable) if u]
    cloud = full[usable]
    spread = float(np.sqrt(np.mean(np.sum((cloud - cloud.mean(axis=0)) ** 2, axis=1))))
    if not spread > length(MIN_SPREAD_CM, rig.units):
        raise RigInputError(f"{take.source or 'take'}: its markers' positions in the calibration frames all lie within "
                            f"{MIN_SPREAD_CM * 10:g} mm of one point, so they cannot be mapped onto a face.")
    if vertices is None:
        vertices = np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) > 0)
    vertices = np.asarray(vertices, dtype=np.int64)
    pts = rig.neutral[vertices]
    tree = cKDTree(pts)
    if landmarks:
        lab = [k for k in landmarks if k in labels_used]
        if len(lab) < 3:
            raise RigInputError("Automatic marker mapping needs at least 3 landmark markers found in the take.")
        src = cloud[[labels_used.index(k) for k in lab]]
        dst = rig.neutral[[landmarks[k] for k in lab]]
        s, R, t = umeyama(src, dst, scale=True)
        starts = [(s, R, t)]
    else:
        c_src, c_dst = cloud.mean(axis=0), pts.mean(axis=0)
        starts = []
        for ax, ang in ((0, 0.0), (1, np.pi), (0, np.pi), (2, np.pi)):
            c, sn = np.cos(ang), np.sin(ang)
            R = np.eye(3)
            i, j = [a for a in range(3) if a != ax]
            R[i, i], R[i, j], R[j, i], R[j, j] = c, -sn, sn, c
            # Start from the take's own frame (often already the rig's) and from centroid alignment.
            starts.append((1.0, R, np.zeros(3)))
            starts.append((1.0, R, c_dst - R @ c_src))
    best = None
    for s, R, t in starts:
        for it in range(iterations):
            moved = s * cloud @ R.T + t
            d, nn = tree.query(moved)
            if not landmarks:
                # Trim the worst 10 % (markers over holes or off the mesh) for robustness.
                keep = d <= np.quantile(d, 0.9)
            else:
                keep = np.ones(d.size, bool)
            s2, R2, t2 = umeyama(cloud[keep], pts[nn[keep]], scale=it > 5)
            if it > 5 and np.allclose(R2, R, atol=1e-10) and abs(s2 - s) < 1e-10 and np.allclose(t2, t, atol=1e-10):
                s, R, t = s2, R2, t2
                break
            s, R, t = s2, R2, t2
        moved = s * cloud @ R.T + t
        d, nn = tree.query(moved)
        rms = float(np.sqrt(np.mean(d ** 2)))
        if best is None or rms < best[0]:
            best = (rms, s, R, t, d, nn, moved)
    rms, s, R, t, d, nn, moved = best
    off = float(np.median(d)) / s if s > 0 else float("inf")     # at the take's own size, rig units
    if not (FACE_SCALE_RANGE[0] <= s <= FACE_SCALE_RANGE[1] and off <= length(OFF_FACE_CM, rig.units)):
        fit = f"needs a scale of {s:.2g} and leaves half of them more than {off:.2g} {rig.units} off its surface at " \
            "their own size" if s >= COLLAPSED_SCALE else "shrinks them to one point of its surface"
        raise RigInputError(f"{take.source or 'take'}: its markers do not look like a face on this rig (fitting them "
                            f"to it {fit}), so they are not mapped automatically; give a marker map if they are on a "
                            "face, or check the take's units.")
    on_face = d <= np.quantile(d, 0.9) if d.size > 10 else np.ones(d.size, bool)
    surface = pts
    if warp and on_face.sum() >= 4:
        # a smooth warp of the rig's neutral toward the markers, alternating with nearest points (§12 (b))
        for _ in range(WARP_ITERATIONS):
            phi = SmoothWarp(pts[nn[on_face]], moved[on_face], scale=length(WARP_SCALE_CM, rig.units), lam=WARP_LAMBDA)
            surface = phi(pts)
            d, nn2 = cKDTree(surface).query(moved)
            if np.array_equal(nn2, nn):
                break
            nn = nn2
            on_face = d <= max(np.quantile(d, 0.9), length(OFF_FACE_CM, rig.units)) if d.size > 10 \
                else np.ones(d.size, bool)
    offset = np.linalg.norm(surface[nn] - pts[nn], axis=1)      # how far the warp moved each marker's point
    keep = d <= length(OFF_FACE_CM, rig.units)
    if keep.sum() < 3:
        keep = np.ones(d.size, bool)
    left_out = [lab for lab, u in zip(take.labels, usable) if not u] + \
        [lab for lab, k in zip(labels_used, keep) if not k]
    markers: dict[str, int | dict] = {}
    dist = d.copy()
    if surface_points:
        faces, bary, dist = _nearest_on_polygons(rig, moved, vertices)
        for label, f, b, k in zip(labels_used, faces, bary, keep):
            if k:
                markers[label] = {"face": int(f), "bary": [float(x) for x in b]}
    else:
        for label, j, k in zip(labels_used, nn, keep):
            if k:
                markers[label] = int(vertices[j])
    info = {"scale": float(s), "rotation": R, "translation": t, "rms": rms, "distances": dist,
            "left_out": left_out, "warp_offset": offset[keep], "refined": [], "refine_rounds": 0}
    if refine and not surface_points and len(markers) >= 3:
        sigma = np.maximum(offset[keep] + d[keep], length(REFINE_SIGMA_FLOOR_CM, rig.units))
        labels = list(markers)
        found, rounds = refine_by_motion(rig, take, labels, np.array([markers[k] for k in labels]), sigma,
                                         _neutral_range(calibration_frames, take.n_frames), vertices, rounds=refine)
        info["refined"] = [k for k, v in zip(labels, found) if v != markers[k]]
        info["refine_rounds"] = rounds
        markers = {k: int(v) for k, v in zip(labels, found)}
    mm = MarkerMap(markers=markers, rig_units=rig.units, take_units=take.units, source="automatic marker map")
    return mm, info


def _neutral_range(frames: int | slice, n_frames: int) -> tuple[int, int]:
    """(first, last) inclusive of the calibration frames (a count from the start or a slice) in a take."""
    if isinstance(frames, slice):
        a, b, _ = frames.indices(n_frames)
        return a, max(a, b - 1)
    return 0, max(1, min(int(frames), n_frames)) - 1


def refine_by_motion(rig: Rig, take: MarkerTake, labels: list[str], registered: np.ndarray, sigma: np.ndarray,
                     neutral: tuple[int, int], vertices: np.ndarray, *, rounds: int = REFINE_ROUNDS,
                     lam: float = REFINE_LAMBDA) -> tuple[np.ndarray, int]:
    """Re-fit the vertex of each marker (``labels``, registered on ``registered`` (M,) vertices with uncertainty
    ``sigma`` (M,) rig units) from the take's motion (ALGORITHMS.md §12 (b)): alternately solve the take (markers
    only, no residual or correctives, the rig's antagonists, ``neutral`` the actor's neutral frames; the neutral and
    at most ``REFINE_FRAMES`` frames of the rest) and move each marker to the vertex of ``vertices`` within
    ``REFINE_RADIUS_CM`` of its registered place whose motion best explains the marker's
    (``solvers.retarget.refit_points``, prior ‖p − p₀‖² / σ² with ``lam``). Stops when no marker moves, or keeps
    the points it has when the take cannot be solved (the solve proper then says why).
    Returns ((M,) vertices, rounds run)."""
    from scipy.spatial import cKDTree
    from solvers.retarget import refit_points
    from solvers.take_solve import TakeSolver
    from .antagonists import pair_indices, rig_antagonists
    cols = [take.labels.index(lab) for lab in labels]
    a, b = neutral
    others = np.r_[0:a, b + 1:take.n_frames]
    step = max(1, -(-others.size // REFINE_FRAMES))
    X = take.positions[np.r_[a:b + 1, others[::step]]][:, cols]
    registered = np.asarray(registered, dtype=np.int64)
    centres = rig.neutral[registered]
    radius = length(REFINE_RADIUS_CM, rig.units)
    near = cKDTree(rig.neutral[vertices]).query_ball_point(centres, radius)
    candidates = [np.union1d(vertices[np.asarray(c, dtype=np.int64)], [r]) for c, r in zip(near, registered)]
    prior = [np.einsum("vc,vc->v", rig.neutral[c] - p, rig.neutral[c] - p) / sg ** 2
             for c, p, sg in zip(candidates, centres, sigma)]
    pairs = pair_indices(rig, rig_antagonists(rig))
    found, n = registered.copy(), 0
    for n in range(1, int(rounds) + 1):
        binding = sp.csr_matrix((np.ones(found.size), (np.arange(found.size), found)), shape=(found.size, rig.n_vertices))
        solver = TakeSolver(rig.neutral, rig.deltas, binding, antagonists=pairs,
                            **take_solver_options({"residual": "none"}, rig.units))
        try:
            sol = solver.solve(X, unit_factor=unit_scale(take.units, rig.units), neutral=(0, b - a))
        except ValueError:
            break
        new = refit_points(sol.markers_rig - solver.rest, sol.weights, rig.deltas, candidates, prior, lam)
        if np.array_equal(new, found):
            break
        found = new
    return found, n


def _nearest_on_polygons(rig: Rig, points: np.ndarray, vertices: np.ndarray):
    """Nearest point on the rig's polygons (those touching ``vertices``) to each point: polygon index,
    barycentric weights per polygon corner, distance (Ericson, Real-Time Collision Detection §5.1.5)."""
    tris = rig.triangles()
    counts = rig.face_counts.astype(np.int64)
    face_of_tri = np.repeat(np.arange(counts.size), np.maximum(counts - 2, 0))
    corner_k = np.arange(tris.shape[0]) - np.repeat(np.cumsum(np.maximum(counts - 2, 0)) - np.maximum(counts - 2, 0),
                                                   np.maximum(counts - 2, 0))
    mask = np.zeros(rig.n_vertices, bool)
    mask[vertices] = True
    use = mask[tris].all(axis=1)
    tris, face_of_tri, corner_k = tris[use], face_of_tri[use], corner_k[use]
    A, B, C = (rig.neutral[tris[:, i]] for i in range(3))
    centroid = (A + B + C) / 3
    from scipy.spatial import cKDTree
    tree = cKDTree(centroid)
    _, cand = tree.query(points, k=min(16, len(tris)))
    faces, barys, dists = [], [], []
    for p, cs in zip(points, np.atleast_2d(cand)):
        best = None
        for c in cs:
            uvw = _closest_bary(p, A[c], B[c], C[c])
            q = uvw @ np.stack([A[c], B[c], C[c]])
            dd = float(np.linalg.norm(p - q))
            if best is None or dd < best[0]:
                best = (dd, c, uvw)
        dd, c, uvw = best
        f = face_of_tri[c]
        n = int(counts[f])
        b = np.zeros(n)
        k = int(corner_k[c])
        b[0] += uvw[0]
        b[k + 1] += uvw[1]
        b[k + 2] += uvw[2]
        if n == 3:
            b = b[:3]
        faces.append(f)
        barys.append(b)
        dists.append(dd)
    return np.array(faces), barys, np.array(dists)


def _closest_bary(p, a, b, c) -> np.ndarray:
    """Barycentric weights of the closest point to p on triangle abc (Ericson 2005, §5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0 and d2 <= 0:
        return np.array([1.0, 0, 0])
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0 and d4 <= d3:
        return np.array([0, 1.0, 0])
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        v = d1 / (d1 - d3)
        return np.array([1 - v, v, 0])
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0 and d5 <= d6:
        return np.array([0, 0, 1.0])
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        w = d2 / (d2 - d6)
        return np.array([1 - w, 0, w])
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return np.array([0, 1 - w, w])
    denom = 1.0 / (va + vb + vc)
    v, w = vb * denom, vc * denom
    return np.array([1 - v - w, v, w])


def polygon_point_entry(rig: Rig, face: int, point, points: np.ndarray | None = None) -> int | dict:
    """The map entry of the point of polygon ``face`` nearest ``point``, on the surface ``points`` (default the
    neutral; a posed surface gives the same place on the face): ``{"face": f, "bary": [one weight per corner]}``,
    or the corner's vertex index when the point is on it. For a map point the user drags onto another place."""
    if not 0 <= int(face) < rig.n_faces:
        raise RigInputError(f"Face {face} is not a face of the rig (it has {rig.n_faces}).")
    X = rig.neutral if points is None else np.asarray(points, dtype=np.float64)
    starts = np.concatenate(([0], np.cumsum(rig.face_counts)))
    corners = rig.face_indices[starts[face]:starts[face + 1]]
    p = np.asarray(point, dtype=np.float64)
    best = None
    for k in range(len(corners) - 2):             # the polygon's fan, as rig.triangles() cuts it
        tri = X[[corners[0], corners[k + 1], corners[k + 2]]]
        uvw = _closest_bary(p, *tri)
        d = float(np.linalg.norm(uvw @ tri - p))
        if best is None or d < best[0]:
            best = (d, k, uvw)
    _, k, uvw = best
    bary = np.zeros(len(corners))
    bary[[0, k + 1, k + 2]] += uvw
    if bary.max() > 0.999:
        return int(corners[int(np.argmax(bary))])
    return {"face": int(face), "bary": [float(x) for x in (bary[:3] if len(corners) == 3 else bary)]}
