"""Solve a motion capture take onto a blendshape rig (ALGORITHMS.md §4, §5, §7).

Pipeline (all in rig units):
1. Units: take markers are multiplied by ``unit_factor`` (take units -> rig units), then lightly low-passed
   in time (``marker_smoothing``, σ in frames; NaN-aware), since optical noise is white in time.
2. Calibration (Ma et al. 2016, §3.1): a similarity transform (Umeyama 1991, Eq. 40–42) from the mean
   marker cloud of the first neutral frames to the rig's markers at rest settles scale, units and pose.
3. Per frame, alternate a few times, started from the previous frame (Ma §3.1):
   rigid head motion by weighted Kabsch with the weights fixed, then the weight QP of Joshi et al. 2003,
   Eq. 2 with Ma Eq. 3–4's sparsity ``λ_s (Σw)²`` and temporal ``λ_t ‖w − w_prev‖²`` terms
   on the head-stabilised markers. Kabsch weights trust markers the expression moves little
   (``1 / (rigid_noise² + rigid_weighting² ‖d(w)‖²)``: the rig's misfit grows with displacement). With
   ``two_pass`` a backward sweep is run too and the two causal solutions are averaged, cancelling the
   lag of the causal temporal term.
4. Optionally per region (Joshi §4): the same QP per region of a segmentation level over the markers inside
   it and the shapes that move there, coarse to fine down the hierarchy (each region regularised toward its
   parent's weights, forward and backward over the take; a region with too few markers inherits them); the
   surface blends the region weights by a partition of unity, and the residual is fitted after the blend.
5. The remaining marker misfit, low-passed in time (``residual_smoothing``), is interpolated by RBFs and
   added to the dense result (Joshi Eq. 3; Fidaleo Eq. 1–5; ``solvers.rbf``).
The box QP of a take solve runs in ``_CachedBoxQP`` (same problem as ``solvers.weight_solve``, whose
general solver is slower along a take, where warm starts make the same working sets recur; that one is still
used for convex mode).
Missing markers (NaN) are dropped per frame. Everything that depends only on the rig and the marker set
(normal matrices, kernel factorisations per missing-marker mask) is built once.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, Optional

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from .antagonists import pair_penalty
from .correctives import linearised_correctives
from .parallel import ordered_map
from .rbf import KERNEL_LENGTH_POWER, KERNELS, RBFResidual, phantom_points
from .regional_solve import shape_region_max
from .retarget import SmoothWarp, neutral_stretch
from .rigid import to_matrix, umeyama
from .weight_solve import WeightSolver, qp_tol

Progress = Optional[Callable[[int, int, str], None]]

RETARGET = ("jacobian", "scale", "none")   # how the markers' motion is carried into the rig (ALGORITHMS.md §12)

# James–Stein-like shrinkage of the actor's neutral offsets toward the rig (``TakeSolver.register``): an offset below
# about √30 ≈ 5.5 standard errors of its neutral mean is taken as noise. Measured: 3 gave 0.2105 mm dense RMS on the
# same-face take, 9 gave 0.2052, 30 gave 0.2042 (0.2049 fitting the rig's own neutral); the actor take's weights
# (0.067 RMS) do not change.
SHRINK = 30.0

# Per-region solves: a shape acts in a region where its displacement exceeds this share of its largest over the regions
# (Joshi §4: the weights of the shapes that move inside r); the others keep the parent region's weights.
REGION_SHAPE_SHARE = 0.02

DENSE_BLOCK = 32          # frames per block of dense results (32 × 106k vertices × 12 bytes = 41 MB)
CORRECTIVE_STEPS = 6      # Gauss–Newton steps per weight solve on a rig with correctives (quadratic: 2–3 suffice)

# Defaults chosen by measurement on the ICT Live Link take (see tests/benchmarks/test_bench_take_solve.py).
# retarget 'scale' (the similarity's scale carries the motion) measured 0.067 weights RMS / 0.31 mm on the actor take
# against 0.10 / 0.43 mm through the smooth warp's Jacobian ('jacobian'), whose per-marker maps the 60 markers do not
# determine well (their local scale correlated 0.3 with the true one). lam_antagonist (rig units², per antagonist
# pair w_i w_j, ALGORITHMS.md §13): 0 left up to 22 frames with both weights of a pair above 0.2; 0.15 none, and
# the same-face take's dense RMS went from 0.2042 to 0.2025 mm (0.2 gave 0.2075, 0.3 gave 0.2216). lam_region (per-region
# solves, λ_r toward the parent region's weights, cm²): at the middle level of ICT's default segmentation,
# coarse to fine, 0.1 gave 0.1985 / 0.2276 mm on the same-face / actor takes, 0.3 gave 0.1988 / 0.2271, 1.0 gave
# 0.2007 / 0.2274 (the global solve: 0.2025 / 0.2276).
# Lengths are in centimetres and the weights of squared-length terms in cm² (``LENGTH_OPTIONS``): these are the
# values for a rig in centimetres, and ``model.units.take_solver_options`` converts them for a rig in other units,
# so that the same face gives the same weights in m, cm or mm. ``ridge`` keeps the QP positive definite (cm²).
DEFAULTS = dict(lam_sparsity=0.0, lam_temporal=1.0, iterations=3, two_pass=True, marker_smoothing=0.7,
                residual="gaussian", rbf_scale=2.0, rbf_lambda=1.0, residual_smoothing=6.0, n_phantoms=48,
                phantom_distance=2.0, calibration_frames=30, rigid_weighting=0.1, rigid_noise=0.05,
                lam_region=0.3, retarget="scale", warp_scale=3.0, warp_lambda=0.1, lam_antagonist=0.15,
                ridge=1e-10)

# The options that carry a length, with its power: λ's weigh terms against squared marker misfits (length²);
# kernel and ring lengths and the head-motion noise are lengths; ``rbf_lambda`` has the kernel's dimension
# (``solvers.rbf.KERNEL_LENGTH_POWER``). Smoothing σ's are in frames; rigid_weighting, warp_lambda and SHRINK
# are ratios.
LENGTH_OPTIONS = {"lam_sparsity": 2, "lam_temporal": 2, "lam_region": 2, "lam_antagonist": 2, "ridge": 2,
                  "rbf_scale": 1, "phantom_distance": 1, "rigid_noise": 1, "warp_scale": 1, "rbf_lambda": None}


def option_length_power(name: str, residual: str = DEFAULTS["residual"]) -> int:
    """The power of length in option ``name`` (0 for a dimensionless one), for the residual kernel ``residual``."""
    power = LENGTH_OPTIONS.get(name, 0)
    return KERNEL_LENGTH_POWER.get(residual, 0) if power is None else power


def _mean_rigid(Ra: np.ndarray, ta: np.ndarray, Rb: np.ndarray, tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame mean of two rigid trajectories: translations averaged, rotations by the chordal L2 mean
    (Hartley et al. 2013, "Rotation averaging", §5.3): average the matrices, project onto SO(3) by SVD."""
    U, _, Vt = np.linalg.svd(0.5 * (Ra + Rb))
    d = np.sign(np.linalg.det(U @ Vt))
    U[:, :, 2] *= d[:, None]
    return U @ Vt, 0.5 * (ta + tb)


def _neutral_mean(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean (M, 3), variance of the mean (M,)) of the neutral frames Y (F, M, 3), NaN where missing: each frame
    rigidly aligned to the plain mean first (a Procrustes mean, Gower 1975), so a head that moves during the
    neutral does not blur it. A marker never seen is NaN."""
    mean = np.nanmean(Y, axis=0)
    ok = np.isfinite(mean).all(axis=1)
    if Y.shape[0] > 1 and ok.sum() >= 3:
        seen = np.isfinite(Y).all(axis=2) & ok
        good = seen.sum(axis=1) >= 3
        if good.any():
            R, t = kabsch_batch(Y[good], mean, seen[good])
            Y = Y.copy()
            Y[good] = np.einsum("fij,fmj->fmi", R, Y[good]) + t[:, None]
            mean = np.nanmean(Y, axis=0)
    n = np.isfinite(Y).all(axis=2).sum(axis=0)
    var = np.nanmean(np.nanvar(Y, axis=0), axis=1) / np.maximum(n, 1) if Y.shape[0] > 1 else np.zeros(Y.shape[1])
    return mean, np.nan_to_num(var, nan=0.0)


def kabsch_batch(source: np.ndarray, target: np.ndarray, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame the rigid (R, t) with target ≈ R source + t over the present points (Umeyama 1991 without scale)."""
    tgt = np.broadcast_to(np.nan_to_num(target), source.shape)
    _, R, t = umeyama(np.nan_to_num(source), tgt, present.astype(np.float64), scale=False)
    return R, t


def _smooth_in_time(values: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian low-pass of (F, M, 3) trajectories along frames, ignoring NaN samples (normalised
    convolution, Knutsson & Westin 1993); NaN stays NaN. Optical noise is white in time, the rig's misfit
    is not, so this separates them before the residual interpolation."""
    from scipy.ndimage import gaussian_filter1d
    ok = np.isfinite(values)
    filled = np.where(ok, values, 0.0)
    num = gaussian_filter1d(filled, sigma, axis=0, mode="nearest")
    den = gaussian_filter1d(ok.astype(np.float64), sigma, axis=0, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[~ok] = np.nan
    return out


class SolveCancelled(Exception):
    """Raised when the cancel flag is set during a take solve."""


def _det3(m: np.ndarray) -> float:
    """The determinant of a 3x3 matrix in plain floats (np.linalg.det costs 8 µs a call; this 1 µs)."""
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


_GESDD = la.get_lapack_funcs("gesdd", (np.zeros((3, 3)),))   # LAPACK's SVD, as np.linalg.svd, at 1/4 the overhead
_POSV = la.get_lapack_funcs("posv", (np.zeros((2, 2)),))     # LAPACK's Cholesky solve, float64


def _kabsch(P: np.ndarray, Y: np.ndarray, p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted Kabsch / Umeyama 1991 (Eq. 40–41) for one frame: Y ≈ R P + t, point weights p (sum 1).
    Called a few thousand times a take, so the 3x3 SVD and determinants go straight to LAPACK and floats."""
    if p is None:
        mp, my = P.mean(axis=0), Y.mean(axis=0)
        C = (Y - my).T @ (P - mp)
    else:
        mp, my = p @ P, p @ Y
        C = (Y - my).T @ ((P - mp) * p[:, None])
    U, _, Vt, info = _GESDD(C)
    if info != 0:
        U, _, Vt = np.linalg.svd(C)
    if _det3(U) * _det3(Vt) < 0:
        U[:, 2] = -U[:, 2]
    R = U @ Vt
    return R, my - R @ mp


class _CachedBoxQP:
    """Box-constrained QP ``min ½wᵀHw − gᵀw, lo ≤ w ≤ hi`` for one fixed H (one marker subset), by the
    primal active-set method (Nocedal & Wright, *Numerical Optimization*, Algorithm 16.3) with the
    Cholesky factor of every free-variable block cached: along a take the same working sets recur, so
    most frames cost a back-substitution or two. H here is ``AᵀA + λ_s 11ᵀ + λ_t I`` (Joshi et al. 2003,
    Eq. 2; Ma et al. 2016, Eq. 3–4)."""

    def __init__(self, H: np.ndarray, lo: float = 0.0, hi: float = 1.0, max_iter: int = 200,
                 cache: bool = True) -> None:
        self.H = np.ascontiguousarray(H, dtype=np.float64)
        self.K = H.shape[0]
        self.lo, self.hi = lo, hi
        self.max_iter = max_iter
        self.cache = cache        # False for a one-off H (a Gauss–Newton step): no factor is kept
        self._factors: dict[bytes, tuple] = {}
        self._seen: dict[bytes, int] = {}
        self._posv = _POSV
        self.tol = qp_tol(H)

    def _factor(self, free: np.ndarray):
        if not self.cache:
            idx = np.flatnonzero(free)
            return idx, None, self.H[np.ix_(idx, idx)]
        key = free.tobytes()
        hit = self._factors.get(key)
        if hit is None:
            idx = np.flatnonzero(free)
            # H is well conditioned (λ_t I on the diagonal): keep the inverse of the free block, so a
            # solve is one small matrix-vector product. Working sets seen only once are not kept.
            Hff = self.H[np.ix_(idx, idx)]
            seen = self._seen.get(key, 0) + 1
            if seen < 2:
                self._seen[key] = seen
                return idx, None, Hff
            hit = (idx, la.cho_solve(la.cho_factor(Hff), np.eye(idx.size)), None)
            if len(self._factors) > 4096:
                self._factors.clear()
                self._seen.clear()
            self._factors[key] = hit
        return hit

    def solve(self, g: np.ndarray, w0: np.ndarray) -> np.ndarray:
        """The box QP from ``w0`` (clipped into the box). Each step solves the free block with the bound
        variables held (r = g_f − H_fb w_b); a blocked step stops at the first bound, else the most violated
        multiplier (−∂ at the lower bound, +∂ at the upper) frees its variable, until none is violated.
        The working set is one float array, s = −1 at the lower bound, +1 at the upper, 0 free, so that a
        step is a dozen numpy calls (each costs microseconds at this size, and a take makes thousands)."""
        H, lo, hi = self.H, self.lo, self.hi
        w = np.minimum(np.maximum(w0, lo), hi)
        s = (w >= hi) - (w <= lo).astype(np.float64)
        for _ in range(self.max_iter):
            free = s == 0.0
            idx, inv, Hff = self._factor(free)
            if idx.size:
                r = g[idx] - (H @ np.where(free, 0.0, w))[idx]    # the bound variables' pull on the free ones
                x = inv @ r if inv is not None else self._posv(Hff, r)[1]
                if np.minimum.reduce(x) < lo or np.maximum.reduce(x) > hi:
                    # blocked: step to the first bound on the way and hold that variable there
                    cur = w[idx]
                    out_lo, out_hi = x < lo, x > hi
                    p = x - cur
                    ratio = np.full(idx.size, np.inf)
                    ratio[out_lo] = (lo - cur[out_lo]) / p[out_lo]
                    ratio[out_hi] = (hi - cur[out_hi]) / p[out_hi]
                    j = int(ratio.argmin())
                    w[idx] = cur + max(ratio[j], 0.0) * p
                    v = idx[j]
                    w[v], s[v] = (lo, -1.0) if out_lo[j] else (hi, 1.0)
                    continue
                w[idx] = x
            viol = (H @ w - g) * s          # the multipliers' violation; 0 for free variables
            j = int(viol.argmax())
            if viol[j] <= self.tol:
                break
            s[j] = 0.0
        np.minimum(np.maximum(w, lo, out=w), hi, out=w)
        return w


@dataclass
class TakeSolution:
    """The result of a take solve.

    weights         (F, K) global weights (for a regional solve, the background row of each frame).
    region_weights  (F, R+1, K) per-region weights, or None for a global solve.
    fitted_weights  (F, K) for a regional solve, the global weights whose surface is closest to each frame's
                    blended regional surface (``solvers.surface_fit.global_weights_of_regional``), set by the
                    caller: one weight per shape, what a weights CSV and a DCC's animation carry; None otherwise.
    head            (F, 4, 4) head transforms: rig space -> take space (take units), ``m ≈ head_f · x``.
    marker_rmse     (F,) RMS distance between the head-stabilised markers and the rig fit (rig units).
    marker_rmse_residual (F,) the same after adding the RBF residual (0-ish unless λ smooths it).
    coefficients    (F, M+P, 3) RBF residual coefficients (None when residual is 'none').
    """

    weights: np.ndarray
    head: np.ndarray
    marker_rmse: np.ndarray
    marker_rmse_residual: np.ndarray
    region_weights: np.ndarray | None = None
    fitted_weights: np.ndarray | None = None
    coefficients: np.ndarray | None = None
    calibration: np.ndarray | None = None
    misfit: np.ndarray | None = None
    markers_rig: np.ndarray | None = None
    motion_explained: float = float("nan")
    motion_explained_per_marker: np.ndarray | None = None
    neutral_frames: tuple[int, int] | None = None
    neutral_reason: dict | None = None
    left_out: dict | None = None          # take markers not solved: label -> why (set by the caller)
    head_labels: list | None = None       # unbound stable markers used for the head motion only
    labels: list | None = None
    solve_seconds: float = 0.0
    solver: "TakeSolver | None" = field(default=None, repr=False)

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])

    @property
    def shape_weights(self) -> np.ndarray:
        """(F, K) one weight per shape per frame: a global solve's weights, a regional solve's fitted ones."""
        return self.weights if self.fitted_weights is None else self.fitted_weights

    @property
    def frames_per_second(self) -> float:
        return self.n_frames / self.solve_seconds if self.solve_seconds > 0 else float("inf")

    def projection(self, frame: int) -> np.ndarray:
        """(V, 3) float64 blendshape surface of ``frame`` (no residual), head-stabilised in rig space."""
        W = self.region_weights if self.region_weights is not None else self.weights
        return self.solver.pose(W[frame])

    def dense(self, frame: int, projection: np.ndarray | None = None) -> np.ndarray:
        """(V, 3) float64 surface of ``frame``, head-stabilised in rig space and rig units: the projection (given,
        or evaluated) plus the RBF residual."""
        s = self.solver
        x = self.projection(frame) if projection is None else np.array(projection, dtype=np.float64)
        if self.coefficients is not None and s.rbf is not None:
            x[s.residual_vertices] += s.rbf.evaluate(self.coefficients[frame])
        return x

    def iter_dense(self) -> Iterator[np.ndarray]:
        """Yield every frame's dense surface in order, (V, 3) float32 (e.g. for a PC2 writer): views into
        ``dense_blocks``."""
        for block in self.dense_blocks():
            yield from block

    def dense_blocks(self, frames: int = DENSE_BLOCK) -> Iterator[np.ndarray]:
        """Yield the dense surfaces of every frame in order as (n, V, 3) float32 blocks of at most ``frames``
        frames: with the solver's batch evaluator (``surface_many``, global solves) each block is two matrix
        products, the pose W (n, K) · D (K, 3V) and the residual Φ (N, M+P) · C (M+P, 3n); otherwise frame by
        frame. The blocks are computed on the machine's cores (``solvers.parallel``: the products run outside
        the GIL), a few ahead of the one the caller is writing, so that its writes overlap them; that bounds the
        memory: a few n × V × 3 × 4 bytes."""
        step = max(1, int(frames))
        starts = range(0, self.n_frames, step)
        s = self.solver
        batch = self._batched()
        if batch and self.n_frames:   # the evaluator's and the residual's copies, made here before the threads
            s.surface_many(self.weights[:1])    # share them
            if self.coefficients is not None and s.rbf is not None:
                s.rbf.eval_matrix_as(np.float32)
                s.residual_runs()
        # frame by frame (regional weights, correctives) the pose's caches are not for sharing: one thread
        yield from ordered_map(lambda start: self._dense_block(start, min(self.n_frames, start + step)), starts,
                               threads=None if batch else 1)

    def _batched(self) -> bool:
        """Whether the dense frames are matrix products over blocks (the solver's batch evaluator, global weights)
        rather than one surface a frame."""
        return self.solver.surface_many is not None and self.region_weights is None

    def _dense_block(self, start: int, stop: int) -> np.ndarray:
        """(stop − start, V, 3) float32: ``dense_blocks``' block of frames start..stop."""
        s = self.solver
        if not self._batched():
            return np.stack([self.dense(f) for f in range(start, stop)]).astype(np.float32)
        x = s.surface_many(self.weights[start:stop])
        if self.coefficients is not None and s.rbf is not None:
            C = self.coefficients[start:stop]                                    # (n, M+P, 3)
            n, P = C.shape[0], C.shape[1]
            E = s.rbf.eval_matrix_as(np.float32)                                 # (N, M+P)
            r = E @ C.transpose(1, 0, 2).reshape(P, n * 3).astype(np.float32)   # (N, 3n)
            r = np.ascontiguousarray(r.reshape(-1, n, 3).transpose(1, 0, 2))    # (n, N, 3)
            runs = s.residual_runs()
            if runs is None:
                x[:, s.residual_vertices] += r
            else:       # runs of consecutive vertices: slices, no gather and scatter of the whole block
                for a, b, v0, v1 in runs:
                    x[:, v0:v1] += r[:, a:b]
        return x


def marker_rest(neutral: np.ndarray, binding: sp.spmatrix) -> np.ndarray:
    """(M, 3) float64 the markers at rest: the (M, V) sparse ``binding`` applied to the rig's ``neutral``, as
    ``TakeSolver`` computes them (and keys its residual's preparation by)."""
    return np.asarray(sp.csr_matrix(binding) @ np.asarray(neutral, dtype=np.float64))


def residual_preparation(neutral: np.ndarray, rest: np.ndarray, *, residual: str = DEFAULTS["residual"],
                         rbf_scale: float = DEFAULTS["rbf_scale"], rbf_lambda: float = DEFAULTS["rbf_lambda"],
                         n_phantoms: int = DEFAULTS["n_phantoms"],
                         phantom_distance: float = DEFAULTS["phantom_distance"],
                         residual_vertices: np.ndarray | None = None,
                         prepared: dict | None = None) -> tuple[np.ndarray, RBFResidual | None]:
    """(the vertices the residual moves, the RBF residual) of markers at rest ``rest`` (M, 3) on the rig's
    ``neutral`` (V, 3) float64 (``TakeSolver``'s, with its options; lengths in the rig's units): Fidaleo's
    phantom ring (``solvers.rbf.phantom_points``) and the RBF interpolant of Joshi et al. 2003, Eq. 3, over the
    vertices within ``phantom_distance`` of a marker (its evaluation matrix is built on first use). No residual:
    (no vertices, None).

    ``prepared``: a dict kept for one rig across takes; the result is taken from it for the same marker points and
    options, else made and put in it. A batch makes it once for its marker map before any take
    (``model.take_workspace.prepare_solver``) and sends it with the job."""
    if residual == "none":
        return np.zeros(0, dtype=np.int64), None
    key = ("residual", rest.tobytes(), residual, float(rbf_scale), float(rbf_lambda), int(n_phantoms),
           float(phantom_distance),
           None if residual_vertices is None else np.asarray(residual_vertices, dtype=np.int64).tobytes())
    hit = None if prepared is None else prepared.get(key)
    if hit is not None:
        return hit
    from scipy.spatial import cKDTree
    if residual_vertices is None:
        d, _ = cKDTree(rest).query(neutral)
        residual_vertices = np.flatnonzero(d < phantom_distance)
    residual_vertices = np.asarray(residual_vertices, dtype=np.int64)
    ph = phantom_points(neutral, rest, phantom_distance, n_phantoms) if n_phantoms else []
    rbf = RBFResidual(rest, neutral[ph] if len(ph) else None, neutral[residual_vertices], kernel=residual,
                      scale=rbf_scale, lam=rbf_lambda)
    if prepared is not None:
        prepared[key] = (residual_vertices, rbf)
    return residual_vertices, rbf


class TakeSolver:
    """Everything of a take solve that depends only on the rig and the marker set, built once.

    neutral (V, 3), deltas (K, V, 3): the rig; binding (M, V) sparse (or (M,) vertex indices): markers as
    weighted sums of vertices. Options (defaults in ``DEFAULTS``):
    lam_sparsity, lam_temporal (Ma Eq. 3–4), iterations (rigid/weight alternations per frame),
    mode ('box' or 'convex'), residual (one of rbf.KERNELS), rbf_scale (kernel length, rig units),
    rbf_lambda (Tikhonov λ), n_phantoms / phantom_distance (zero-residual ring, rig units),
    residual_vertices (vertices that receive the residual; default: those nearer to a marker than the
    phantom ring), regions (list of vertex index arrays) and blend ((V, R+1) partition of unity, last
    column the background) for a per-region solve; coarser_regions (the region lists of the hierarchy's levels
    above, finest first, without the top one-region level) makes it coarse to fine: each region is regularised
    toward its parent region's weights (λ_r, lam_region) instead of the global solve's, and a region with fewer
    than min_region_markers markers, fewer marker coordinates than shapes acting in it, or equal to its parent
    takes its parent's weights (``_solve_regions``). Every length option is in rig units (``LENGTH_OPTIONS``; the
    ``DEFAULTS`` are those of a rig in cm: ``model.units.take_solver_options`` converts them for any other).

    correctives: the rig's corrective shapes (Smith 2006 §4.5; ALGORITHMS.md §6), as (activate, E, drivers):
    activate maps weights (U, K) to activations (U, C) by the rig's rules, E (C, V, 3) holds their deltas and
    drivers the indices of the shapes that drive them (``model.correctives.solver_correctives``). The model is
    then x(w) = b0 + Σ_k w_k d_k + Σ_c a_c(w) e_c, solved by Gauss–Newton steps on the weights (``_weights``;
    one per Kabsch alternation), and every pose, fit and dense frame includes the correctives.

    surface: the rig's pose evaluation as a callable, weights (K,) or region weights (R+1, K) -> a new (V, 3)
    float64 surface with the same correctives (``model.pose.PoseEvaluator.pose`` with the level's blend); the
    dense frames and projections use it. Without it the solver fits the markers only. surface_many: the same
    pose for many global weight vectors at once, (n, K) -> (n, V, 3) float32 (``PoseEvaluator.evaluate_many``):
    ``TakeSolution.dense_blocks`` then computes all frames as matrix products.

    prepared: a dict the caller keeps for one rig (its neutral unchanged) across takes, e.g. a batch worker's: the
    residual's preparation (its vertices, the phantom points, the RBF's kernel matrices and factorisations, ~20 ms
    on ICT) is reused from it for the same marker points and residual settings instead of being computed again.
    The same numbers either way (``tests/test_batch.py`` compares a worker's weights with ``solve``'s, byte for byte).
    """

    def __init__(self, neutral: np.ndarray, deltas: np.ndarray, binding, *, mode: str = "box",
                 lam_sparsity: float = DEFAULTS["lam_sparsity"], lam_temporal: float = DEFAULTS["lam_temporal"],
                 iterations: int = DEFAULTS["iterations"], residual: str = DEFAULTS["residual"],
                 rbf_scale: float = DEFAULTS["rbf_scale"], rbf_lambda: float = DEFAULTS["rbf_lambda"],
                 n_phantoms: int = DEFAULTS["n_phantoms"], phantom_distance: float = DEFAULTS["phantom_distance"],
                 residual_vertices: np.ndarray | None = None, regions: list[np.ndarray] | None = None,
                 blend=None, min_region_markers: int = 3, coarser_regions=(),
                 residual_smoothing: float = DEFAULTS["residual_smoothing"],
                 two_pass: bool = DEFAULTS["two_pass"],
                 marker_smoothing: float = DEFAULTS["marker_smoothing"],
                 head_motion: bool = True,
                 rigid_weighting: float = DEFAULTS["rigid_weighting"],
                 rigid_noise: float = DEFAULTS["rigid_noise"],
                 lam_region: float = DEFAULTS["lam_region"], correctives=None,
                 surface: Callable[[np.ndarray], np.ndarray] | None = None,
                 retarget: str = DEFAULTS["retarget"], warp_scale: float = DEFAULTS["warp_scale"],
                 warp_lambda: float = DEFAULTS["warp_lambda"], antagonists=None,
                 lam_antagonist: float = DEFAULTS["lam_antagonist"], ridge: float = DEFAULTS["ridge"],
                 surface_many: Callable[[np.ndarray], np.ndarray] | None = None,
                 prepared: dict | None = None) -> None:
        if residual not in KERNELS:
            raise ValueError(f"Unknown residual '{residual}': use one of {', '.join(KERNELS)}.")
        if retarget not in RETARGET:
            raise ValueError(f"Unknown retargeting '{retarget}': use one of {', '.join(RETARGET)}.")
        self.retarget, self.warp_scale, self.warp_lambda = retarget, float(warp_scale), float(warp_lambda)
        self.neutral = np.asarray(neutral, dtype=np.float64)
        deltas = np.asarray(deltas)   # float32 shapes stay float32 (a studio rig's float64 copy is gigabytes)
        self.deltas = deltas if deltas.dtype in (np.float32, np.float64) else deltas.astype(np.float64)
        K, V, _ = self.deltas.shape
        self.K, self.V = K, V
        if not sp.issparse(binding):
            idx = np.asarray(binding, dtype=np.int64)
            binding = sp.csr_matrix((np.ones(idx.size), (np.arange(idx.size), idx)), shape=(idx.size, V))
        self.binding = sp.csr_matrix(binding)
        M = self.binding.shape[0]
        self.M = M
        # head stabilisation: (head-band markers per frame, their neutral, which mapped markers are stable);
        # solve() sets it from the take, and by default every marker is stable and there is no head band
        self._head = (np.zeros((0, 0, 3)), np.zeros((0, 3)), np.ones(M, dtype=bool))
        self.iterations = int(iterations)
        self.residual_smoothing = float(residual_smoothing)
        self.two_pass = bool(two_pass)
        self.marker_smoothing = float(marker_smoothing)
        self.head_motion = bool(head_motion)  # False: markers are already head-stabilised in rig space
        self.rigid_weighting = float(rigid_weighting)
        self.rigid_noise = float(rigid_noise)
        self.rest = marker_rest(self.neutral, self.binding)  # (M, 3) markers at rest
        self._Dm_rig = np.stack([self.binding @ self.deltas[k] for k in range(K)])  # (K, M, 3)
        self.mode, self.lam_sparsity, self.lam_temporal = mode, float(lam_sparsity), float(lam_temporal)
        self.ridge = float(ridge)   # rig units²: keeps H positive definite where λ_t is 0
        self.lower, self.upper = 0.0, 1.0
        # Antagonist pairs (ALGORITHMS.md §13): λ_a w_i w_j added to the QP for each pair (i, j).
        self.lam_antagonist = float(lam_antagonist)
        self.pair_penalty = pair_penalty(antagonists if antagonists is not None else [], K, self.lam_antagonist)
        # The compiled sweep (numba, loaded here with the rig's preparation rather than inside the timed solve).
        from . import take_kernel
        self._kernel = take_kernel if take_kernel.available() else None
        self.qp_iterations = 0      # active-set iterations of the compiled sweeps so far (a cost measure)
        # Correctives: their activation rule and deltas, at the markers (C, 3M) and on the surface.
        self._activate, E, drivers = correctives if correctives is not None else (None, np.zeros((0, V, 3)), [])
        E = np.asarray(E, dtype=np.float64).reshape(-1, V, 3)
        if self._activate is None or E.shape[0] == 0:
            self._activate, E, drivers = None, np.zeros((0, V, 3)), []
        self._drivers = np.unique(np.asarray(drivers, dtype=np.intp))   # the shapes the activations depend on
        self.C = E.shape[0]
        self._Em_rig = np.stack([self.binding @ E[c] for c in range(self.C)]) if self.C else np.zeros((0, M, 3))
        # Dense pose: the rig's one pose evaluation, handed in (model.pose.PoseEvaluator.pose with the blend).
        self.surface = surface
        self.surface_many = surface_many     # global weights (n, K) -> (n, V, 3) float32, the same pose (exports)
        # Regions.
        self.lam_region = float(lam_region)
        self.n_regions: int | None = None     # regions of a per-region solve (None: a global solve)
        self._region_args = None if regions is None else (regions, blend, min_region_markers, coarser_regions)
        # The model the markers are fitted with: the rig's marker points until a take's neutral is known.
        self._set_actor(self.rest, None)
        # Residual.
        self.residual = residual
        self.residual_vertices, self.rbf = residual_preparation(
            self.neutral, self.rest, residual=residual, rbf_scale=rbf_scale, rbf_lambda=rbf_lambda,
            n_phantoms=n_phantoms, phantom_distance=phantom_distance, residual_vertices=residual_vertices,
            prepared=prepared)

    # --- the actor's model at the markers (ALGORITHMS.md §12) -------------------------------------
    def _set_actor(self, anchor: np.ndarray, jac: np.ndarray | None) -> None:
        """Fit the markers with the actor's neutral ``anchor`` (M, 3) (rig frame) and the rig's displacements
        carried into the actor's face by the warp's Jacobian ``jac`` (M, 3, 3) (None: the identity):
        marker j at weights w sits at anchor_j + J_j Σ_k w_k d_kj (+ correctives). Rebuilds what depends on it."""
        K, M = self.K, self.M
        self.anchor = np.asarray(anchor, dtype=np.float64)
        if jac is None and getattr(self, "jac", 0) is None:
            return          # the model's displacements did not change: keep the cached QP factors (warm solves)
        self.jac = jac
        Dm = self._Dm_rig if jac is None else np.einsum("mab,kmb->kma", jac, self._Dm_rig)
        self.Dm = np.ascontiguousarray(Dm.reshape(K, 3 * M))  # w @ Dm -> (3M,)
        self.A = np.ascontiguousarray(self.Dm.T)  # (3M, K)
        self.At = self.Dm                          # (K, 3M) = Aᵀ, row-major for the per-frame Aᵀb
        Em = self._Em_rig if (jac is None or not self.C) else np.einsum("mab,cmb->cma", jac, self._Em_rig)
        self.Em = Em.reshape(self.C, 3 * M)
        self._qps: dict[bytes, tuple] = {}
        self.weight_solver = WeightSolver(self.A, mode=self.mode, lam_sparsity=self.lam_sparsity,
                                          lam_temporal=self.lam_temporal)
        if self._region_args is not None:
            regions, blend, min_markers, coarser = self._region_args
            self._setup_regions(regions, blend, min_markers, coarser, self.mode, self.lam_sparsity,
                                self.lam_temporal)

    def to_rig(self, z: np.ndarray) -> np.ndarray:
        """(…, M, 3) head-stabilised actor markers carried into the rig's frame: rest + J⁻¹ (z − anchor)
        (ALGORITHMS.md §12 (c)); the identity for the rig's own face."""
        d = np.asarray(z, dtype=np.float64) - self.anchor
        if self.jac is not None:
            d = np.einsum("mab,...mb->...ma", self._jac_inv, d)
        return self.rest + d

    def register(self, neutral: np.ndarray, variance: np.ndarray | None = None) -> None:
        """Register the actor's neutral markers (M, 3) (rig frame after the similarity, NaN where never seen)
        to the rig (ALGORITHMS.md §12 (b)): a smooth warp (``solvers.retarget.SmoothWarp``) from the rig's
        marker points to them; the markers never seen take the warp's image of their rig point.
        ``variance`` (M,): the variance of each neutral mean (noise² / frames). Each marker's offset from the
        rig is shrunk toward 0 by a James–Stein factor max(0, 1 − 30σ²/‖o‖²) (James & Stein 1961; ``SHRINK``): an offset
        as small as the noise (the rig's own face) is noise, and fitting it would bend the residual. With
        ``retarget`` 'jacobian' the motion is carried through the warp's Jacobian at each marker, with 'scale'
        through the similarity alone, with 'none' the rig's own neutral is fitted (a take of the rig's face)."""
        if self.retarget == "none":
            self._set_actor(self.rest, None)
            return
        seen = np.isfinite(neutral).all(axis=1)
        anchor = np.array(neutral, dtype=np.float64)
        if variance is not None:
            off = anchor[seen] - self.rest[seen]
            n2 = np.maximum(np.einsum("mc,mc->m", off, off), 1e-300)
            shrink = np.clip(1.0 - SHRINK * np.asarray(variance)[seen] / n2, 0.0, 1.0)
            anchor[seen] = self.rest[seen] + shrink[:, None] * off
        jac = None
        if seen.sum() >= 4 and (self.retarget == "jacobian" or not seen.all()):
            warp = SmoothWarp(self.rest[seen], anchor[seen], scale=self.warp_scale, lam=self.warp_lambda)
            anchor[~seen] = warp(self.rest[~seen])
            if self.retarget == "jacobian":
                jac = warp.jacobian(self.rest)
                self._jac_inv = np.linalg.inv(jac)
        elif not seen.all():
            anchor[~seen] = self.rest[~seen]
        self._set_actor(anchor, jac)

    # --- regions (Joshi §4) ----------------------------------------------------------------------
    def _setup_regions(self, regions, blend, min_markers, coarser, mode, lam_s, lam_t) -> None:
        """The per-region problems of every tier, coarsest first (``coarser`` levels, then ``regions``): each
        region's markers (their main vertex inside it), the shapes that act in it (``REGION_SHAPE_SHARE`` of a
        shape's largest displacement over the regions), its parent (the region of the tier above holding most of
        its vertices; -1: the global solve) and a solver, or None where it inherits the parent's weights."""
        blend = sp.csr_matrix(blend)
        R = len(regions)
        if blend.shape != (self.V, R + 1):
            raise ValueError(f"The region blend must be (V, R+1) = ({self.V}, {R + 1}), not {blend.shape}.")
        self.blend = blend
        self.marker_blend = np.asarray((self.binding @ blend).todense())  # (M, R+1)
        main_vertex = np.asarray(self.binding.argmax(axis=1)).ravel()
        levels = [[np.asarray(v, dtype=np.int64) for v in lvl] for lvl in [*coarser][::-1] + [regions]]
        flat = [v for lvl in levels for v in lvl]
        region_max = shape_region_max(self.deltas, flat)                    # (all regions, K)
        acting = region_max > REGION_SHAPE_SHARE * region_max.max(axis=0, initial=0.0)
        self.n_regions = len(regions)
        self.region_tiers = []
        n, parents = 0, None
        for lvl in levels:
            tier = []
            for verts in lvl:
                parent, same = -1, False
                if parents is not None:
                    parent = int(np.argmax([np.intersect1d(verts, p, assume_unique=True).size for p in parents]))
                    same = np.array_equal(verts, parents[parent])
                mk = np.flatnonzero(np.isin(main_vertex, verts))
                shapes = np.flatnonzero(acting[n])
                n += 1
                # a region equal to its parent, or with fewer marker coordinates than shapes, inherits
                if same or mk.size < min_markers or shapes.size == 0 or 3 * mk.size < shapes.size:
                    tier.append(_RegionProblem(parent))
                    continue
                rows = (mk[:, None] * 3 + np.arange(3)).ravel()
                others = np.setdiff1d(np.arange(self.K), shapes)
                solver = WeightSolver(self.A[np.ix_(rows, shapes)], mode=mode, lam_sparsity=lam_s,
                                      lam_temporal=lam_t, lam_reg=self.lam_region)
                tier.append(_RegionProblem(parent, rows, shapes, others, solver, self.A[np.ix_(rows, others)]))
            self.region_tiers.append(tier)
            parents = lvl

    # --- poses -----------------------------------------------------------------------------------
    def corrective_markers(self, W: np.ndarray) -> np.ndarray:
        """(F, 3M) the correctives' displacement of the markers for global weights W (F, K); 0 without any."""
        W = np.atleast_2d(np.asarray(W, dtype=np.float64))
        if self._activate is None:
            return np.zeros((W.shape[0], 3 * self.M))
        return self._activate(W) @ self.Em

    def _corrective_per_marker(self, per_marker: np.ndarray) -> np.ndarray:
        """(M, 3) the correctives' displacement of each marker for its own blended weights (M, K)."""
        if self._activate is None:
            return np.zeros((self.M, 3))
        return np.einsum("mc,cmx->mx", self._activate(per_marker), self.Em.reshape(self.C, self.M, 3))

    def markers_at(self, w: np.ndarray) -> np.ndarray:
        """(M, 3) the rig's marker points for global weights w (correctives included), in the rig's frame."""
        return self.to_rig(self._fit_at(w))

    def markers_regional(self, W: np.ndarray) -> np.ndarray:
        """(M, 3) the rig's marker points for region weights W (R+1, K): Joshi §4 blend at the markers."""
        return self.to_rig(self._fit_regional(W))

    def _fit_at(self, w: np.ndarray) -> np.ndarray:
        """(M, 3) the fitted markers on the actor (anchor + J A w) for global weights w."""
        return self.anchor + (w @ self.Dm + self.corrective_markers(w)[0]).reshape(-1, 3)

    def _fit_regional(self, W: np.ndarray) -> np.ndarray:
        per_marker = self.marker_blend @ W  # (M, K)
        return (self.anchor + np.einsum("mk,kmc->mc", per_marker, self.Dm.reshape(self.K, self.M, 3))
                + self._corrective_per_marker(per_marker))

    def pose(self, w: np.ndarray) -> np.ndarray:
        """(V, 3) float64 surface for global weights (K,) or region weights (R+1, K) (ALGORITHMS.md §1, Joshi §4),
        correctives included: the ``surface`` callable the solver was given."""
        if self.surface is None:
            raise ValueError("This take solver was built without a surface evaluator: it solves the markers only.")
        return np.array(self.surface(np.asarray(w, dtype=np.float64)), dtype=np.float64)

    # --- calibration (Ma §3.1; Umeyama 1991) -----------------------------------------------------
    def calibrate(self, markers: np.ndarray, frames) -> np.ndarray:
        """4×4 similarity taking the take (rig units) onto the rig at rest, from the mean of the neutral frames
        (``frames``: a count from the start, or (first, last) inclusive): Umeyama 1991, Eq. 40–42."""
        a, b = (0, max(1, int(frames)) - 1) if np.isscalar(frames) else (int(frames[0]), int(frames[1]))
        pos = markers[a:b + 1]
        with np.errstate(invalid="ignore"):
            cloud = np.nanmean(pos, axis=0)
        ok = np.isfinite(cloud).all(axis=1)
        if ok.sum() < 3:
            raise ValueError("Calibration needs at least 3 markers seen in the neutral frames.")
        s, R, t = umeyama(cloud[ok], self.rest[ok], scale=True)
        return to_matrix(s, R, t)

    def neutral_range(self, X: np.ndarray, neutral, calibration_frames: int) -> tuple[tuple[int, int], dict | None]:
        """((first, last), why) of the actor's neutral in ``X`` (F, M, 3) rig units: ``neutral`` (first, last)
        inclusive, 'auto' (``solvers.retarget.neutral_stretch``, ``calibration_frames`` long) or None (the first
        ``calibration_frames``). ValueError (one sentence) for a range outside the take."""
        F = X.shape[0]
        if neutral is None:
            return (0, max(1, min(int(calibration_frames), F)) - 1), None
        if isinstance(neutral, str):
            if neutral != "auto":
                raise ValueError(f"The neutral frames must be 'auto' or a range A:B, not '{neutral}'.")
            a, b, why = neutral_stretch(X, self.rest, max(1, min(int(calibration_frames), F)))
            return (a, b), why
        a, b = int(neutral[0]), int(neutral[1])
        if not 0 <= a <= b < F:
            raise ValueError(f"The neutral frames {a}:{b} are outside the take, which has frames 0 to {F - 1}.")
        return (a, b), None

    # --- the solve -------------------------------------------------------------------------------
    def solve(self, markers: np.ndarray, *, unit_factor: float = 1.0,
              calibration_frames: int = DEFAULTS["calibration_frames"], calibrate: bool = True,
              neutral=None, stable: np.ndarray | None = None, head_markers: np.ndarray | None = None,
              progress: Progress = None, cancel: Callable[[], bool] | None = None) -> TakeSolution:
        """Solve every frame of ``markers`` (F, M, 3) (take units, NaN where missing; columns in the order
        of the binding rows). Ma et al. 2016 §3.1 alternation of Kabsch and the QP of Joshi Eq. 2 /
        Ma Eq. 3–4 frame by frame (forward, and with ``two_pass`` also backward, averaged), optional
        per-region QPs (Joshi §4), then the RBF residual (Joshi Eq. 3; Fidaleo Eq. 1–5).

        Retargeting (ALGORITHMS.md §12): the actor's neutral is the mean of the neutral frames (``neutral``:
        (first, last), 'auto', or None for the first ``calibration_frames``); the markers' motion from it is
        fitted, carried into the rig by ``register``, never their absolute positions. Head motion comes from
        the ``stable`` face markers ((M,) bool, default all) and the ``head_markers`` (F, H, 3) take units, markers
        on the head that no expression moves (a head band), which need no binding."""
        t0 = time.perf_counter()
        X = np.asarray(markers, dtype=np.float64) * float(unit_factor)
        if X.ndim != 3 or X.shape[2] != 3:
            raise ValueError(f"Marker positions must be frames x markers x 3, not {X.shape}.")
        F, M, _ = X.shape
        if M != self.M:
            raise ValueError(f"The take has {M} marker columns but the solver was built for {self.M}.")
        if F == 0:
            raise ValueError("The take has no frames.")
        H = np.zeros((F, 0, 3)) if head_markers is None else np.asarray(head_markers, dtype=np.float64) * float(unit_factor)
        if H.shape[:1] != (F,) or H.ndim != 3:
            raise ValueError(f"The head markers must be {F} frames x markers x 3, not {H.shape}.")
        stable = np.ones(M, dtype=bool) if stable is None else np.asarray(stable, dtype=bool)
        neutral_frames, why = None, None
        if calibrate:   # found on the raw markers: the stillness score is measured against their noise
            neutral_frames, why = self.neutral_range(X, neutral, calibration_frames)
        if self.marker_smoothing and F > 1:  # optical noise is white in time: a light low-pass
            X = _smooth_in_time(X, self.marker_smoothing)
            if H.shape[1]:
                H = _smooth_in_time(H, self.marker_smoothing)
        if calibrate:
            cal = self.calibrate(X, neutral_frames)
        else:
            cal = np.eye(4)
        Y = X @ cal[:3, :3].T + cal[:3, 3]  # calibrated take, rig space up to head motion
        Yh = H @ cal[:3, :3].T + cal[:3, 3]
        a, b = neutral_frames if neutral_frames is not None else (0, -1)
        with np.errstate(invalid="ignore"):
            if calibrate:
                self.register(*_neutral_mean(Y[a:b + 1]))
            else:
                self._set_actor(self.rest, None)
            head_anchor = np.nanmean(Yh[a:b + 1], axis=0) if (calibrate and Yh.shape[1]) else np.zeros((0, 3))
        head_ok = np.isfinite(head_anchor).all(axis=1)
        self._head = (Yh[:, head_ok], head_anchor[head_ok], stable)
        passes = 2 if self.two_pass else 1
        step = max(1, F // 50)

        def progress_at(i: int, offset: int) -> None:
            if i % step == 0 or i == F - 1:
                progress(offset + i + 1, passes * F, "solving")
        report = progress_at if progress is not None else None
        W, Rs, ts, solved = self._pass(Y, range(F), np.zeros(self.K), np.eye(3), np.zeros(3), cancel,
                                       report and (lambda i: report(i, 0)))
        if self.two_pass:
            # Backward pass from the last frame's forward solution; the average of the two causal
            # solutions cancels their lag (a forward–backward smoother, cf. Rauch–Tung–Striebel).
            last = F - 1
            Wb, Rb, tb, _ = self._pass(Y, range(F - 1, -1, -1), W[last], Rs[last], ts[last], cancel,
                                       report and (lambda i: report(i, F)))
            W = 0.5 * (W + Wb)
            Rs, ts = _mean_rigid(Rs, ts, Rb, tb)
        Z = (Y - ts[:, None]) @ Rs  # head-stabilised markers (Σ_c y_c R_ck; a stacked product, not einsum's loop)
        RW = None
        if self.n_regions is not None:
            RW = self._solve_regions(Z, W, solved, cancel)
            fit = self.anchor + np.einsum("mr,frk,kmc->fmc", self.marker_blend, RW,
                                          self.Dm.reshape(self.K, self.M, 3))
            if self._activate is not None:
                fit += np.stack([self._corrective_per_marker(self.marker_blend @ RW[f]) for f in range(F)])
        else:
            fit = self.anchor + (W @ self.Dm + self.corrective_markers(W)).reshape(F, M, 3)
        Zr = self.to_rig(Z)                                  # the markers' motion carried into the rig's frame
        Zr[~solved] = np.nan
        misfit = Zr - self.to_rig(fit)
        motion = Zr - self.rest
        with np.errstate(invalid="ignore", divide="ignore"):
            r2 = np.einsum("fmc,fmc->fm", misfit, misfit)
            d2 = np.einsum("fmc,fmc->fm", motion, motion)
            explained = 1.0 - np.nansum(r2) / np.nansum(d2) if np.nansum(d2) > 0 else float("nan")
            explained_m = 1.0 - np.nansum(r2, axis=0) / np.nansum(d2, axis=0)
        heads = np.einsum("ij,fjk->fik", np.linalg.inv(cal), to_matrix(np.ones(F), Rs, ts))
        heads[:, :3, :] /= float(unit_factor)  # to take units
        with np.errstate(invalid="ignore"):
            rmse = np.sqrt(np.nanmean(r2, axis=1))
        coeffs, rmse_res = None, rmse.copy()
        if self.rbf is not None:
            if progress is not None:
                progress(passes * F, passes * F, "residual")
            target = _smooth_in_time(misfit, self.residual_smoothing) if self.residual_smoothing else misfit
            coeffs = self.residual_coefficients(target)
            after = misfit - self.rbf.Phi[:self.M] @ coeffs      # (M, N) @ (F, N, 3): 20x einsum's speed
            with np.errstate(invalid="ignore"):
                rmse_res = np.sqrt(np.nanmean(np.einsum("fmc,fmc->fm", after, after), axis=1))
        return TakeSolution(weights=W, head=heads, marker_rmse=rmse, marker_rmse_residual=rmse_res,
                            region_weights=RW, coefficients=coeffs, calibration=cal, misfit=misfit,
                            markers_rig=Zr, motion_explained=float(explained),
                            motion_explained_per_marker=explained_m, neutral_frames=neutral_frames,
                            neutral_reason=why, solve_seconds=time.perf_counter() - t0, solver=self)

    def _pass(self, Y, order, w, R, t, cancel, report):
        """One causal sweep over ``order``: per frame, ``iterations`` alternations of weighted Kabsch
        (Umeyama 1991) and the weight QP (Joshi Eq. 2; Ma Eq. 3–4, λ_t to the previous frame), started
        from the previous frame (Ma et al. 2016, §3.1). Frames with fewer than 3 markers hold the pose."""
        F = Y.shape[0]
        W = np.zeros((F, self.K))
        Rs = np.zeros((F, 3, 3))
        ts = np.zeros((F, 3))
        solved = np.zeros(F, dtype=bool)
        Yh, head_anchor, stable = self._head
        if (self._kernel is not None and self.head_motion and self._activate is None and self.mode == "box"
                and bool(stable.all()) and head_anchor.shape[0] == 0):
            self._pass_compiled(Y, np.asarray(order, dtype=np.int64), w, R, t, cancel, report, W, Rs, ts, solved)
            return W, Rs, ts, solved
        rest, Dm = self.anchor, self.Dm
        rw, rw0 = self.rigid_weighting ** 2, self.rigid_noise ** 2
        Yh, head_anchor, stable = self._head
        all_stable = bool(stable.all())
        w_prev = None
        for i, f in enumerate(order):
            if cancel is not None and cancel():
                raise SolveCancelled(f"Take solve cancelled at frame {f} of {F}.")
            y = Y[f]
            valid = np.isfinite(y).all(axis=1)
            rigid = valid if all_stable else valid & stable
            hv = np.isfinite(Yh[f]).all(axis=1) if head_anchor.shape[0] else np.zeros(0, dtype=bool)
            if valid.sum() >= 3 and (not self.head_motion or rigid.sum() + hv.sum() >= 3):
                yv, rest_v = y[rigid], rest[rigid]
                if hv.any():   # head-band markers: rigid, no expression moves them
                    yv = np.vstack([yv, Yh[f][hv]])
                if not self.head_motion:  # the head is fixed: the weight QP is the whole solve
                    b = (y - rest).reshape(-1)
                    w = self._weights(valid, b, w if w_prev is None else w_prev, w, steps=CORRECTIVE_STEPS)
                    w_prev = w
                    solved[f] = True
                    W[f], Rs[f], ts[f] = w, np.eye(3), np.zeros(3)
                    if report is not None:
                        report(i)
                    continue
                for _ in range(self.iterations):
                    disp = (w @ Dm if self._activate is None else w @ Dm + self.corrective_markers(w)[0])
                    disp = disp.reshape(-1, 3)
                    dv = disp[rigid]
                    P = rest_v + dv
                    if hv.any():
                        P = np.vstack([P, head_anchor[hv]])
                        dv = np.vstack([dv, np.zeros((int(hv.sum()), 3))])
                    if rw:  # trust markers the expression moves little: the rig's misfit grows with motion
                        pw = 1.0 / (rw0 + rw * np.einsum("mc,mc->m", dv, dv))
                        R, t = _kabsch(P, yv, pw / pw.sum())
                    else:
                        R, t = _kabsch(P, yv)
                    z = (y - t) @ R  # Rᵀ (y − t): head-stabilised markers
                    w = self._weights(valid, (z - rest).reshape(-1), w if w_prev is None else w_prev, w)
                w_prev = w
                solved[f] = True
            W[f], Rs[f], ts[f] = w, R, t
            if report is not None:
                report(i)
        return W, Rs, ts, solved

    def residual_runs(self) -> list[tuple[int, int, int, int]] | None:
        """The residual vertices as runs of consecutive indices, (a, b, v0, v1): ``residual_vertices[a:b]`` is
        ``v0 .. v1 − 1``; None when they repeat a vertex. Built once (the dense frames add the residual per run)."""
        if getattr(self, "_residual_runs", False) is False:
            rv = np.asarray(self.residual_vertices, dtype=np.int64)
            runs = None
            if rv.size and np.unique(rv).size == rv.size:
                cut = np.flatnonzero(np.diff(rv) != 1) + 1
                a = np.concatenate(([0], cut))
                b = np.concatenate((cut, [rv.size]))
                runs = list(zip(a.tolist(), b.tolist(), rv[a].tolist(), (rv[b - 1] + 1).tolist()))
            self._residual_runs = runs
        return self._residual_runs

    def _pass_compiled(self, Y, order, w, R, t, cancel, report, W, Rs, ts, solved) -> None:
        """``_pass`` in the compiled kernel (``solvers.take_kernel.solve_pass``, same QP and pivot rules),
        run over chunks of frames so that ``cancel`` and ``report`` are heard between them. The QP's H per
        missing-marker mask is the cached one of ``_qp_entry``."""
        take_kernel = self._kernel
        masks, mask_of = take_kernel.pass_masks(Y)
        mu = self.lam_temporal + self.ridge             # H's diagonal term, as _qp_entry builds it
        if self.K > 2 * (3 * self.M + 1) and mu > 0 and not self.pair_penalty.any():
            # many more shapes than marker coordinates: the QP in its low-rank form, H = BᵀB + μI with
            # B = [A_present; √λ_s 1ᵀ] (a step O(K·3M) instead of O(n_free²); the dense form is faster up to about
            # twice 3M + 1 shapes); H's largest entry is on its diagonal
            Bts = np.zeros((masks.shape[0], self.K, 3 * self.M + 1))
            for i, m in enumerate(masks):
                Bts[i, :, :-1] = self.At * np.repeat(m, 3)
            Bts[:, :, -1] = np.sqrt(self.lam_sparsity)
            Hs = np.zeros((0, 1, 1))
            tols = 1e-12 * np.maximum((Bts * Bts).sum(axis=2).max(axis=1) + mu, 1e-300)
        else:
            qps = [self._qp_entry(m)[2] for m in masks]
            Hs = np.stack([q.H for q in qps])
            tols = np.array([q.tol for q in qps])
            Bts = np.zeros((masks.shape[0], 1, 0))
        w, R, t = np.array(w, dtype=np.float64), np.array(R, dtype=np.float64), np.array(t, dtype=np.float64)
        Yc = np.ascontiguousarray(Y, dtype=np.float64)
        F = Y.shape[0]
        chunk = 16          # frames between two looks at cancel / progress (a few ms)
        for start in range(0, order.size, chunk):
            if cancel is not None and cancel():
                raise SolveCancelled(f"Take solve cancelled at frame {int(order[start])} of {F}.")
            self.qp_iterations += take_kernel.solve_pass(
                Yc, order[start:start + chunk], w, R, t, self.anchor, self.Dm, self.At, Hs, Bts, mu, tols, mask_of,
                self.lam_temporal, self.iterations, self.rigid_weighting ** 2, self.rigid_noise ** 2, float(self.lower), float(self.upper), 200, W, Rs, ts, solved,
                bool(solved.any()))
            if report is not None:
                for i in range(start, min(start + chunk, order.size)):
                    report(i)

    def residual_coefficients(self, misfit: np.ndarray) -> np.ndarray:
        """(F, M+P, 3) RBF coefficients for per-frame misfits (F, M, 3) (NaN rows = missing markers):
        frames sharing a missing-marker mask share one factorisation and one multi-right-hand-side solve
        (Joshi Eq. 3; Fidaleo Eq. 1–5)."""
        F = misfit.shape[0]
        out = np.zeros((F, self.rbf.centres.shape[0], 3))
        present = np.isfinite(misfit).all(axis=2)
        keys, inverse = np.unique(np.packbits(present, axis=1), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        for g in range(keys.shape[0]):
            fr = np.flatnonzero(inverse == g)
            if present[fr[0]].sum() == 0:
                continue
            out[fr] = self.rbf.coefficients_batch(misfit[fr])
        return out

    def _weights(self, valid: np.ndarray, b: np.ndarray, w_prev: np.ndarray, w_start: np.ndarray,
                 steps: int = 1) -> np.ndarray:
        """The frame's weights for head-stabilised marker displacements ``b`` (3M,): the linear QP (``_qp``), or
        with correctives ``steps`` Gauss–Newton steps on Aw + C(w) ≈ b: linearise C(w) = Σ_c a_c(w) e_c at the
        current w (J = Σ_c e_c ∇a_cᵀ over the drivers, ``solvers.correctives.linearised_correctives``) and
        solve the box QP of (A + J) w ≈ b − C(w₀) + J w₀, stopping early once a step moves less than 1e-7.
        Where no corrective acts or varies (its drivers at 0) a step is the linear QP with its cached factors."""
        if self._activate is None:
            return self._qp(valid, b, w_prev, w_start)
        if self.mode != "box":    # the general solver's other constraints: the correctives frozen at w instead
            w = w_start
            for _ in range(steps):
                w = self._qp(valid, b - self.corrective_markers(w)[0], w_prev, w)
            return w
        rows, At, linear = self._qp_entry(valid)
        At = self.At if At is None else At                                   # (K, 3M'): Aᵀ of the present rows
        d = self._drivers
        w = np.minimum(np.maximum(w_start, self.lower), self.upper)
        for _ in range(steps):
            C0, J = linearised_correctives(self._activate, self.Em, d, w)    # (1, 3M), (1, 3M, n)
            if not C0.any() and not J.any():    # no corrective acts or varies here: the linear QP
                step = self._qp(valid, b, w_prev, w)
            else:
                Jd = J[0][rows]                                              # (3M', n): ∂C/∂w_d
                r = b[rows] - C0[0][rows] + Jd @ w[d]
                AtJ = At @ Jd                                                # (K, n)
                H = linear.H.copy()                                          # (A + J)ᵀ(A + J) + λ terms
                H[:, d] += AtJ
                H[d, :] += AtJ.T
                H[np.ix_(d, d)] += Jd.T @ Jd
                g = At @ r + self.lam_temporal * w_prev
                g[d] += Jd.T @ r
                if self._kernel is not None:     # the compiled box QP (the same optimum as _CachedBoxQP's)
                    step = w.copy()
                    self._kernel.box_qp_fresh(H, g, step, self.lower, self.upper, qp_tol(H))
                else:
                    step = _CachedBoxQP(H, self.lower, self.upper, cache=False).solve(g, w.copy())
            done = np.abs(step - w).max() < 1e-7
            w = step
            if done:
                break
        return w

    def _qp_entry(self, valid: np.ndarray) -> tuple:
        """(rows, Aᵀ of those rows or None for all, the cached QP) of one missing-marker subset, made once."""
        key = valid.tobytes()
        qp = self._qps.get(key)
        if qp is None:
            rows = np.repeat(valid, 3)
            A = self.A[rows]
            H = A.T @ A + self.lam_sparsity + (self.lam_temporal + self.ridge) * np.eye(self.K)
            if self.lam_antagonist:
                # λ_a w_i w_j is not convex by itself: the temporal term keeps H positive definite along a take;
                # where it cannot (a one-frame keyframe, λ_t = 0), the penalty is left out of this solve
                Hp = H + self.pair_penalty
                try:
                    la.cho_factor(Hp)
                    H = Hp
                except la.LinAlgError:
                    pass
            # Aᵀ of the present rows, contiguous (one gemv a call), and None for all rows (no row selection)
            qp = self._qps[key] = (rows, None if rows.all() else np.ascontiguousarray(A.T),
                                   _CachedBoxQP(H, self.lower, self.upper))
        return qp

    def _qp(self, valid: np.ndarray, b: np.ndarray, w_prev: np.ndarray, w_start: np.ndarray) -> np.ndarray:
        """The frame's weight QP (Joshi Eq. 2 + Ma Eq. 3–4): ``‖Aw − b‖² + λ_s(Σw)² + λ_t‖w − w_prev‖²``
        over the present markers, in the box; one cached solver per missing-marker subset."""
        rows, At, solver = self._qp_entry(valid)
        if self.mode != "box":
            return self.weight_solver.solve(np.where(rows, b, np.nan), w_prev=w_prev, w_start=w_start)
        g = self.At @ b if At is None else At @ b[rows]
        g += self.lam_temporal * w_prev
        return solver.solve(g, w_start)

    def _solve_regions(self, Z: np.ndarray, W: np.ndarray, solved: np.ndarray, cancel) -> np.ndarray:
        """(F, R+1, K) region weights of the take, coarse to fine (Joshi et al. 2003, §4: the hierarchy's coarse
        levels first, finer ones refine locally): each tier's regions solve the QP of Joshi Eq. 2 per region with
        Ma Eq. 3–4's temporal term, regularised toward the parent region's weights (λ_r, ``lam_region``; the
        global solve's for the coarsest tier), forward and backward over the take and averaged as the global
        solve is; regions that inherit take the parent's weights. Z (F, M, 3) head-stabilised markers, W (F, K)
        the global weights (also the background row), ``solved`` the frames the global solve solved."""
        F = W.shape[0]
        B = (Z - self.anchor).reshape(F, -1) - self.corrective_markers(W)   # correctives frozen at the global w
        out = None
        for tier in self.region_tiers:
            ref = np.repeat(W[:, None], len(tier) + 1, axis=1)
            for r, reg in enumerate(tier):
                if out is not None and reg.parent >= 0:
                    ref[:, r] = out[:, reg.parent]
            out = ref.copy()
            for r, reg in enumerate(tier):
                if reg.solver is None:
                    continue
                if cancel is not None and cancel():
                    raise SolveCancelled("Take solve cancelled in the per-region solve.")
                w = self._region_sweep(reg, B, ref[:, r], solved, range(F))
                if self.two_pass:
                    w = 0.5 * (w + self._region_sweep(reg, B, ref[:, r], solved, range(F - 1, -1, -1)))
                out[:, r, reg.shapes] = w
        return out

    @staticmethod
    def _region_sweep(reg: "_RegionProblem", B: np.ndarray, ref: np.ndarray, solved: np.ndarray,
                      order) -> np.ndarray:
        """One causal sweep of region ``reg`` over the frames in ``order``: (F, shapes) weights fitting the region's
        markers of B (F, 3M) with the other shapes at the reference ``ref`` (F, K), λ_r toward ``ref`` and λ_t
        toward the previous frame; a frame with fewer than 3 of the region's markers holds the previous weights."""
        out = np.empty((B.shape[0], reg.shapes.size))
        prev = None
        for f in order:
            b = B[f, reg.rows]
            if solved[f] and np.isfinite(b).sum() >= 9:
                if reg.others.size:
                    b = b - reg.A_others @ ref[f, reg.others]
                w_ref = ref[f, reg.shapes]
                prev = reg.solver.solve(b, w_prev=prev, w_ref=w_ref, w_start=w_ref if prev is None else prev)
            out[f] = prev if prev is not None else ref[f, reg.shapes]
        return out


@dataclass
class _RegionProblem:
    """One region of a per-region take solve: its parent in the tier above (-1: the global solve) and, when it
    solves its own weights, its marker rows of A, the shapes it solves, the others and their columns of A."""

    parent: int
    rows: np.ndarray | None = None
    shapes: np.ndarray | None = None
    others: np.ndarray | None = None
    solver: WeightSolver | None = None
    A_others: np.ndarray | None = None
