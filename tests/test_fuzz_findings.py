"""What a mutation-fuzz audit of the readers found on real files (truncations, byte flips, header fields set to
0/-1/huge, NaN/inf), each as its smallest reproducer made here from the real seed file: refused in one sentence
naming the file (or, for what only the texture or shading uses, left out with a note), never garbage loaded, never a
huge allocation. The hostile files listed in issue 17 are in tests/test_hostile_inputs.py and test_hostile_files.py."""
from __future__ import annotations

import copy
import json
import os
import shutil
import struct
import subprocess
import sys

import numpy as np
import pytest

from model.readers import load_rig
from tests.cli_runner import run_cli
from tests.conftest import DATA, REPO, require_data
from tests.test_hostile_inputs import _refused as refused

NEUTRAL = "generic_neutral_mesh.obj"
GLTF = DATA / "thirdparty" / "gltf"


def _refused(path, *words):
    return refused(load_rig, path, *words)


@pytest.fixture()
def ict_two(tmp_path, ict_dir):
    """The ICT neutral and one target (jawOpen) as a folder of their own."""
    folder = tmp_path / "rig"
    folder.mkdir()
    for name in (NEUTRAL, "jawOpen.obj"):
        shutil.copy(ict_dir / name, folder / name)
    return folder


def _edit_lines(path, prefix, nth, edit):
    lines = path.read_bytes().split(b"\n")
    hits = [i for i, line in enumerate(lines) if line.startswith(prefix)]
    lines[hits[nth]] = edit(lines[hits[nth]])
    path.write_bytes(b"\n".join(lines))


@pytest.mark.parametrize("victim", [NEUTRAL, "jawOpen.obj"])
def test_an_obj_coordinate_beyond_1e9_names_its_own_file(ict_two, victim):
    """Was: '<folder>: the neutral has coordinates beyond ±1e+09' or '<folder>: a shape moves a vertex by more than
    1e+09', naming neither OBJ."""
    _edit_lines(ict_two / victim, b"v ", 99, lambda line: b"v 1e10 0 0")
    _refused(ict_two, f"{victim}: vertex 99")


def test_a_damaged_neutral_face_list_names_the_neutral_too(ict_two):
    """A face index of the neutral changed to another valid vertex: the first target was blamed alone ('jawOpen.obj:
    its face list differs from the neutral's (26384 faces vs 26384)'); now both files and the face are named."""
    def edit(line):
        corners = line.split()
        corners[2] = b"5"
        return b" ".join(corners)
    _edit_lines(ict_two / NEUTRAL, b"f ", 100, edit)
    _refused(ict_two, "jawOpen.obj", NEUTRAL, "face 101")


def test_obj_normals_that_are_not_finite_are_left_out(ict_two):
    """'vn nan 0 1' was kept in the rig's normals (and written back on export)."""
    _edit_lines(ict_two / NEUTRAL, b"f ", 0, lambda line: b"vn nan 0 1\nvn 0 0 1\n" + line)
    rig = load_rig(ict_two)
    assert rig.corners.normals is None or np.isfinite(rig.corners.normals).all()
    assert any("('vn')" in note and NEUTRAL in note for note in rig.corners.notes), rig.corners.notes
    assert rig.corners.uvs is not None   # the UVs are not touched


def _glb(path):
    raw = path.read_bytes()
    length = struct.unpack_from("<I", raw, 12)[0]
    return json.loads(raw[20:20 + length]), raw[20 + length:]


def _write_glb(path, doc, rest):
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + rest
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


def test_a_zero_filled_accessor_of_10_to_the_12_values_is_refused_before_allocating(tmp_path):
    """A sparse morph target's accessor (no buffer view: zeros, the sparse values on top) with its count set to 10¹²:
    was a MemoryError from allocating 12 TB."""
    doc, rest = _glb(require_data(GLTF / "singleBlendshapeCube_sparse.glb"))
    index = next(i for i, a in enumerate(doc["accessors"]) if "bufferView" not in a)
    doc["accessors"][index]["count"] = 10**12
    out = _write_glb(tmp_path / "huge.glb", doc, rest)
    _refused(out, "huge.glb", f"accessor {index}", "1000000000000")


@pytest.mark.parametrize("edit", ["normalized", "no buffer view", "float"])
def test_triangle_indices_that_are_not_whole_numbers_are_refused(tmp_path, edit):
    """Were read as vertex 0 (normalised: i / 65535; no buffer view: zeros; float: tiny numbers truncated), every
    triangle collapsed on one vertex and the rig accepted."""
    doc = json.loads(require_data(GLTF / "SimpleMorph.gltf").read_text())
    doc = copy.deepcopy(doc)
    index = doc["meshes"][0]["primitives"][0]["indices"]
    acc = doc["accessors"][index]
    if edit == "normalized":
        acc["normalized"] = True
    elif edit == "no buffer view":
        del acc["bufferView"]
    else:   # three float32 where the three uint16 were: the view widened to hold them
        acc["componentType"] = 5126
        doc["bufferViews"][acc["bufferView"]]["byteLength"] = 12
    out = tmp_path / "indices.gltf"
    out.write_text(json.dumps(doc))
    _refused(out, "indices.gltf", f"accessor {index}")


def test_the_real_gltf_samples_still_open():
    for name in ("SimpleMorph.gltf", "singleBlendshapeCube_sparse.glb", "MorphStressTest.gltf"):
        rig = load_rig(require_data(GLTF / name))
        assert rig.n_shapes >= 1 and np.isfinite(rig.deltas).all()


# --- lists checked for repeats with list.count: n² on 10⁵ entries, minutes for a file of a few MB ---------------
def _finishes(code: str, timeout: float = 60) -> str:
    """Run ``code`` in a fresh interpreter (this checkout, the test data); a hang is killed and fails the test."""
    env = dict(os.environ, PYTHONPATH=str(REPO), BLENDSHAPE_STUDIO_DATA=str(DATA))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    return proc.stdout


def test_a_corrective_with_300000_drivers_is_refused_at_once(tmp_path, sample_rig):
    """Found by the fuzz (a long line in a project's manifest): the drivers' repeat check took minutes."""
    from model.correctives import Corrective
    from model.project import Project, save_project
    from tests.test_hostile_files import _rewrite_manifest
    rig = sample_rig.copy()
    rig.correctives = [Corrective(drivers=["jawOpen", "mouthSmile_L"], delta=np.zeros_like(rig.neutral))]
    save_project(Project(rig=rig), tmp_path / "c.bsproj")

    def edit(manifest):
        manifest["correctives"][0]["drivers"] = ["jawOpen"] * 300_000
        return manifest
    out = _rewrite_manifest(tmp_path / "c.bsproj", tmp_path / "drivers.bsproj", edit)
    proc = run_cli("info", out, check=False, timeout=60)
    assert proc.returncode == 2 and "drivers.bsproj" in proc.stderr and "more than once: jawOpen" in proc.stderr


def test_a_gltf_with_150000_morph_targets_opens(tmp_path):
    """SimpleMorph's first target listed 150,000 times under distinct names: the target names' and then the rig's
    shape names' repeat checks took minutes."""
    doc = json.loads(require_data(GLTF / "SimpleMorph.gltf").read_text())
    mesh = doc["meshes"][0]
    mesh["primitives"][0]["targets"] = mesh["primitives"][0]["targets"][:1] * 150_000
    mesh["weights"] = [0.0] * 150_000
    mesh["extras"] = {"targetNames": [f"t{k}" for k in range(150_000)]}
    out = tmp_path / "many.gltf"
    out.write_text(json.dumps(doc))
    proc = run_cli("info", out, "--json", check=False, timeout=60)
    assert proc.returncode == 0 and len(json.loads(proc.stdout)["shapes"]) == 150_000, proc.stderr


def test_a_trc_naming_150000_markers_reads_at_once(tmp_path, take_dir):
    """The real take's header with 150,000 more marker names (two frames kept): MarkerTake's repeat check of the
    labels took minutes."""
    lines = (take_dir / "take.trc").read_text().splitlines()[:7]
    extra = 150_000
    lines[3] += "".join(f"\tX{k}\t\t" for k in range(extra))
    lines[4] += "".join(f"\tX{k}\tY{k}\tZ{k}" for k in range(extra))
    lines[5:] = [row + "\t" * (3 * extra) for row in lines[5:]]   # the new markers missing in both frames
    out = tmp_path / "wide.trc"
    out.write_text("\n".join(lines) + "\n")
    proc = run_cli("take-info", out, "--json", check=False, timeout=60)
    assert proc.returncode == 0 and len(json.loads(proc.stdout)["labels"]) == 60 + extra, proc.stderr


def test_a_markers_section_of_150000_markers_is_checked_at_once():
    """A project's markers section (Marker ▸ markers on the rig) with 150,000 names: the names' repeat check took
    minutes before the first two markers on one vertex were refused."""
    out = _finishes(
        "from model.errors import RigInputError\n"
        "from model.markers import MarkerSet\n"
        "from model.readers import load_rig\n"
        "from tests.conftest import DATA\n"
        "rig = load_rig(DATA / 'thirdparty' / 'gltf' / 'SimpleMorph.gltf')\n"
        "d = {'markers': [{'name': f'm{i}', 'vertex': 0} for i in range(150_000)]}\n"
        "try:\n"
        "    MarkerSet.from_dict(d, rig, source='project')\n"
        "except RigInputError as e:\n"
        "    print(e)\n")
    assert "m0 and m1 sit on the same surface point" in out, out


# --- rows far shorter than the header: filled in with NaN to the header's width, GBs from a few MB ----------------
@pytest.mark.parametrize("kind", ["trc", "csv"])
def test_a_header_naming_20000_markers_over_short_rows_is_refused(tmp_path, take_dir, kind):
    """The real take (358 frames of 60 markers) under a header naming 20,000 more: was read as a 358 x 20,060 take,
    all NaN but the 60 (172 MB; 150,000 more markers took 3.9 GB and 17 s from a 5 MB file)."""
    extra = 20_000
    if kind == "trc":
        lines = (take_dir / "take.trc").read_text().splitlines()
        lines[3] += "".join(f"\tX{k}\t\t" for k in range(extra))
        lines[4] += "".join(f"\tX{k}\tY{k}\tZ{k}" for k in range(extra))
    else:
        from model.takes import load_take
        real = load_take(take_dir / "take.c3d")     # as a plain marker CSV (frame,A_X,A_Y,A_Z,...)
        lines = ["frame," + ",".join(f"{n}_{a}" for n in real.labels for a in "XYZ")]
        lines += [f"{i}," + ",".join("" if v != v else f"{v:.6f}" for v in row)
                  for i, row in enumerate(real.positions.reshape(real.n_frames, -1))]
        lines[0] += "".join(f",X{k}_X,X{k}_Y,X{k}_Z" for k in range(extra))
    out = tmp_path / f"wide.{kind}"
    out.write_text("\n".join(lines) + "\n")
    proc = run_cli("take-info", out, check=False, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert f"wide.{kind}" in proc.stderr and "20060 markers" in proc.stderr, proc.stderr


def test_a_file_that_unfolds_into_more_than_the_memory_available_is_refused_before_allocating(tmp_path, sample_rig,
                                                                                             monkeypatch):
    """Found by the fuzz: the sample's glTF with 20,000 morph targets that all share one accessor (2 MB) unfolds into
    6 GB of deltas, 18 GB at the read's peak; where the machine holds less, Linux hands the pages out lazily and kills
    the process as they fill (the window, and the rig the user had open, with it). Such a file, and a project whose
    arrays deflate to more than the memory available, are refused in one sentence before anything is allocated
    (here against 200 MB, faked; with the memory there the same files open)."""
    import model.pages
    from model.gltf import write_gltf
    from model.project import Project, load_project, save_project
    write_gltf(sample_rig, tmp_path / "sample.gltf")
    doc = json.loads((tmp_path / "sample.gltf").read_text())
    prim = doc["meshes"][0]["primitives"][0]
    prim["targets"] = prim["targets"][:1] * 2000
    doc["meshes"][0]["extras"] = {"targetNames": [f"t{k}" for k in range(2000)]}
    doc["meshes"][0].pop("weights", None)
    (tmp_path / "shared.gltf").write_text(json.dumps(doc))
    save_project(Project(rig=sample_rig.copy()), tmp_path / "sample.bsproj")
    assert load_rig(tmp_path / "shared.gltf").n_shapes == 2000             # 1.8 GB at its peak: the memory is there
    monkeypatch.setattr(model.pages, "available_memory", lambda: 200_000_000)
    refused(load_rig, tmp_path / "shared.gltf", "its 2,000 morph targets on 12,651 vertices need 1.8 GB of memory, "
                                                "more than the 200 MB available.")
    assert load_project(tmp_path / "sample.bsproj").rig.n_shapes == sample_rig.n_shapes   # its 10 MB of deltas fit
    monkeypatch.setattr(model.pages, "available_memory", lambda: 2_000_000)
    refused(load_project, tmp_path / "sample.bsproj", "the array 'rig/deltas' needs ", "more than the 2 MB available.")


def test_an_obj_number_with_digit_separators_is_no_number(ict_two):
    """Was: 'v 1_000 0 0' read as x = 1000 (Python's float takes '_' between digits; numpy's text reader, Blender's
    and every C reader stop at it), a face moved 10 m with no word."""
    _edit_lines(ict_two / "jawOpen.obj", b"v ", 7, lambda line: b"v 1_000 0 0")
    _refused(ict_two, "jawOpen.obj: vertex record 8 is not a number", "1_000")


def test_a_c3d_parameter_whose_dimensions_overflow_64_bits_is_skipped(tmp_path):
    """Was: a parameter's size as numpy's int64 product of its dimensions, which ten dimensions of 128 wrap to 0 (and
    eight of 255 to a negative number): the parameter was read as holding no bytes instead of as running past the
    file, which the section's reader skips."""
    from model.take_c3d import _Params, _group, _param
    body = _group(1, "POINT") + _param(1, "LABELS", -1, (128,) * 10, b"") + _param(1, "USED", 2, (), b"\x01\x00")
    section = bytes([1, 80, 1, 84]) + body + b"\x00\x00"
    data = b"\x00" * 512 + section.ljust(512, b"\x00")
    params = _Params(data, 512, tmp_path / "take.c3d", [])
    assert params.number("POINT", "USED") == 1.0          # the parameters around it are read
    assert params.strings("POINT", "LABELS") is None      # it holds 128^10 bytes: not in a 1 kB file


def test_a_trajectories_units_row_of_numbers_is_refused_in_one_short_sentence(tmp_path):
    """The fuzzer's finding (a Vicon seed, 2026-12-06): a units row replaced by a data row listed every distinct cell
    in the sentence, 600 characters and more."""
    from model.errors import RigInputError
    from model.take_csv import read_marker_csv
    n = 40
    names = ",".join(f"M{i},," for i in range(n))
    rows = ["Trajectories", "100", f",,{names}", "Frame,Sub Frame," + ",".join("X,Y,Z" for _ in range(n)),
            ",," + ",".join(f"{-i * 1.37:.6f}" for i in range(3 * n)), "1,0," + ",".join("1.0" for _ in range(3 * n))]
    path = tmp_path / "take.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(RigInputError) as exc:
        read_marker_csv(path)
    msg = str(exc.value)
    assert "mixes units" in msg and "\n" not in msg and len(msg) < 300, msg
