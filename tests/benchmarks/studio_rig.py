"""A studio-scale benchmark rig made from ICT FaceKit: its mesh subdivided by midpoint subdivision (every
polygon of n corners becomes n quads through its edge midpoints and its centre), the shapes carried along by
the same averaging, so they stay ICT's local shapes on a denser mesh. One step gives about 106k vertices,
two about 422k. Vertex order: the original vertices first, then the edge midpoints, then the face centres.

The rigs are cached as .npz under the system's temporary folder (``blendshape-studio-bench``, outside the
repository), keyed by the subdivision level; delete the folder to rebuild them.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from solvers.laplacian import polygon_edges

CACHE = Path(tempfile.gettempdir()) / "blendshape-studio-bench"


def subdivide(points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray
              ) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """One step of midpoint subdivision: (S, counts, indices) with S the (V', V) averaging matrix (new
    points = S @ old points; the same S carries every shape's deltas) and the all-quad faces."""
    counts = np.asarray(face_counts, dtype=np.int64)
    idx = np.asarray(face_indices, dtype=np.int64)
    V, F = int(points.shape[0]), counts.size
    edges = polygon_edges(counts, idx)                     # (E, 2) sorted unique, i < j
    E = edges.shape[0]
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    nxt = np.arange(idx.size) + 1
    nxt[starts + counts - 1] = starts
    a, b = idx, idx[nxt]
    key = np.minimum(a, b) * V + np.maximum(a, b)
    edge_of = np.searchsorted(edges[:, 0] * V + edges[:, 1], key)   # corner c -> edge (c, next(c))
    face_of = np.repeat(np.arange(F), counts)
    rows = np.concatenate([np.arange(V), np.repeat(V + np.arange(E), 2), V + E + face_of])
    cols = np.concatenate([np.arange(V), edges.ravel(), idx])
    vals = np.concatenate([np.ones(V), np.full(2 * E, 0.5), 1.0 / counts[face_of]])
    S = sp.csr_matrix((vals, (rows, cols)), shape=(V + E + F, V))
    prv = np.arange(idx.size) - 1
    prv[starts] = starts + counts - 1
    quads = np.stack([idx, V + edge_of, V + E + face_of, V + edge_of[prv]], axis=1)
    return S, np.full(idx.size, 4, dtype=np.int64), quads.ravel()


def studio_rig(levels: int, source=None):
    """(neutral (V, 3) float64, face_counts, face_indices, deltas (K, V, 3) float32) of ICT subdivided
    ``levels`` times (0 = ICT itself), from the cache when there. ``source``: the ICT folder."""
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"ict_subdivided_{levels}.npz"
    if path.exists():
        z = np.load(path)
        return z["neutral"], z["face_counts"], z["face_indices"], z["deltas"]
    from model.readers import load_rig
    if source is None:
        from tests.conftest import ICT_DIR
        source = ICT_DIR
    rig = load_rig(source)
    x, counts, idx = rig.neutral, rig.face_counts, rig.face_indices
    d = rig.deltas.astype(np.float32)
    for _ in range(levels):
        S, counts, idx = subdivide(x, counts, idx)
        x = S @ x
        d = np.stack([(S @ d[k]).astype(np.float32) for k in range(d.shape[0])])
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, neutral=x, face_counts=counts, face_indices=idx, deltas=d)
    tmp.replace(path)
    return x, counts, idx, d


# The start of a probe run in a fresh process (``python -c``) to measure peak memory (Linux): ``status(key)`` reads
# /proc/self/status in bytes; ``reset_peak()`` makes the peak (VmHWM) start again from the resident size now and
# returns that size. (ru_maxrss would not do: a child process starts with its parent's peak.)
MEMORY_PROBE = """
import json, sys, time
def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))
def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    return status("VmRSS")
"""
