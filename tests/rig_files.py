"""Small OBJ rig folders written on the fly for reader tests (bad input is easiest to make by hand), and independent
readings of an OBJ's materials (usemtl per face, an MTL's Kd) to check the parts and exports against."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def grid(n: int = 6) -> tuple[np.ndarray, list[list[int]]]:
    """An n×n vertex grid in the XY plane with quad faces (1-based corner order kept)."""
    ys, xs = np.mgrid[0:n, 0:n]
    verts = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1).astype(float)
    faces = [[r * n + c, r * n + c + 1, (r + 1) * n + c + 1, (r + 1) * n + c] for r in range(n - 1) for c in range(n - 1)]
    return verts, faces


def obj_text(verts: np.ndarray, faces: list[list[int]], with_uv: bool = True) -> str:
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    if with_uv:
        lines += [f"vt {x / 10:.4f} {y / 10:.4f}" for x, y, _ in verts]
        lines += ["usemtl skin"]
        lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in f) for f in faces]
    else:
        lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    return "\n".join(lines) + "\n"


def write_rig_folder(folder: Path, n: int = 6) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """neutral.obj + two shapes (raise, push). Returns (neutral, {name: target vertices})."""
    folder.mkdir(parents=True, exist_ok=True)
    verts, faces = grid(n)
    targets = {"raise": verts + np.array([0, 0, 1.0]) * (verts[:, :1] / n),
               "push": verts + np.array([0.5, 0, 0]) * (verts[:, 1:2] / n)}
    (folder / "neutral.obj").write_text(obj_text(verts, faces))
    for name, t in targets.items():
        (folder / f"{name}.obj").write_text(obj_text(t, faces))
    return verts, targets


def material_of_each_face(obj_path) -> list[str | None]:
    """An independent reading of an OBJ: the material named by the last ``usemtl`` line before each face line."""
    out, current = [], None
    with open(obj_path) as f:
        for line in f:
            if line.startswith("usemtl "):
                current = line.split(None, 1)[1].strip()
            elif line.startswith("f "):
                out.append(current)
    return out


def mtl_kd(mtl_path) -> dict[str, list[float]]:
    """An independent reading of a material library: each ``newmtl``'s ``Kd`` numbers."""
    out, name = {}, None
    with open(mtl_path) as f:
        for line in f:
            words = line.split()
            if words[:1] == ["newmtl"]:
                name = words[1]
            elif words[:1] == ["Kd"]:
                out[name] = [float(w) for w in words[1:4]]
    return out
