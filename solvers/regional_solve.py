"""Per-region weight solves for one level of the region hierarchy (Joshi et al. 2003, §4, Eq. 2; ALGORITHMS.md
§4 and §8).

Each region r of a level owns the markers that sit on its vertices (core plus overlap) and the shapes that
move inside it (max displacement in r above ``shape_threshold`` × the region's largest). For every region
holding markers the bounded least-squares problem of ``solvers.weight_solve`` (Joshi Eq. 2 with Ma et al.
2016 Eq. 3–4 sparsity and the λ_r term to the current pose) is solved for the region's shapes; the region's
other shapes keep their weights, and their contribution at the markers is subtracted from the targets.
Regions without markers keep their weights (``unmarked="keep"``), or, for a drag (``unmarked="follow"``), are
solved from every marker with their own shapes; the background row (last) keeps the global weights.
The result is a (R+1, K) regional pose, evaluated as ``x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v)``
(``model.pose.PoseEvaluator.evaluate_regional(W, blend)`` evaluates it).

Everything is set up once per (markers, level) in ``RegionalSolver`` (per-region ``AᵀA`` factors), so one
drag step costs a few small QPs: for ~8 regions and a handful of markers, well under a millisecond each.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError

from .weight_solve import WeightSolver, weight_objective


def shape_region_max(deltas: np.ndarray, regions: list[np.ndarray]) -> np.ndarray:
    """(R, K) the largest displacement ‖d_k(v)‖ of each shape k over each region's vertices (Joshi §2 maps).

    A shape at a time: its displacement lengths over the regions' vertices, laid end to end region after region,
    and one ``maximum.reduceat`` over them. Over the whole (K, V, 3) array at once (``D[:, union]``, twice, in an
    einsum) it took 2.8 s and a transposed copy of the deltas on a 106k-vertex, 228-shape rig, where a marker drag
    waits for it."""
    D = np.asarray(deltas)
    K = D.shape[0]
    out = np.zeros((len(regions), K))
    idx = [np.asarray(r, dtype=np.int64).reshape(-1) for r in regions]
    sizes = np.array([i.size for i in idx], dtype=np.int64)
    if not sizes.any():
        return out
    order = np.concatenate(idx)
    union, where = np.unique(order, return_inverse=True)     # each vertex's length once, read where regions share it
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    filled = sizes > 0
    for k in range(K):
        d = D[k][union]
        lengths = np.sqrt(np.einsum("vc,vc->v", d, d))
        out[filled, k] = np.maximum.reduceat(lengths[where], starts[filled])
    return out


def region_shapes(region_max: np.ndarray, threshold: float = 0.02) -> list[np.ndarray]:
    """Per region, the shapes whose max displacement there is above ``threshold`` × the region's largest."""
    M = np.asarray(region_max)
    out = []
    for row in M:
        top = row.max(initial=0.0)
        out.append(np.flatnonzero(row > threshold * top) if top > 0 else np.zeros(0, dtype=np.int64))
    return out


def markers_in_regions(sampling: sp.spmatrix, regions: list[np.ndarray]) -> list[np.ndarray]:
    """Per region, the markers (rows of ``sampling`` (M, V)) that put weight on a vertex of the region."""
    S = sp.csr_matrix(sampling)
    V = S.shape[1]
    out = []
    for verts in regions:
        mask = np.zeros(V, dtype=np.float64)
        mask[np.asarray(verts, dtype=np.int64)] = 1.0
        out.append(np.flatnonzero(np.asarray(abs(S) @ mask).reshape(-1) > 0))
    return out


class RegionalSolver:
    """Per-region bounded least-squares weight solves for one hierarchy level (Joshi et al. 2003, §4, Eq. 2;
    Ma et al. 2016, Eq. 3–4), set up once per marker set and level.

    regions        R vertex index arrays (core plus overlap) of the level's non-background regions.
    sampling       (M, V) sparse marker sampling (``MarkerSet.S``).
    marker_rows    (3M, K) marker rows of the deltas (``MarkerSet.delta_rows``), row 3j + c.
    deltas         (K, V, 3) shape deltas, used only to find which shapes move in each region; or give
                   ``region_max`` (R, K) (``shape_region_max``) instead.
    solve_background  also solve the background row (default: keep it): from the markers on ``background``'s
                   vertices (the level's vertices the background blends into) when given, as a region's from its
                   markers, and kept when none is there; else globally from all markers. A drag gives it: solved
                   from every marker, the background row followed a dragged chin with mouth shapes at 1 that
                   creased the face where the background blends in, and pinned markers on it moved 0.2 mm.
    antagonists    shape index pairs that must not be both on (ALGORITHMS.md §13; ``model.antagonists``): when a
                   region's solve leaves both above ``exclusion_level``, one of them is held at 0 and the region
                   solved again (an exclusion, the complementarity constraint w_i w_j = 0, by active set): the one
                   whose hold leaves the lower objective, both being tried (holding the weaker could hold the
                   shape the drag needs: a chin dragged down with the lower lip pinned uses jawOpen with
                   mouthShrugLower, and holding jawOpen, the weaker at first, left the chin 1.4 mm short of a
                   5.4 mm move and moved a pinned marker 1.6 mm; ``tests/test_regional_solve.py``).
    unmarked       "keep": a region holding no marker keeps its weights (Joshi §4: a drag changes the regions it
                   touches). "follow": it is solved from every marker with its own shapes, so that a region no marker
                   sits on moves with the face around it where its shapes move the markers (a chin dragged down
                   with one marker opens the jaw: the lower lip's region takes jawOpen too) and stays where they
                   do not (a brow's shapes move no mouth marker). With "keep", the chin's region alone took the jaw
                   shapes and the face creased along its border.
    Other keywords go to ``WeightSolver`` (mode, lam_sparsity, lam_temporal, lam_reg, lower, upper).
    """

    def __init__(self, regions: list[np.ndarray], sampling: sp.spmatrix, marker_rows: np.ndarray, *,
                 deltas: np.ndarray | None = None, region_max: np.ndarray | None = None,
                 shape_threshold: float = 0.02, solve_background: bool = False,
                 background: np.ndarray | None = None, mode: str = "box",
                 lam_sparsity: float = 0.0, lam_temporal: float = 0.0, lam_reg: float = 1e-3,
                 lower=0.0, upper=1.0, antagonists=None, exclusion_level: float = 0.1,
                 unmarked: str = "keep") -> None:
        A = np.asarray(marker_rows, dtype=np.float64)
        S = sp.csr_matrix(sampling)
        M = S.shape[0]
        if A.ndim != 2 or A.shape[0] != 3 * M:
            raise RigInputError(f"The regional solve needs {3 * M} marker rows for {M} markers, not {A.shape[0]}.")
        self.K = A.shape[1]
        self.R = len(regions)
        self.n_markers = M
        self.A = A
        if region_max is None:
            if deltas is None:
                raise RigInputError("The regional solve needs the deltas or the per-region shape displacement.")
            region_max = shape_region_max(deltas, regions)
        region_max = np.asarray(region_max)
        if region_max.shape != (self.R, self.K):
            raise RigInputError(f"The per-region shape displacement must be ({self.R}, {self.K}), not {region_max.shape}.")
        self.shapes = region_shapes(region_max, shape_threshold)
        self.antagonists = [(int(i), int(j)) for i, j in (antagonists or [])]
        self.exclusion_level = float(exclusion_level)
        if unmarked not in ("keep", "follow"):
            raise RigInputError(f"A region without markers must 'keep' its weights or 'follow' the markers, not "
                                f"{unmarked!r}.")
        self.markers = markers_in_regions(S, regions)
        if unmarked == "follow":
            self.markers = [mk if mk.size else np.arange(M) for mk in self.markers]
        lo = np.broadcast_to(np.asarray(lower, dtype=np.float64), (self.K,))
        hi = np.broadcast_to(np.asarray(upper, dtype=np.float64), (self.K,))
        opts = dict(mode=mode, lam_sparsity=lam_sparsity, lam_temporal=lam_temporal, lam_reg=lam_reg)
        self._problems: list[tuple | None] = []  # (r, rows, shapes, other shapes, solver, A_others)
        for r in range(self.R):
            mk, sh = self.markers[r], self.shapes[r]
            if mk.size == 0 or sh.size == 0:
                self._problems.append(None)
                continue
            rows = (3 * mk[:, None] + np.arange(3)).reshape(-1)
            others = np.setdiff1d(np.arange(self.K), sh)
            Ar = A[rows]
            solver = WeightSolver(Ar[:, sh], lower=lo[sh], upper=hi[sh], **opts)
            self._problems.append((r, rows, sh, others, solver, Ar[:, others]))
        self._background = None
        self._background_rows: np.ndarray | None = None      # the background's marker rows (None: all)
        if solve_background and M:
            if background is not None:
                mk = markers_in_regions(S, [np.asarray(background, dtype=np.int64)])[0]
                self._background_rows = (3 * mk[:, None] + np.arange(3)).reshape(-1)
            rows = self._background_rows
            if rows is None or rows.size:
                self._background = WeightSolver(A if rows is None else A[rows], lower=lo, upper=hi, **opts)

    @property
    def active_regions(self) -> list[int]:
        """Regions that hold markers and shapes (the ones a solve changes)."""
        return [p[0] for p in self._problems if p is not None]

    def solve(self, b: np.ndarray, weights: np.ndarray, *, w_prev: np.ndarray | None = None,
              linearised: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """New (R+1, K) regional weights for targets ``b`` (3M,) = marker targets − neutral at the markers
        (NaN for markers to ignore), starting from and regularised toward the current ``weights`` (R+1, K).
        ``w_prev`` (R+1, K) feeds the temporal term when ``lam_temporal`` > 0.

        ``linearised`` = (offset (R+1, 3M), J (R+1, 3M, K)): a weight-dependent extra displacement of the
        markers, linearised per region at its weights W₀ (a rig's correctives, Smith §4.5: C(W) ≈ C(W₀) +
        J (W − W₀), offset = C(W₀) − J W₀); region r then fits (A + J_r) w ≈ b − offset_r (a Gauss–Newton
        step, Joshi Eq. 2 on the linearised model). Needs finite ``b``."""
        if linearised is not None:
            return self._solve_linearised(b, weights, w_prev, *linearised)
        W = np.asarray(weights, dtype=np.float64)
        if W.shape != (self.R + 1, self.K):
            raise RigInputError(f"The regional weights must be ({self.R + 1}, {self.K}), not {W.shape}.")
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        if b.shape[0] != 3 * self.n_markers:
            raise RigInputError(f"The regional solve got {b.shape[0]} target values for {self.n_markers} markers.")
        out = W.copy()
        for prob in self._problems:
            if prob is None:
                continue
            r, rows, sh, others, solver, A_others = prob
            br = b[rows]
            if not np.isfinite(br).any():
                continue
            if others.size:
                br = br - A_others @ W[r, others]
            wr = W[r, sh]
            prev = None if w_prev is None else np.asarray(w_prev)[r, sh]
            out[r, sh] = self._excluding(solver, br, sh, dict(w_ref=wr, w_start=wr, w_prev=prev))
        if self._background is not None:
            wr = W[self.R]
            prev = None if w_prev is None else np.asarray(w_prev)[self.R]
            bb = b if self._background_rows is None else b[self._background_rows]
            if np.isfinite(bb).any():
                out[self.R] = self._excluding(self._background, bb, np.arange(self.K), dict(w_ref=wr, w_start=wr,
                                                                                          w_prev=prev))
        return out

    def _excluding(self, solver: WeightSolver, b: np.ndarray, shapes: np.ndarray, kw: dict) -> np.ndarray:
        """``solver.solve(b, **kw)`` for the region's ``shapes``, then, while an antagonist pair is both above the
        exclusion level, one of the pair most on (the larger smaller weight) held at 0 and the region solved
        again: each of the two is tried with the shapes held so far, and the hold whose solve has the lower
        objective (``_objective``) is kept."""
        w = solver.solve(b, **kw)
        if not self.antagonists:
            return w
        pos = {int(k): n for n, k in enumerate(shapes)}
        pairs = [(pos[i], pos[j]) for i, j in self.antagonists if i in pos and j in pos]
        held: set[int] = set()
        for _ in range(len(pairs)):
            on = [(i, j) for i, j in pairs if w[i] > self.exclusion_level and w[j] > self.exclusion_level]
            if not on:
                break
            pair = max(on, key=lambda p: min(w[p[0]], w[p[1]]))
            tries = [(self._solve_holding(solver, b, held | {k}, kw), k) for k in pair]
            w, k = min(tries, key=lambda t: _objective(solver, t[0], b, kw))
            held.add(k)
        return w

    @staticmethod
    def _solve_holding(solver: WeightSolver, b: np.ndarray, held: set[int], kw: dict) -> np.ndarray:
        """The region's solve with the shapes ``held`` at 0 (a stiff diagonal term on them for this call)."""
        finite = np.isfinite(b)
        A = solver.A
        stiff = 1e6 * max(float(np.trace(solver.AtA)) / max(solver.K, 1), 1.0)
        upd = np.zeros((solver.K, solver.K))
        upd[list(held), list(held)] = stiff
        if not finite.all():
            upd -= A[~finite].T @ A[~finite]
        w = solver.solve_gram(A[finite].T @ b[finite], gram_update=upd, **kw)
        w[list(held)] = 0.0
        return w

    def _solve_linearised(self, b, weights, w_prev, offset, J) -> np.ndarray:
        """``solve`` with ``linearised=(offset, J)``: one Gauss–Newton step per region (see ``solve``)."""
        W = np.asarray(weights, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        if W.shape != (self.R + 1, self.K) or b.shape[0] != 3 * self.n_markers or not np.isfinite(b).all():
            raise RigInputError("The linearised regional solve needs finite targets for every marker and "
                                f"({self.R + 1}, {self.K}) weights.")
        out = W.copy()

        def step(solver, A_sh, J_sh, target, sh, r):
            # (A + J)ᵀ(A + J) = AᵀA + AᵀJ + JᵀA + JᵀJ: the solver's gram plus an update for this call
            upd = A_sh.T @ J_sh + J_sh.T @ A_sh + J_sh.T @ J_sh
            prev = None if w_prev is None else np.asarray(w_prev)[r, sh]
            return solver.solve_gram((A_sh + J_sh).T @ target, w_ref=W[r, sh], w_start=W[r, sh], w_prev=prev,
                                     gram_update=upd)

        for prob in self._problems:
            if prob is None:
                continue
            r, rows, sh, others, solver, A_others = prob
            Jr = J[r][rows]
            target = b[rows] - offset[r][rows]
            if others.size:
                target = target - (A_others + Jr[:, others]) @ W[r, others]
            out[r, sh] = step(solver, self.A[rows][:, sh], Jr[:, sh], target, sh, r)
        if self._background is not None:
            rows = slice(None) if self._background_rows is None else self._background_rows
            allk = np.arange(self.K)
            out[self.R] = step(self._background, self.A[rows], J[self.R][rows], (b - offset[self.R])[rows], allk,
                               self.R)
        return out


def _objective(solver: WeightSolver, w: np.ndarray, b: np.ndarray, kw: dict) -> float:
    """The region's objective at ``w`` (``weight_objective``, ALGORITHMS.md §4) over its finite targets ``b``, with
    the solver's λ's and the references ``kw`` gives."""
    finite = np.isfinite(b)
    return weight_objective(solver.A[finite], b[finite], w, lam_sparsity=solver.lam_sparsity,
                            lam_temporal=solver.lam_temporal, lam_reg=solver.lam_reg, w_prev=kw.get("w_prev"),
                            w_ref=kw.get("w_ref"))
