"""The readers under test, their seed files (real files from ../shared/data and files the application
writes), how a mutated input is laid out on disk, and what a valid result must satisfy."""
from __future__ import annotations

import io
import json
import os
import random
import shutil
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import mutate as M

DATA = Path(os.environ.get("BLENDSHAPE_STUDIO_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data"))
LIMIT = 1e15   # no coordinate or weight a real file holds comes near this


# --- what a valid result is ---------------------------------------------------------------------------------
def _finite(a, what: str, bound: float = LIMIT) -> None:
    a = np.asarray(a)
    assert a.dtype.kind == "f", f"{what}: dtype {a.dtype}"
    assert np.isfinite(a).all(), f"{what}: not finite"
    assert np.abs(a).max(initial=0) < bound, f"{what}: magnitude {np.abs(a).max():.3g}"


def check_rig(rig) -> None:
    V = rig.neutral.shape[0]
    assert rig.neutral.shape == (V, 3) and V > 0, f"neutral shape {rig.neutral.shape}"
    _finite(rig.neutral, "neutral")
    assert rig.deltas.shape == (len(rig.shape_names), V, 3), f"deltas {rig.deltas.shape}"
    _finite(rig.deltas, "deltas")
    assert len(set(rig.shape_names)) == len(rig.shape_names), "duplicate shape names"
    counts, idx = np.asarray(rig.face_counts), np.asarray(rig.face_indices)
    assert counts.size > 0 and counts.min() >= 3, "a face with fewer than 3 corners"
    assert int(counts.sum()) == idx.size, "face counts do not add up to the indices"
    assert idx.min() >= 0 and idx.max() < V, "face index out of range"
    for name, weights in rig.presets.items():
        for k, v in weights.items():
            assert k in rig.shape_names, f"preset {name} names {k}"
            assert np.isfinite(v) and abs(v) < 1e6, f"preset {name}: {k}={v}"
    for c in rig.correctives:
        _finite(c.delta, f"corrective {c.name}")
        assert c.delta.shape == (V, 3)


def check_project(project) -> None:
    check_rig(project.rig)
    w = np.asarray(project.weights)
    assert w.shape == (project.rig.n_shapes,), f"weights {w.shape}"
    _finite(w, "weights", 1e6)


def check_take(take) -> None:
    from model.takes import MarkerTake
    assert np.isfinite(take.rate) and 0 < take.rate <= 100_000, f"rate {take.rate}"
    if isinstance(take, MarkerTake):
        P = take.positions
        assert P.ndim == 3 and P.shape[2] == 3 and P.shape[0] >= 1 and P.shape[1] >= 1, f"positions {P.shape}"
        assert not np.isinf(P).any(), "infinite coordinates"
        assert np.nanmax(np.abs(P), initial=0) < LIMIT, "absurd coordinates"
        assert len(set(take.labels)) == len(take.labels) == P.shape[1]
    else:
        W = take.weights
        assert W.ndim == 2 and W.shape[0] >= 1
        _finite(W, "weights", 1e6)


def check_marker_map(result) -> None:
    mm, rig = result
    B = mm.binding(rig)
    _finite(B.data, "binding")


# --- readers ---------------------------------------------------------------------------------------------
@dataclass
class Target:
    name: str
    seeds: list[Path]
    mutators: list[Callable]
    load: Callable
    check: Callable
    layout: Callable = None          # (seed, mutated bytes, folder) -> the path the reader opens
    extra: dict = field(default_factory=dict)


def _write(folder: Path, name: str, data: bytes) -> Path:
    p = folder / name
    p.write_bytes(data)
    return p


def _same_name(seed: Path, data: bytes, folder: Path) -> Path:
    return _write(folder, seed.name, data)


def build_targets(work: Path) -> dict[str, Target]:
    """Seed files are written into ``work`` (files this application writes) or taken from DATA."""
    from model.gltf import load_gltf, write_gltf
    from model.livelink import read_livelink_csv
    from model.marker_map import load_marker_map
    from model.project import Project, load_project, save_project
    from model.readers import load_obj_folder, load_rig
    from model.takes import load_take
    from model.take_csv import write_marker_csv
    from resources.sample_rig import build_sample_rig, write_sample

    work.mkdir(parents=True, exist_ok=True)
    sample = build_sample_rig()
    # a small OBJ folder: the sample's neutral, two shapes and its presets
    full = work / "sample_full"
    if not full.exists():
        write_sample(full)
    small = work / "obj_seed"
    small.mkdir(exist_ok=True)
    keep = [p for p in sorted(full.iterdir()) if "neutral" in p.name or p.name in
            ("jawOpen.obj", "mouthSmile_L.obj", "presets.json")]
    for p in keep:
        shutil.copy(p, small / p.name)
    presets = json.loads((small / "presets.json").read_text())     # only the shapes this small folder has
    have = {p.stem for p in small.glob("*.obj")}
    (small / "presets.json").write_text(json.dumps({k: {s: w for s, w in v.items() if s in have}
                                                    for k, v in presets.items()}))

    def obj_layout(seed: Path, data: bytes, folder: Path) -> Path:
        rig_dir = folder / "rig"
        rig_dir.mkdir()
        for p in small.iterdir():
            if p.name != seed.name:
                os.link(p, rig_dir / p.name)
        _write(rig_dir, seed.name, data)
        return rig_dir

    proj = work / "sample.bsproj"
    if not proj.exists():
        save_project(Project(rig=sample), proj)
    proj_shapes = work / "sample_shapes.bsproj"     # with the shape list's settings (mute, ranges, in-betweens)
    if not proj_shapes.exists():
        from model.rig import Inbetween
        rig = sample.copy()
        k = rig.shape_index("jawOpen")
        rig.inbetweens = {"jawOpen": [Inbetween(0.5, 0.6 * rig.deltas[k])]}
        rig.ranges, rig.muted, rig.solo = {"mouthSmile_L": (-0.5, 1.5)}, ["eyeBlink_L"], ["jawOpen"]
        rig.validate()
        save_project(Project(rig=rig), proj_shapes)
    gltf_seed = work / "sample.glb"
    if not gltf_seed.exists():
        write_gltf(sample, gltf_seed)

    takes = DATA / "mocap" / "ict_livelink_take"
    csv_seed = work / "take.csv"
    if not csv_seed.exists():
        t = load_take(takes / "take.trc")
        t.positions = t.positions[:40]
        write_marker_csv(csv_seed, t)   # a Vicon Trajectories section
    plain_seed = work / "plain_take.csv"
    if not plain_seed.exists():         # the plain layout, frame,A_X,A_Y,A_Z,...
        t = load_take(takes / "take.trc")
        rows = ["frame," + ",".join(f"{n}_{a}" for n in t.labels for a in "XYZ")]
        rows += [f"{i}," + ",".join("" if v != v else f"{v:.4f}" for v in row)
                 for i, row in enumerate(t.positions[:40].reshape(40, -1))]
        plain_seed.write_text("\n".join(rows) + "\n")

    weights_seed = work / "weights.csv"
    if not weights_seed.exists():
        from model.weights_csv import write_weights_csv
        rng = np.random.default_rng(0)
        write_weights_csv(weights_seed, rng.random((40, 6)), sample.shape_names[:6], rate=30.0)

    def load_weights_take(path):
        from model.weights_csv import read_weights_take
        return read_weights_take(path, sample.shape_names)

    tp = DATA / "thirdparty"
    c3d_small = sorted((tp / "c3d").glob("*"), key=lambda p: p.stat().st_size)[:8]
    trc_small = sorted((tp / "trc").glob("*.trc"), key=lambda p: p.stat().st_size)[:6]

    ict = {}

    def load_map(path):
        if "rig" not in ict:
            raise RuntimeError("the ICT rig must be loaded in the parent before forking")
        mm = load_marker_map(path)
        mm.validate(ict["rig"])    # as a solve does before it uses the map
        return mm, ict["rig"]

    targets = {
        "obj-folder": Target("obj-folder", sorted(small.iterdir()), M.TEXT, lambda p: load_obj_folder(p), check_rig,
                             obj_layout),
        "gltf": Target("gltf", [gltf_seed] + sorted((tp / "gltf").glob("*")), M.BINARY, load_gltf, check_rig),
        "bsproj": Target("bsproj", [proj, proj_shapes], M.BINARY, load_project, check_project),
        "c3d": Target("c3d", [takes / "take.c3d"] + c3d_small, M.BINARY, load_take, check_take),
        "trc": Target("trc", trc_small + [takes / "take.trc"], M.TEXT, load_take, check_take),
        "marker-csv": Target("marker-csv", [csv_seed, plain_seed], M.TEXT, load_take, check_take),
        "livelink": Target("livelink", [DATA / "livelinkface" / "MySlate_3_iPhone.csv"], M.TEXT,
                           lambda p: read_livelink_csv(p), check_take),
        "weights-csv": Target("weights-csv", [weights_seed], M.TEXT, load_weights_take, check_take),
        "marker-map": Target("marker-map", [takes / "marker_map.json"], [M.mutate_json], load_map, check_marker_map),
        "rig-any": Target("rig-any", [proj, gltf_seed], [M.truncate], load_rig, check_rig),
    }
    targets["marker-map"].extra["prepare"] = lambda: ict.setdefault("rig", load_rig(DATA / "ict-facekit"))
    for t in targets.values():
        if t.layout is None:
            t.layout = _same_name
    return targets


def mutate_input(target: Target, seed: Path, rng: random.Random) -> bytes:
    data = seed.read_bytes()
    if target.name == "gltf" and seed.suffix == ".gltf" and rng.random() < 0.6:
        return M.mutate_json(data, rng)
    if target.name == "bsproj" and rng.random() < 0.7:
        return mutate_bsproj(data, rng)
    return rng.choice(target.mutators)(data, rng)


def mutate_bsproj(data: bytes, rng: random.Random) -> bytes:
    """A project with one hostile member: its manifest's values changed, an array's header or bytes
    changed, or a member that inflates to far more than the file's size."""
    src = zipfile.ZipFile(io.BytesIO(data))
    names = src.namelist()
    out = io.BytesIO()
    victim = rng.choice(names)
    roll = rng.random()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for n in names:
            b = src.read(n)
            if n == victim:
                if n.endswith(".json"):
                    b = M.mutate_json(b, rng)
                elif roll < 0.15:
                    b = _bomb()
                elif roll < 0.5:
                    b = _evil_npy_header(b, rng)
                else:
                    b = rng.choice(M.BINARY + [M.evil_number])(b, rng)
            dst.writestr(n, b)
    return out.getvalue()


_BOMB: list[bytes] = []


def _bomb() -> bytes:
    """An .npy member that deflates 64 MiB of zeros behind a header declaring 3 GiB."""
    if not _BOMB:
        header = np.lib.format.header_data_from_array_1_0(np.zeros((1, 3)))
        header["shape"] = (134_217_728, 3)
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, header)
        _BOMB.append(buf.getvalue() + bytes(64 << 20))
    return _BOMB[0]


def _evil_npy_header(b: bytes, rng: random.Random) -> bytes:
    try:
        arr = np.load(io.BytesIO(b), allow_pickle=False)
    except Exception:
        return M.flip_bytes(b, rng)
    header = np.lib.format.header_data_from_array_1_0(arr)
    shape = list(arr.shape) or [1]
    choice = rng.random()
    if choice < 0.3:
        shape[0] = rng.choice([10**12, 0, shape[0] + 1, max(shape[0] - 1, 0)])
    elif choice < 0.5:
        header["descr"] = rng.choice(["<i8", "|O", "<f2", ">f8", "<c16", "|b1"])
    elif choice < 0.7 and arr.dtype.kind in "iu":
        arr = arr.copy()
        flat = arr.reshape(-1)
        if flat.size:
            flat[rng.randrange(flat.size)] = rng.choice([-1, -(2**31), 2**31 - 1, 0])
        buf = io.BytesIO()
        np.save(buf, arr)
        return buf.getvalue()
    elif arr.dtype.kind == "f":
        arr = arr.astype(np.float64).copy()
        flat = arr.reshape(-1)
        if flat.size:
            flat[rng.randrange(flat.size)] = rng.choice([np.nan, np.inf, 1e308])
        buf = io.BytesIO()
        np.save(buf, arr)
        return buf.getvalue()
    header["shape"] = tuple(shape)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    return buf.getvalue() + arr.tobytes()
