"""Pose evaluation: one blended product, vectorised (ALGORITHMS.md §1 and §4). The one place the posed surface is
computed: the viewport, exports, take solves (through a callable), marker drags, authoring and the CLI use it.

Global pose:   x = b0 + Σ_k w_k d_k + Σ_c a_c(w) e_c   (muted correctives left out)
Regional pose: x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v) (+ correctives activated per vertex)

The Shapes list's per-shape settings take part in every evaluation (``model.shape_weights``): weights are
clamped to a shape's slider range, muted (and, while any shape is soloed, unsoloed) shapes count as 0 -- for
the correctives too -- and a shape with in-betweens contributes its piecewise linear curve through them: the
in-betweens are extra rows of the delta matrix, [shapes (K), in-betweens (N), correctives (C)], so a pose is
still one product. A regional pose takes the coefficients of each region's weights, then blends them.

``PoseEvaluator`` is built once per rig content (after an edit, ``with_settings`` makes the edited rig's from it:
sharing its matrices, or copying their rows, where the edit allows; the document does so on every rig edit): it
keeps the shape and corrective deltas as one (K+C, 3U) matrix over the U
vertices that any of them moves, so a global pose is a single matrix-vector product plus a copy of the
neutral (or, where the rig's deltas already are that matrix in the evaluator's dtype -- no in-betweens or
correctives --, reads them in place over all V vertices: no copy). float32 for display, float64 for solving and exports.

Which correctives take part: the unmuted ones by default; ``exclude`` (names or indices) leaves chosen ones
out, e.g. the corrective being authored; ``include_muted`` also applies the muted ones (authoring counts a
muted lower-order corrective as applied, Smith §5.6).
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import scipy.sparse as sp

from solvers.parallel import cores, for_spans

from .correctives import corrective_activations, corrective_activations_per_vertex
from .rig import Rig
from .shape_weights import ShapeWeights

_BLEND_CACHE = 4     # blends whose per-region set-up is kept (levels the user switches between)


class _BlendEntry:
    """What a regional evaluation needs of one blend (V, R+1), kept with a copy of the blend's content so
    that a lookup compares content, not object identity."""

    def __init__(self, blend: sp.csr_matrix) -> None:
        self.shape = blend.shape
        self.indptr, self.indices, self.data = blend.indptr.copy(), blend.indices.copy(), blend.data.copy()
        self.moving_rows: np.ndarray | None = None    # blend[moving] (U, R+1) dense-able, for per-vertex weights
        self.parts: list | None = None                # per-region (cols, phi, D_r) for the gemv path

    def matches(self, blend: sp.csr_matrix) -> bool:
        return (blend.shape == self.shape and blend.nnz == self.data.size
                and np.array_equal(blend.indptr, self.indptr) and np.array_equal(blend.indices, self.indices)
                and np.array_equal(blend.data, self.data))


def _moving_vertices(full: np.ndarray, V: int) -> np.ndarray:
    """The vertices some row of ``full`` ((rows, 3V): the deltas of the shapes, in-betweens and correctives) moves.
    Row by row along contiguous memory (~6x faster than over axes (0, 2) on ICT), with no (rows, 3V) temporary: on
    a 422k-vertex, 228-shape rig that would be 0.3 GB of new memory."""
    moves = np.zeros(full.shape[1], dtype=bool)
    for row in full:
        moves |= row != 0
    return np.flatnonzero(moves.reshape(V, 3).any(axis=1))


def _gathered_columns(full: np.ndarray, cols: np.ndarray, dtype, threads: int | None = None) -> np.ndarray:
    """(rows, cols.size) ``full[:, cols]`` as ``dtype``, one row at a time: the display evaluator's float32 matrix
    without a float64 copy of every row first (a 422k-vertex, 228-shape rig: 2 GB of new memory less, which on a VM
    whose host backs new memory lazily cost seconds). A float64 evaluator gets the one gathered copy it keeps.
    ``threads``: how many share the rows (default: the machine's cores from 64 MB of output on, else one)."""
    out = np.empty((full.shape[0], cols.size), dtype=dtype)
    same = full.dtype == out.dtype

    def rows(a: int, b: int) -> None:
        for row, into in zip(full[a:b], out[a:b]):
            if same:
                np.take(row, cols, out=into)
            else:
                np.copyto(into, row[cols])      # one row's float64 gather at a time, cast into its float32 row
    # a studio rig's rows on the machine's cores (numpy's gather and cast run outside the GIL): the output's first
    # touch, most of the time on 1 GB of new memory, is shared by them too
    for_spans(rows, full.shape[0], threads or (cores() if out.nbytes >= 1 << 26 else 1))
    return out


class PoseEvaluator:
    """Evaluates poses of one rig (a snapshot of its arrays at construction)."""

    def __init__(self, rig: Rig, dtype=np.float32) -> None:
        self.rig = rig
        self.dtype = dtype
        self._D_full: np.ndarray | None = None   # the deltas over every vertex, made on the first evaluate_many
        V = rig.n_vertices
        self.K = rig.n_shapes
        self.shape_weights = sw = ShapeWeights(rig)
        self._nk = self.K + sw.N   # shape rows then in-between rows
        self._neutral = rig.neutral.astype(dtype).reshape(-1)
        corr = list(rig.correctives)
        self._correctives = corr
        self._names = tuple(rig.shape_names)
        self._corr_names = [c.name for c in corr]
        self._muted = np.array([c.muted for c in corr], dtype=bool)
        blocks = [rig.deltas.reshape(rig.n_shapes, 3 * V)]     # (3V, not -1: a rig of no shapes has none)
        if sw.N:
            blocks.append(sw.inbetween_deltas.reshape(sw.N, -1))
        if corr:
            blocks.append(np.stack([c.delta for c in corr]).reshape(len(corr), -1))
        full = np.concatenate(blocks, axis=0) if len(blocks) > 1 else blocks[0]
        if len(blocks) == 1 and full.dtype == np.dtype(dtype) and np.shares_memory(full, rig.deltas):
            # The rig's own deltas are the matrix, read in place over every vertex: a float64 evaluator of a rig
            # without in-betweens or correctives (the solves', exports' and a batch worker's) holds no copy of them
            # (ICT: 29 MB less and ~15 ms; a 422k-vertex, 228-shape rig: ~2 GB less in every batch worker). A
            # pose then reads the columns of the vertices no shape moves too (ICT: 26.7k instead of 21.2k).
            self.moving_vertices = np.arange(V)
            self._cols = None                 # every column: ``out += w @ D``, no scatter
            self._D = full
        else:
            moving = _moving_vertices(full, V)
            self.moving_vertices = moving
            self._cols = (moving[:, None] * 3 + np.arange(3)).reshape(-1)
            # (K+C, 3U) row-major: w @ D is a fast BLAS gemv.
            self._D = _gathered_columns(full, self._cols, dtype)
        self._blends: list[_BlendEntry] = []
        self._shape_moving_cache: np.ndarray | None = None   # ``_shape_moving``, made on the first regional pose
        self._inbetween_refs = _inbetween_refs(rig)   # the arrays themselves (kept alive), not their ids
        # the arrays the matrices were made of (the rig's own objects: an edit replaces them, never changes them)
        self._sources = _row_sources(rig)

    def with_settings(self, rig: Rig, shape_rows=None) -> "PoseEvaluator":
        """An evaluator of ``rig`` -- this one's rig after an edit -- made of this one's matrices where it can:

        - shared, no copy, when the edit left every array they were made of in place: other mute, solo or ranges, a
          renamed shape or corrective, other drivers (a rename on a 106k-vertex, 228-shape rig took 1-2 s to
          rebuild them);
        - else, with ``shape_rows`` (an edit of the shape list: shapes reordered, deleted, put back, duplicated, or
          one shape's deltas replaced), copied row by row: ``shape_rows[k]`` is the index among this evaluator's
          shapes of the one whose deltas the edited rig's shape k has, unchanged, or -1 where they are new (read
          from the rig); in-between and corrective rows are kept where their delta arrays are the same objects.
          One pass over the gathered float matrix instead of the gather and conversion of the rig's float64
          deltas (on that rig 232 MB read instead of 580 MB, and no temporaries). Its moving vertices stay this
          one's: those of the shapes a delete took away are kept (their columns are then zero). Made from scratch
          when a new row moves a vertex outside them;
        - else made from scratch.

        ``rig`` may be this evaluator's own Rig object, edited in place since (edits replace its arrays)."""
        sources = _row_sources(rig)
        if self.made_of(rig, sources):
            D = self._D
        elif shape_rows is not None and rig.neutral is self._sources[0]:
            D = self._rows_for(rig, sources, shape_rows)
            if D is None:
                return PoseEvaluator(rig, self.dtype)
        else:
            return PoseEvaluator(rig, self.dtype)
        ev = object.__new__(PoseEvaluator)
        ev.__dict__.update(self.__dict__)
        ev.rig = rig
        ev.shape_weights = sw = ShapeWeights(rig)
        ev.K, ev._nk = rig.n_shapes, rig.n_shapes + sw.N
        ev._correctives = list(rig.correctives)
        ev._names = tuple(rig.shape_names)
        ev._corr_names = [c.name for c in rig.correctives]
        ev._muted = np.array([c.muted for c in rig.correctives], dtype=bool)
        ev._inbetween_refs = _inbetween_refs(rig)
        ev._sources = sources
        if D is not self._D:
            ev._D, ev._D_full = D, None
            ev._blends, ev._shape_moving_cache = [], None
        else:   # the per-blend set-up is made of the same rows: kept (on a studio rig it takes a second to redo)
            ev._blends = list(self._blends)
        return ev

    def _rows_for(self, rig: Rig, sources: tuple, shape_rows) -> np.ndarray | None:
        """``with_settings``'s matrix of ``rig`` from this one's rows (``shape_rows``: see there), or None when a
        new row moves a vertex outside this one's moving vertices."""
        shape_rows = np.asarray(shape_rows, dtype=np.int64).reshape(-1)
        if shape_rows.size != rig.n_shapes or (shape_rows >= self.K).any():
            raise ValueError(f"shape_rows: {rig.n_shapes} rows of 0..{self.K - 1} or -1 expected")
        inbetween_row = {id(d): self.K + j for j, (_, d) in enumerate(self._sources[2])}
        corrective_row = {id(d): self._nk + j for j, d in enumerate(self._sources[3])}
        rows = np.concatenate([shape_rows, [inbetween_row.get(id(d), -1) for _, d in sources[2]],
                               [corrective_row.get(id(d), -1) for d in sources[3]]]).astype(np.int64)
        new = np.flatnonzero(rows < 0)
        fresh = []
        if new.size:
            V = rig.n_vertices
            outside = np.ones(V, dtype=bool)
            outside[self.moving_vertices] = False
            K, N = rig.n_shapes, len(sources[2])
            for r in new:
                d = rig.deltas[r] if r < K else sources[2][r - K][1] if r < K + N else sources[3][r - K - N]
                d = np.asarray(d).reshape(V, 3)
                if d[outside].any():
                    return None
                fresh.append(d[self.moving_vertices].reshape(-1))
        D = np.take(self._D, np.where(rows < 0, 0, rows), axis=0)
        for r, d in zip(new, fresh):
            D[r] = d
        return D

    def made_of(self, rig: Rig, sources: tuple | None = None) -> bool:
        """Whether ``rig``'s arrays now are the very ones this evaluator's matrices were made of (then
        ``with_settings`` shares them; ``sources``: ``_row_sources(rig)`` when the caller has it)."""
        return _same_sources(_row_sources(rig) if sources is None else sources, self._sources)

    def shares_matrices(self, other: "PoseEvaluator | None") -> bool:
        """Whether ``other`` evaluates with this one's very matrices (``with_settings`` kept them)."""
        return other is not None and other._D is self._D

    # --- which correctives ------------------------------------------------------------------------
    def live(self, exclude: Iterable = (), include_muted: bool = False) -> np.ndarray:
        """(C,) 1.0 for every corrective that is applied, 0.0 for the muted (unless ``include_muted``) and for
        those named or indexed in ``exclude``."""
        on = np.ones(len(self._correctives)) if include_muted else (~self._muted).astype(np.float64)
        for e in exclude:
            if isinstance(e, (int, np.integer)):
                on[int(e)] = 0.0
            else:
                on[[i for i, n in enumerate(self._corr_names) if n == e]] = 0.0
        return on

    def activations(self, weights: np.ndarray) -> np.ndarray:
        """Corrective activations a_c(w) (Smith §4.5) of every corrective, muted or not, at the effective weights
        (ranges, mute and solo applied); empty when none."""
        if not self._correctives:
            return np.zeros(0)
        return corrective_activations(self._correctives, self._names, self.shape_weights.effective(weights))

    def _rows(self, W: np.ndarray, exclude: Iterable = (), include_muted: bool = False) -> np.ndarray:
        """(..., K+N+C) the weight of every delta row for weight rows (..., K) (``ShapeWeights.row_weights``)."""
        live = self.live(exclude, include_muted) if self._correctives else None
        return self.shape_weights.row_weights(W, self._correctives, self._names, live)

    # --- evaluation -------------------------------------------------------------------------------
    def evaluate(self, weights: np.ndarray, out: np.ndarray | None = None, *, exclude: Iterable = (),
                 include_muted: bool = False) -> np.ndarray:
        """(V, 3) surface for a global weight vector (K,).

        Only the delta rows of non-zero weight are read when they are few (``_weighted_rows``)."""
        w = self._rows(np.asarray(weights, dtype=np.float64), exclude, include_muted)
        if out is None:
            out = self._neutral.copy()
        else:
            out = out.reshape(-1)
            out[:] = self._neutral
        moved = _weighted_rows(w.astype(self.dtype), self._D)
        if self._cols is None:
            out += moved
        else:
            out[self._cols] += moved
        return out.reshape(-1, 3)

    def evaluate_many(self, weights: np.ndarray, dtype=np.float32) -> np.ndarray:
        """(n, V, 3) surfaces for global weight vectors (n, K) as one matrix product (take exports, PC2 caches),
        in ``dtype``. Uses a copy of the deltas over all 3V columns (zero where nothing moves) in ``dtype``, made
        on first use and kept (the rig's deltas themselves where they are read in place and in ``dtype``): one
        GEMM and one add, no scatter (a scatter into the moving columns costs more than the product)."""
        W = self._rows(np.atleast_2d(np.asarray(weights, dtype=np.float64)))
        dtype = np.dtype(dtype)
        full = self._D_full
        if full is None or full.dtype != dtype:
            if self._cols is None:      # the matrix is over every column already
                full = self._D.astype(dtype, copy=False)
            else:
                full = np.zeros((self._D.shape[0], self._neutral.size), dtype=dtype)
                full[:, self._cols] = self._D
            self._D_full = full
        out = np.matmul(W.astype(dtype), full)
        out += self._neutral.astype(dtype, copy=False)
        return out.reshape(W.shape[0], -1, 3)

    def evaluate_regional(self, region_weights: np.ndarray, blend: sp.spmatrix, *, exclude: Iterable = (),
                          include_muted: bool = False) -> np.ndarray:
        """(V, 3) surface for per-region weights (R, K) blended by a partition of unity ``blend`` (V, R).

        Joshi §4: x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v). Correctives are activated per vertex from the
        blended weights. Without a corrective to apply, one gemv per region over that region's own vertices
        (set up once per blend), so a drag step costs about one global evaluation.
        """
        sw = self.shape_weights
        We = sw.effective(np.asarray(region_weights, dtype=np.float64))
        C = sw.coefficients(We)        # (R+1, K+N): each region's own pose, blended below
        entry = self._blend_entry(blend)
        live = self.live(exclude, include_muted)
        if not live.any():
            return self._regional_gemv(C, entry)
        if entry.moving_rows is None:
            entry.moving_rows = sp.csr_matrix(blend)[self.moving_vertices]
        a = corrective_activations_per_vertex(self._correctives, self._names, np.asarray(entry.moving_rows @ We))
        a *= live
        per_vertex = np.concatenate([np.asarray(entry.moving_rows @ C), a], axis=1)
        D = self._D.reshape(self._D.shape[0], -1, 3)  # (K+C, U, 3)
        out = self._neutral.copy().reshape(-1, 3)
        out[self.moving_vertices] += np.einsum("uk,kuc->uc", per_vertex.astype(self.dtype), D)
        return out

    def pose(self, weights: np.ndarray, blend: sp.spmatrix | None = None, **options) -> np.ndarray:
        """(V, 3) surface of a global pose (weights (K,)) or, with ``blend``, a regional one (weights (R+1, K))."""
        if blend is None or np.ndim(weights) == 1:
            return self.evaluate(weights, **options)
        return self.evaluate_regional(weights, blend, **options)

    # --- the regional gemv path ---------------------------------------------------------------------
    def blend_parts(self, blend: sp.spmatrix) -> list:
        """What the first regional pose of ``blend`` sets up (its regions' blocks of the deltas, ``_region_parts``),
        made without touching this evaluator's cache: callable on another thread while the evaluator poses, then
        handed to ``adopt_blend_parts`` on its own (a marker drag's level, found while Marker Mode waits for a press:
        0.1-0.4 s on the 106k-vertex, 228-shape studio rig)."""
        return self._region_parts(sp.csr_matrix(blend))

    def adopt_blend_parts(self, blend: sp.spmatrix, parts: list) -> None:
        """Keep ``parts`` (``blend_parts(blend)`` of this evaluator) for the poses of ``blend``."""
        entry = self._blend_entry(blend)
        if entry.parts is None:
            entry.parts = parts

    def _blend_entry(self, blend: sp.spmatrix) -> _BlendEntry:
        B = blend if sp.isspmatrix_csr(blend) else sp.csr_matrix(blend)
        for i, e in enumerate(self._blends):
            if e.matches(B):
                if i:
                    self._blends.insert(0, self._blends.pop(i))
                return e
        e = _BlendEntry(B)
        self._blends = [e] + self._blends[:_BLEND_CACHE - 1]
        return e

    def _regional_gemv(self, W: np.ndarray, entry: _BlendEntry) -> np.ndarray:
        if entry.parts is None:
            entry.parts = self._region_parts(sp.csr_matrix((entry.data, entry.indices, entry.indptr),
                                                           shape=entry.shape))
        out = self._neutral.copy()
        Wf = W.astype(self.dtype)
        for r, (cols, phi, D) in enumerate(entry.parts):
            if cols.size and Wf[r].any():
                out[cols] += phi * _weighted_rows(Wf[r], D)
        return out.reshape(-1, 3)

    def _region_parts(self, blend: sp.csr_matrix) -> list:
        """Per region r: the columns (3 per vertex) of the vertices it covers that a shape moves, φ_r there,
        and the shapes' (and in-betweens') deltas at those vertices as (K+N, 3n).

        Each region's block is gathered a row at a time along contiguous memory (``_gathered_columns``, on the
        machine's cores for a large one): ``D[:, p]`` over a (K, U, 3) view made a transposed copy and then a
        second one, and the shapes' moving vertices were found over axes (0, 2) of a float temporary; the first
        drag on the 106k-vertex, 228-shape studio rig waited 2.0-2.8 s for it."""
        K = self._nk
        D = self._D[:K]
        pos = np.full(self.rig.n_vertices, -1, dtype=np.int64)
        shape_moving = self._shape_moving()
        pos[self.moving_vertices[shape_moving]] = np.flatnonzero(shape_moving)
        B = sp.csc_matrix(blend)
        parts = []
        for r in range(B.shape[1]):
            lo, hi = B.indptr[r], B.indptr[r + 1]
            verts, phi = B.indices[lo:hi], B.data[lo:hi]
            p = pos[verts]
            keep = p >= 0
            verts, phi, p = verts[keep], phi[keep], p[keep]
            Dr = _gathered_columns(D, (p[:, None] * 3 + np.arange(3)).reshape(-1), self.dtype)
            cols = (verts[:, None] * 3 + np.arange(3)).reshape(-1)
            parts.append((cols, np.repeat(phi, 3).astype(self.dtype), Dr))
        return parts

    def _shape_moving(self) -> np.ndarray:
        """(U,) bool: which of ``moving_vertices`` a shape or in-between row moves (the others only a corrective
        moves); every one where the evaluator's rows are those alone. Made once."""
        if self._shape_moving_cache is None:
            U, K = self.moving_vertices.size, self._nk
            moving = np.ones(U, dtype=bool)         # moving_vertices were found over these rows alone
            if K < self._D.shape[0] or self._cols is None:
                moving[:] = False
                moving[_moving_vertices(self._D[:K], U)] = True
            self._shape_moving_cache = moving
        return self._shape_moving_cache


def _weighted_rows(w: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``w @ D`` for one weight row ``w`` (R,) over the delta rows ``D`` (R, n), reading only the rows of non-zero
    weight when they are fewer than a third of them (a keyed animation of a few shapes, a slider on the neutral:
    ICT, 3 of 57 rows, 0.14 instead of 0.58 ms a global pose; a regional one reads them region by region): the same
    sums of the same terms."""
    live = np.flatnonzero(w)
    if 3 * live.size < w.size:
        return w[live] @ D[live]
    return w @ D


def _inbetween_refs(rig: Rig) -> list:
    return [(n, i.weight, i.delta) for n in rig.shape_names for i in rig.inbetweens.get(n, ())]


def _row_sources(rig: Rig) -> tuple:
    """What an evaluator's matrices are made of, row by row: the neutral, the shapes' deltas, each in-between's
    weight and delta (in the rows' order: by shape, each shape's as listed) and each corrective's delta (the arrays
    themselves)."""
    return (rig.neutral, rig.deltas, [(i.weight, i.delta) for n in rig.shape_names for i in rig.inbetweens.get(n, ())],
            [c.delta for c in rig.correctives])


def _same_sources(a: tuple, b: tuple) -> bool:
    """Whether two ``_row_sources`` make the same matrix: the same arrays in the same rows (an in-between's weight
    is not in its row: ``ShapeWeights`` reads it from the rig)."""
    (na, da, ia, ca), (nb, db, ib, cb) = a, b
    return (na is nb and da is db and len(ia) == len(ib) and all(x[1] is y[1] for x, y in zip(ia, ib))
            and len(ca) == len(cb) and all(x is y for x, y in zip(ca, cb)))


def evaluate(rig: Rig, weights: np.ndarray) -> np.ndarray:
    """(V, 3) float64 surface of a global pose; convenience for one-off calls (builds an evaluator)."""
    return PoseEvaluator(rig, dtype=np.float64).evaluate(weights)
