"""Personalising a template rig to an actor's captured poses (Ma et al. 2016, §3; ALGORITHMS.md §9).

Plain arrays in, plain arrays out (no model objects). Given the template neutral ``b0*`` (V, 3), the template
deltas ``D*`` (K, V, 3), the triangles, the actor's neutral ``b0`` (a neutral scan, or a first guess that is
re-estimated) and N captured poses ``P_i`` (N, V, 3, the rig's topology, actor space), alternate

(a) per pose, the rigid head pose and the weights (Ma §3.1, Eq. 3–4; ALGORITHMS.md §7): weighted Kabsch /
    Umeyama 1991 (Eq. 40–41) between the model ``x(w_i)`` and the scan, then the box QP
    ``min ‖B w − p̃_i‖² + λ_s (Σw)², 0 ≤ w ≤ 1`` on the head-stabilised scan ``p̃_i = R_iᵀ(P_i − t_i) − b0``;
(b) new deltas (Ma §3, the personalisation energy as ALGORITHMS.md §9 writes it):

    ‖(Wᵀ ⊗ I) vec(D) − vec(P̃)‖²  +  λ_r ‖G' vec(D) + G'(1ᵀ ⊗ b0) − g*‖²  +  λ_d ‖vec(D) − vec(D*)‖²

with ``D_kv = 0`` kept wherever ``D*_kv = 0`` (only the vertices a template shape moves are unknowns, so the
shapes stay local), and, without a neutral scan, the neutral re-estimated by a row of ones in W (a
correction ``c`` of the neutral guess, every vertex an unknown, pulled toward 0 by ``λ_d``).

Without a neutral scan the first guess is not the template's neutral but one made from the poses
(``_neutral_from_poses``): step (a) with the template's shapes alternated with the neutral as the scans' mean
once each scan's expression and head pose are taken off (``NEUTRAL_ROUNDS`` times). Started from the template's
neutral, step (a) reads the actor's identity (7 mm RMS on ``mocap/actor_take``) as expression and the deltas
then carry it: the neutral ended 4.4 mm RMS from the actor's neutral scan over the moving face (placed by one
rigid transform) and the take solved on the result had weights 0.086 RMS off the truth, worse than the
template's own 0.057. From the poses' guess: 2.3 mm and 0.057 (0, 4 and 10 rounds: 4.4 / 2.3 / 2.3 mm,
0.086 / 0.057 / 0.060), and with the head's pose read where no shape acts (below) 2.0 mm and 0.056.

Choices made here (the paper's summary leaves them open):

* ``G'`` is the per-triangle gradient of a piecewise-linear field on the **actor's** neutral (the FEM
  gradient, Botsch et al. 2010 §3.2), each triangle weighted by the square root of its area, so
  ``‖G' x‖² = Σ_t A_t ‖∇x‖²`` is the Dirichlet energy: independent of units and of tessellation density and
  per vertex of the same order as the data term, so λ_r and λ_d mean the same on any rig.
* ``g*`` is the template's deformation gradient transferred to the actor (deformation transfer, Sumner &
  Popović 2004, Eq. 1 and §4): ``Q_kt = Ṽ_kt V_t⁻¹`` with ``V = [e1, e2, n/√|n|]`` on the template triangle
  (``Ṽ`` on the template shape), turned into the actor triangle's orientation by the rotation ρ_t that
  carries the template's neutral triangle onto the actor's (the polar factor of their own deformation
  gradient). The actor's shape should deform its own neutral triangle by ``ρ Q ρᵀ``:
  ``G'(b0 + d_k) ≈ ρ Q ρᵀ Π_t`` with ``Π_t = I − n'n'ᵀ`` the actor triangle's tangent projector, and since
  ``G' b0 = Π_t`` the term is ``‖G' d_k − ρ(Q_kt − I)ρᵀ Π_t‖²`` ("the template's deformation applied
  relative to the actor neutral"). A face larger, turned or sloped differently from the template gets
  shapes that are larger, turned and sloped with it (tests: a face 1.25 times larger and turned by 23°
  gets exactly the template's shapes scaled and turned), which plain closeness to ``D*`` (λ_d) would not.
* The head's pose in step (a) is read by Kabsch over the vertices no shape moves (the skull, the back of the head),
  when they are at least ``STILL_SHARE`` of the surface the poses measure, not over the whole surface: their
  expression is zero whatever the weights, so the pose does not lean on how well the shapes explain the scan, and
  it is found once per scan. On ``mocap/actor_take`` from pose scans alone the neutral went from 2.3 to 2.0 mm off
  the actor's (the vertices no shape moves from 1.3 to 0.5 mm) in 24 s instead of 42; with the neutral scan the
  result is the same (solved 0.190 mm against 0.191, posed 0.262 mm).
* The data term is averaged over the poses (``mean_data``), so λ_r and λ_d weigh the same against 5 scans
  as against 50.
* λ_s is relative: it multiplies the mean squared norm of a shape (``trace(BᵀB)/K``), so the sparsity
  ``(Σw)²`` weighs the same for a dense scan as for 60 markers. Default 1e-4 by measurement on
  ``mocap/actor_take`` at λ_d 0.02 (the take solved on the result / the result posed with the performance's true
  weights, mm): λ_s 0 0.204 / 0.253, 1e-4 0.191 / 0.263, 3e-4 0.193 / 0.301, 1e-3 0.196 / 0.45, 3e-3 0.205 /
  0.69, 0.01 0.209 / 0.84. A larger λ_s shrinks the scans' weights, and the energy leaves each shape's scale
  against its weight free, so the shapes grow to match: the weights lose their meaning. ``gauge=True``
  rescales each shape to the template's size afterwards (``template_gauge``; at λ_s 0.01 and λ_d 0.05 posed
  0.57 mm instead of 0.80, but solved 0.222 mm instead of 0.212; applied in every alternation 0.61 and 0.224).

The deltas are solved for x, y and z at once (the matrix is the same for the three coordinates) by
conjugate gradients on the normal equations, preconditioned by the exact per-vertex blocks of the data term
(the shapes acting at a vertex, coupled by WᵀW) plus the regulariser's diagonal (``_DeltaSystem``); the data
coupling is a dense K×K product over the vertices the shapes move, so no matrix with K² blocks per vertex is
ever formed. ICT FaceKit with 24 scans: 1,997,283 unknowns, 14–25 CG iterations, 5–22 s on a loaded 2-core
machine (Ma et al. report 86k unknowns in 30 s).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .rigid import kabsch
from .weight_solve import WeightSolver

LAM_R = 0.1          # Ma et al. 2016, §3.2: deformation-gradient regulariser
LAM_D = 0.02         # Ma et al. 2016, §3.2: closeness to the template deltas (they use 0.05; measured on
                     # mocap/actor_take, the take solved on the rig personalised from its 24 scans, at λ_s 0.01:
                     # 0.05 gave 0.212 mm, 0.02 0.209 mm, 0.01 0.209 mm; λ_r 0.05 instead of 0.1 0.212 mm)
LAM_S = 1e-4         # Ma et al. 2016, Eq. 3: sparsity (Σw)², relative to a shape's mean squared norm (measured)
ITERATIONS = 3       # alternations of (a) weights and (b) deltas
STILL_SHARE = 0.1    # the head's pose is read where no shape acts when that is at least this share of the surface
NEUTRAL_ROUNDS = 4   # without a neutral scan: alternations making the first guess of it (module docstring)
MIN_AREA = 1e-12     # relative to the mean triangle area: below it a triangle has no gradient


# --- deformation gradients --------------------------------------------------------------------------------
def _triangle_frames(X: np.ndarray, T: np.ndarray):
    """Edges e1, e2 (T, 3), doubled-area normals n (T, 3) and areas (T,) of the triangles of X."""
    e1 = X[T[:, 1]] - X[T[:, 0]]
    e2 = X[T[:, 2]] - X[T[:, 0]]
    n = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(n, axis=1)
    return e1, e2, n, area


def gradient_operator(vertices: np.ndarray, triangles: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """(3T, V) area-weighted gradient operator and (T,) triangle areas.

    Row ``3t + j`` of ``G @ f`` is ``√A_t`` times component j of the gradient of the piecewise-linear
    field f on triangle t (∇φ_i = n̂ × e_i / 2A with e_i the edge opposite corner i; Botsch et al. 2010,
    *Polygon Mesh Processing*, §3.2), so ``‖G f‖² = Σ_t A_t ‖∇f‖²`` (the Dirichlet energy) and
    ``G X`` stacks the 3×3 Jacobians of a map X (rows: coordinates of X, columns: tangent directions).
    Degenerate triangles (area below ``MIN_AREA`` of the mean) get zero rows.
    """
    X = np.asarray(vertices, dtype=np.float64)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    _, _, n, area = _triangle_frames(X, T)
    ok = area > MIN_AREA * max(float(area.mean()) if area.size else 0.0, 1e-300)
    nhat = np.zeros_like(n)
    nhat[ok] = n[ok] / (2.0 * area[ok, None])
    coef = np.zeros(area.shape)
    coef[ok] = 1.0 / (2.0 * np.sqrt(area[ok]))       # √A / (2A)
    rows, cols, vals = [], [], []
    for i in range(3):
        a, b = T[:, (i + 1) % 3], T[:, (i + 2) % 3]
        g = np.cross(nhat, X[b] - X[a]) * coef[:, None]     # √A ∇φ_i, (T, 3)
        for j in range(3):
            rows.append(3 * np.arange(T.shape[0]) + j)
            cols.append(T[:, i])
            vals.append(g[:, j])
    G = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(3 * T.shape[0], X.shape[0]))
    return G, area


def _sumner_frames(X: np.ndarray, T: np.ndarray):
    """Per triangle ``V = [e1, e2, n/√|n|]`` (Sumner & Popović 2004, Eq. 1's fourth vertex) and the area."""
    e1, e2, n, area = _triangle_frames(X, T)
    n4 = n / np.sqrt(np.maximum(np.linalg.norm(n, axis=1), 1e-300))[:, None]
    return np.stack([e1, e2, n4], axis=2), area


class TransferFrames:
    """What deformation transfer from a template neutral to an actor neutral needs per triangle, built
    once: the inverse template frames ``V⁻¹``, the rotation ``ρ_t`` that turns the template triangle into
    the actor's (the polar factor of ``V_actor V⁻¹``), the actor triangle's tangent projector Π and √A."""

    def __init__(self, template_neutral: np.ndarray, actor_neutral: np.ndarray, triangles: np.ndarray):
        self.T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.X0 = np.asarray(template_neutral, dtype=np.float64)
        V0, area0 = _sumner_frames(self.X0, self.T)
        Va, area = _sumner_frames(np.asarray(actor_neutral, dtype=np.float64), self.T)
        self.ok = (area0 > MIN_AREA * max(float(area0.mean()) if area0.size else 0.0, 1e-300)) & \
                  (area > MIN_AREA * max(float(area.mean()) if area.size else 0.0, 1e-300))
        self.V0 = V0
        self.Vi = np.zeros_like(V0)
        self.Vi[self.ok] = np.linalg.inv(V0[self.ok])
        U, _, Wt = np.linalg.svd(Va @ self.Vi)
        d = np.sign(np.linalg.det(U @ Wt))
        U[:, :, 2] *= d[:, None]
        self.rot = U @ Wt
        nn = Va[:, :, 2] / np.maximum(np.linalg.norm(Va[:, :, 2], axis=1), 1e-300)[:, None]
        self.proj = np.eye(3)[None] - nn[:, :, None] * nn[:, None, :]
        self.sqrt_area = np.where(self.ok, np.sqrt(area), 0.0)

    def targets(self, template_delta: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """(3·len(tris), 3) targets for ``G' d_k`` on the triangles ``tris`` (Sumner & Popović 2004).

        ``Q = Ṽ V⁻¹`` is the template triangle's deformation gradient from the template neutral to the
        template shape; turned into the actor triangle's orientation (``ρ Q ρᵀ``, so a shape moves with its
        surface when the actor's face is turned or sloped differently) it is applied to the actor triangle:
        the target is ``(ρ Q ρᵀ − I) Π = ρ (Q − I) ρᵀ Π``, weighted by √A as in ``gradient_operator``.
        Returned in the layout of ``gradient_operator(actor)[rows of tris] @ d`` (row 3t + j, column c)."""
        T = self.T[tris]
        V1, _ = _sumner_frames(self.X0 + template_delta, T)
        QmI = (V1 - self.V0[tris]) @ self.Vi[tris]
        rho = self.rot[tris]
        J = rho @ QmI @ rho.transpose(0, 2, 1) @ self.proj[tris]
        J *= self.sqrt_area[tris][:, None, None]
        return np.ascontiguousarray(J.transpose(0, 2, 1)).reshape(-1, 3)


# --- the delta system (b) ---------------------------------------------------------------------------------
class _DeltaSystem:
    """Normal equations of Ma Eq. 5 over the masked unknowns, for x, y and z at once.

    Unknowns: for each shape k (and, with ``neutral_unknown``, a last "shape" that is the neutral's
    correction) the vertices ``support[k]``; packed shape by shape. ``M = S((WᵀW)⊗I_obs + λ_r ⊕_k G_kᵀG_k
    + λ_d I)Sᵀ`` (S selects the unknowns, I_obs the observed vertices). Matrix-vector products scatter the
    unknowns to a dense (K, Vs·3) array over the vertices Vs any shape moves, multiply by the K×K WᵀW,
    and gather; the regulariser is one block-diagonal sparse product.
    """

    def __init__(self, supports: list[np.ndarray], n_vertices: int, reg: sp.csr_matrix, diag_extra: np.ndarray):
        self.K = len(supports)
        self.counts = np.array([s.size for s in supports], dtype=np.int64)
        self.offsets = np.concatenate(([0], np.cumsum(self.counts)))
        self.n = int(self.offsets[-1])
        allv = np.concatenate(supports)
        self.vs = np.unique(allv)                          # vertices some unknown lives on
        local = np.full(n_vertices, -1, dtype=np.int64)
        local[self.vs] = np.arange(self.vs.size)
        self.shape_of = np.repeat(np.arange(self.K), self.counts)
        self.vert_of = allv
        self.flat = self.shape_of * self.vs.size + local[allv]
        self.reg = reg                                      # (n, n) λ_r ⊕ G_kᵀG_k + λ_d I (+ extra)
        self.reg_diag = reg.diagonal() + diag_extra
        self.diag_extra = diag_extra

    def scatter(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros((self.K * self.vs.size, x.shape[1]))
        out[self.flat] = x
        return out.reshape(self.K, -1)

    def gather(self, Y: np.ndarray, cols: int) -> np.ndarray:
        return Y.reshape(self.K * self.vs.size, cols)[self.flat]

    def _vertex_blocks(self, C: np.ndarray, obs_s: np.ndarray):
        """Per-vertex blocks ``C[s_v, s_v] obs_v + α_v I`` (s_v: the shapes with an unknown at v; α_v the
        regulariser's diagonal there), grouped by pattern s_v, each group's C block eigen-decomposed once:
        the inverse for a vertex is ``U diag(1 / (Λ + α_v)) Uᵀ``."""
        Vs = self.vs.size
        local = np.searchsorted(self.vs, self.vert_of)
        alpha = np.zeros(Vs)
        np.maximum.at(alpha, local, self.reg_diag)
        member = np.zeros((Vs, self.K), dtype=bool)
        member[local, self.shape_of] = True
        key = np.packbits(np.hstack([member, obs_s[:, None] > 0]), axis=1)
        _, group = np.unique(key, axis=0, return_inverse=True)
        group = group.ravel()
        where = np.full((Vs, self.K), -1, dtype=np.int64)
        where[local, self.shape_of] = np.arange(self.n)
        order = np.argsort(group, kind="stable")
        bounds = np.flatnonzero(np.diff(group[order])) + 1
        blocks = []
        for verts in np.split(order, bounds):
            shapes = np.flatnonzero(member[verts[0]])
            Cb = C[np.ix_(shapes, shapes)] * obs_s[verts[0]]
            lam, U = np.linalg.eigh(Cb)
            blocks.append((where[np.ix_(verts, shapes)], U, lam[None, :, None] + alpha[verts][:, None, None]))
        return blocks

    def solve(self, C: np.ndarray, obs: np.ndarray, rhs: np.ndarray, x0: np.ndarray, *, tol: float,
              maxiter: int) -> tuple[np.ndarray, int]:
        """CG on M X = rhs (n, 3) from x0, preconditioned by the exact per-vertex blocks of the data term
        plus the regulariser's diagonal (``_vertex_blocks``): the data term couples the shapes at a vertex
        strongly (shapes used together in the poses), the regulariser couples neighbouring vertices weakly."""
        if self.n == 0:
            return x0.copy(), 0
        obs_s = obs[self.vs].astype(np.float64)             # observed (1) or not (0), per Vs vertex
        reg = self.reg
        extra = self.diag_extra
        blocks = self._vertex_blocks(C, obs_s)

        def matvec(X):
            D = self.scatter(X)                             # (K, Vs*3)
            Y = C @ D
            Y = (Y.reshape(self.K, self.vs.size, -1) * obs_s[None, :, None]).reshape(self.K, -1)
            return self.gather(Y, X.shape[1]) + reg @ X + extra[:, None] * X

        def precond(R):
            Z = np.empty_like(R)
            for idx, U, den in blocks:
                Z[idx] = U @ ((U.T @ R[idx]) / den)
            return Z

        X = x0.copy()
        R = rhs - matvec(X)
        Z = precond(R)
        Pd = Z.copy()
        rz = np.einsum("ij,ij->j", R, Z)
        bnorm = np.maximum(np.linalg.norm(rhs, axis=0), 1e-300)
        it = 0
        for it in range(1, maxiter + 1):
            Q = matvec(Pd)
            alpha = rz / np.maximum(np.einsum("ij,ij->j", Pd, Q), 1e-300)
            X += Pd * alpha
            R -= Q * alpha
            if (np.linalg.norm(R, axis=0) <= tol * bnorm).all():
                break
            Z = precond(R)
            rz_new = np.einsum("ij,ij->j", R, Z)
            Pd = Z + Pd * (rz_new / np.maximum(rz, 1e-300))
            rz = rz_new
        return X, it


# --- the whole alternation --------------------------------------------------------------------------------
@dataclass
class PersonalizeResult:
    """neutral (V, 3) and deltas (K, V, 3) of the actor's rig; weights (N, K), rotations (N, 3, 3) and
    translations (N, 3) per pose (``P_i ≈ R_i x(w_i) + t_i``); fit_rms per alternation (RMS distance from
    the scans to the model over the observed vertices, before each delta solve and after the last);
    unknowns (scalar unknowns of one delta solve: 3 × vertex-shape pairs), cg_iterations per solve,
    seconds (total), delta_seconds (the delta solves, wall clock) and delta_cpu_seconds (their CPU time, the
    figure that holds on a machine other jobs share)."""

    neutral: np.ndarray
    deltas: np.ndarray
    weights: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    fit_rms: list = field(default_factory=list)
    unknowns: int = 0
    cg_iterations: list = field(default_factory=list)
    seconds: float = 0.0
    delta_seconds: list = field(default_factory=list)
    delta_cpu_seconds: list = field(default_factory=list)


def _supports(deltas: np.ndarray) -> list[np.ndarray]:
    return [np.flatnonzero(np.abs(d).max(axis=1) > 0) for d in deltas]


def solve_pose_weights(neutral: np.ndarray, deltas: np.ndarray, poses: np.ndarray, *, lam_sparsity: float = LAM_S,
                       rigid: bool = True, iterations: int = 10, observed: np.ndarray | None = None,
                       weights0: np.ndarray | None = None, head0: tuple | None = None):
    """Step (a): per pose the weights in [0, 1] (Ma Eq. 3 with its sparsity term, λ_s relative to a shape's
    mean squared norm) and, with ``rigid``, R_i, t_i by Kabsch (Umeyama 1991, Eq. 40–41) between the
    model and the scan (over the vertices no shape moves where they are enough: module docstring), alternated
    with the weights until the head pose settles (at most ``iterations``
    times; Ma §3.1), started from ``weights0`` and ``head0`` = (R, t) if given. Returns (W (N, K),
    R (N, 3, 3), t (N, 3)) with ``P_i ≈ R_i x(w_i) + t_i``."""
    K, V = deltas.shape[0], neutral.shape[0]
    obs = np.ones(V, bool) if observed is None else observed
    moving = np.flatnonzero((np.abs(deltas).max(axis=(0, 2)) > 0) & obs)
    B = deltas[:, moving].reshape(K, -1).T                     # (3Vm, K)
    solver = WeightSolver(B, lam_sparsity=lam_sparsity * float(np.einsum("ij,ij->", B, B)) / max(K, 1))
    N = poses.shape[0]
    W = np.zeros((N, K)) if weights0 is None else weights0.copy()
    R = np.repeat(np.eye(3)[None], N, axis=0) if head0 is None else head0[0].copy()
    t = np.zeros((N, 3)) if head0 is None else head0[1].copy()
    oi = np.flatnonzero(obs)
    size = max(float(np.ptp(neutral[oi], axis=0).max()), 1e-300) if oi.size else 1.0
    still = np.setdiff1d(oi, moving)
    fixed = bool(still.size >= max(30, STILL_SHARE * oi.size))
    if fixed:       # the head's pose from where no shape acts (module docstring): the weights do not move it
        oi = still
    if rigid:
        rest_o = neutral[oi]
        flat_o = None if fixed else deltas[:, oi].reshape(K, -1)
    for i in range(N):
        P = poses[i]
        for _ in range(iterations if rigid and not fixed else 1):   # fixed: one pose, one weight solve
            if rigid:
                x = rest_o if fixed else rest_o + (W[i] @ flat_o).reshape(-1, 3)
                R_new, t_new = kabsch(x, P[oi])
                settled = np.abs(R_new - R[i]).max() < 1e-7 and np.abs(t_new - t[i]).max() < 1e-7 * size
                R[i], t[i] = R_new, t_new
            local = (P[moving] - t[i]) @ R[i] - neutral[moving]
            W[i] = solver.solve(local.reshape(-1), w_start=W[i])
            if rigid and settled:
                break
    return W, R, t


def template_gauge(deltas: np.ndarray, template_deltas: np.ndarray, weights: np.ndarray):
    """Fix the scale of each shape against its weights (Ma's energy leaves ``d_k w_k`` = ``(c d_k)(w_k / c)``
    to the regularisers, and a sparsity term shrinks the weights and grows the shapes): each shape is scaled
    by ``c_k = ⟨d_k, d*_k⟩ / ⟨d_k, d_k⟩``, the least-squares factor onto the template shape, and its weights
    by ``1 / c_k``, so a shape at weight 1 moves as far as the template's does. The poses are unchanged."""
    num = np.einsum("kvc,kvc->k", deltas, template_deltas)
    den = np.einsum("kvc,kvc->k", deltas, deltas)
    c = np.where((den > 0) & (num > 0), num / np.where(den > 0, den, 1.0), 1.0)
    return deltas * c[:, None, None], weights / c[None, :]


def _neutral_from_poses(template_neutral, template_deltas, poses, rounds, **weight_options) -> np.ndarray:
    """The actor's neutral (V, 3) from pose scans alone (module docstring): ``rounds`` alternations of each scan's
    weights and head pose (step (a), ``solve_pose_weights`` with the template's shapes) and the neutral as the
    mean over the scans of ``R_iᵀ(P_i − t_i) − Σ_k w_ik d*_k``, the scan with its expression taken off."""
    nb = np.asarray(template_neutral, dtype=np.float64).copy()
    observed = weight_options.get("observed")
    oi = np.arange(len(nb)) if observed is None else np.flatnonzero(observed)   # the rest keep the template's
    W = R = t = None
    for _ in range(rounds):
        W, R, t = solve_pose_weights(nb, template_deltas, poses, weights0=W,
                                     head0=None if R is None else (R, t), **weight_options)
        rest = np.einsum("nvc,ncd->nvd", poses[:, oi] - t[:, None], R) - np.einsum("nk,kvc->nvc", W,
                                                                                    template_deltas[:, oi])
        nb[oi] = rest.mean(axis=0)
    return nb


def personalize(template_neutral: np.ndarray, template_deltas: np.ndarray, triangles: np.ndarray,
                poses: np.ndarray, neutral: np.ndarray | None = None, *, reestimate_neutral: bool | None = None,
                observed: np.ndarray | None = None, lam_r: float = LAM_R, lam_d: float = LAM_D,
                lam_sparsity: float = LAM_S, iterations: int = ITERATIONS, rigid: bool = True,
                mean_data: bool = True, gauge: bool = False, weights: np.ndarray | None = None,
                tol: float = 1e-5, maxiter: int = 300,
                neutral_rounds: int = NEUTRAL_ROUNDS, progress=None) -> PersonalizeResult:
    """Ma et al. 2016 §3 personalisation (module docstring). poses (N, V, 3) in actor space; ``neutral``
    the actor's neutral (a scan), or None to start from the template's and re-estimate it (the row of
    ones in W). ``observed`` (V,) bool: vertices the poses measure (default all; e.g. marker vertices).
    ``weights`` (N, K): the poses' weights when they are known (no step (a), no head motion: one delta
    solve). ``neutral_rounds``: without ``neutral``, the alternations of ``_neutral_from_poses`` that make the
    neutral's first guess (0: the template's neutral). ``mean_data``: the data term is averaged over the poses
    (so λ_r and λ_d keep their weight whatever the number of scans). With no poses the result is the pure
    deformation transfer of the template onto ``neutral``. ``progress``: called with the stage reached, one short
    phrase ("shape 12/53: its transferred gradients", "round 2/3: the scans' weights"), for a progress display."""
    t0 = time.perf_counter()

    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)
    b0t = np.asarray(template_neutral, dtype=np.float64)
    Dt = np.asarray(template_deltas, dtype=np.float64)
    K, V = Dt.shape[0], b0t.shape[0]
    P = np.asarray(poses, dtype=np.float64).reshape(-1, V, 3)
    N = P.shape[0]
    b0 = b0t.copy() if neutral is None else np.asarray(neutral, dtype=np.float64)
    if reestimate_neutral is None:
        reestimate_neutral = neutral is None and N > 0
    obs = np.ones(V, bool) if observed is None else np.asarray(observed, bool)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)

    if reestimate_neutral and neutral is None and weights is None and neutral_rounds:
        say("the actor's neutral from the pose scans")
        b0 = _neutral_from_poses(b0t, Dt, P, neutral_rounds, lam_sparsity=lam_sparsity, rigid=rigid,
                                 observed=observed)
    G, area = gradient_operator(b0, T)
    G = G.tocsc()
    frames = TransferFrames(b0t, b0, T)
    supports = _supports(Dt)
    blocks, targets = [], []
    tri_of_vertex = sp.csr_matrix((np.ones(T.size), (T.ravel(), np.repeat(np.arange(T.shape[0]), 3))),
                                  shape=(V, T.shape[0]))
    for k, s in enumerate(supports):
        say(f"shape {k + 1}/{K}: its transferred gradients")
        tris = np.unique(tri_of_vertex[s].indices)
        rows = (3 * tris[:, None] + np.arange(3)).ravel()
        Gk = G[:, s][rows]
        blocks.append(lam_r * (Gk.T @ Gk) + lam_d * sp.identity(s.size))
        g = frames.targets(Dt[k], tris)
        targets.append(lam_r * (Gk.T @ g) + lam_d * Dt[k, s])
    if reestimate_neutral:
        supports.append(np.arange(V))
        blocks.append(lam_d * sp.identity(V, format="csr"))
        targets.append(np.zeros((V, 3)))
    reg = sp.block_diag(blocks, format="csr")
    system = _DeltaSystem(supports, V, reg, np.zeros(reg.shape[0]))
    reg_rhs = np.concatenate(targets)
    x = np.concatenate([Dt[k, s] for k, s in enumerate(supports[:K])] +
                       ([np.zeros((V, 3))] if reestimate_neutral else []))

    def unpack(x):
        D = np.zeros((K, V, 3))
        for k in range(K):
            D[k, supports[k]] = x[system.offsets[k]:system.offsets[k + 1]]
        c = x[system.offsets[K]:] if reestimate_neutral else np.zeros((V, 3))
        return D, b0 + c

    D, nb = unpack(x)
    W = np.zeros((N, K))
    R = np.repeat(np.eye(3)[None], N, axis=0)
    t = np.zeros((N, 3))
    if weights is not None:
        W = np.asarray(weights, dtype=np.float64).reshape(N, K)
    result = PersonalizeResult(nb, D, W, R, t, unknowns=3 * system.n)
    oi = np.flatnonzero(obs)

    def fit_rms(D, nb, W, R, t):
        if N == 0:
            return 0.0
        X = nb[oi][None] + np.einsum("nk,kvc->nvc", W, D[:, oi])
        X = np.einsum("nvc,ndc->nvd", X, R) + t[:, None]
        return float(np.sqrt(((X - P[:, oi]) ** 2).sum(axis=2).mean()))

    rounds = iterations if N and weights is None else 1
    for i in range(rounds):
        said = f"round {i + 1}/{rounds}: " if rounds > 1 else ""
        if N:
            if weights is None:
                say(f"{said}the scans' weights")
                W, R, t = solve_pose_weights(nb, D, P, lam_sparsity=lam_sparsity, rigid=rigid, observed=obs,
                                             weights0=W, head0=(R, t))
            result.fit_rms.append(fit_rms(D, nb, W, R, t))
            Wn = np.hstack([W, np.ones((N, 1))]) if reestimate_neutral else W
            # head-stabilised scans minus the starting neutral, over the vertices the unknowns live on
            Pt = np.einsum("nvc,ncd->nvd", P[:, system.vs] - t[:, None], R) - b0[system.vs]
            Pt *= obs[system.vs][None, :, None]
            scale = 1.0 / N if mean_data else 1.0
            C = scale * (Wn.T @ Wn)
            data_rhs = scale * system.gather((Wn.T @ Pt.reshape(N, -1)), 3)
        else:
            C = np.zeros((system.K, system.K))
            data_rhs = 0.0
        say(f"{said}the {K} shapes' deltas ({3 * system.n:,} unknowns)")
        ts, tc = time.perf_counter(), time.process_time()
        x, its = system.solve(C, obs, reg_rhs + data_rhs, x, tol=tol, maxiter=maxiter)
        result.delta_seconds.append(time.perf_counter() - ts)
        result.delta_cpu_seconds.append(time.process_time() - tc)
        result.cg_iterations.append(its)
        D, nb = unpack(x)
    if N and weights is None:
        say("the scans' final weights")
        W, R, t = solve_pose_weights(nb, D, P, lam_sparsity=lam_sparsity, rigid=rigid, observed=obs, weights0=W,
                                     head0=(R, t))
    if N and weights is None and gauge:
        D, W = template_gauge(D, Dt, W)
    if N:
        result.fit_rms.append(fit_rms(D, nb, W, R, t))
    result.neutral, result.deltas, result.weights, result.rotations, result.translations = nb, D, W, R, t
    result.seconds = time.perf_counter() - t0
    return result


# --- what changed ------------------------------------------------------------------------------------------
@dataclass
class ShapeChange:
    """Per shape: rms and max (K,) of ‖d_k − d*_k‖ over the vertices the template shape moves, relative
    (K,) = rms / RMS of the template shape there; per_vertex (K, V) the change's length (a heat map)."""

    rms: np.ndarray
    max: np.ndarray
    relative: np.ndarray
    per_vertex: np.ndarray


def shape_change(template_deltas: np.ndarray, deltas: np.ndarray) -> ShapeChange:
    """How much personalisation moved each shape: ``‖d_k(v) − d*_k(v)‖`` per vertex, its RMS and max over
    the template shape's support, and the RMS relative to the template shape's own RMS there."""
    Dt = np.asarray(template_deltas, dtype=np.float64)
    D = np.asarray(deltas, dtype=np.float64)
    if Dt.shape != D.shape:
        raise RigInputError(f"The shapes to compare differ in size: {Dt.shape} and {D.shape}.")
    per_vertex = np.linalg.norm(D - Dt, axis=2)
    sup = (np.abs(Dt).max(axis=2) > 0) | (per_vertex > 0)
    cnt = np.maximum(sup.sum(axis=1), 1)
    rms = np.sqrt((per_vertex ** 2 * sup).sum(axis=1) / cnt)
    base = np.sqrt(((Dt ** 2).sum(axis=2) * sup).sum(axis=1) / cnt)
    rel = np.divide(rms, base, out=np.zeros_like(rms), where=base > 0)
    return ShapeChange(rms=rms, max=per_vertex.max(axis=1, initial=0.0), relative=rel, per_vertex=per_vertex)
