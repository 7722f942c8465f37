"""Hostile and damaged files the tester listed (issue 17), one test each, outside projects (those are in
tests/test_hostile_files.py): every one is now refused in one sentence naming the file, or read correctly."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from model.errors import RigInputError
from model.livelink import read_livelink_csv
from model.marker_map import load_marker_map
from model.readers import load_obj_folder, load_rig
from model.takes import load_take
from tests.cli_runner import run_cli


def _refused(fn, path, *words):
    with pytest.raises(RigInputError) as err:
        fn(path)
    msg = str(err.value)
    assert str(path.name) in msg and "\n" not in msg and len(msg) < 600, msg
    for w in words:
        assert w in msg, msg
    return msg


@pytest.fixture()
def small_rig(tmp_path, sample_rig):
    """The sample's neutral and two shapes as an OBJ folder, with presets of those shapes."""
    from model.obj_io import write_obj
    folder = tmp_path / "rig"
    folder.mkdir()
    write_obj(folder / "neutral.obj", sample_rig.neutral, sample_rig.face_counts, sample_rig.face_indices)
    for name in ("jawOpen", "mouthSmile_L"):
        write_obj(folder / f"{name}.obj", sample_rig.shape(name), sample_rig.face_counts, sample_rig.face_indices)
    (folder / "presets.json").write_text(json.dumps({"happy": {"mouthSmile_L": 1.0}}))
    return folder


def _edit_line(path, prefix, new_line, nth=0):
    lines = path.read_text().splitlines()
    hits = [i for i, l in enumerate(lines) if l.startswith(prefix)]
    lines[hits[nth]] = new_line
    path.write_text("\n".join(lines) + "\n")


def test_obj_face_index_beyond_2_to_the_63(small_rig):
    _edit_line(small_rig / "neutral.obj", "f ", "f 1 2 9223372036854775809")
    _refused(load_obj_folder, small_rig)


@pytest.mark.parametrize("value", ["1e308", "1e400", "nan", "inf"])
def test_obj_coordinates_that_are_not_lengths(small_rig, value):
    _edit_line(small_rig / "jawOpen.obj", "v ", f"v {value} 0 0", nth=5)
    _refused(load_obj_folder, small_rig)


@pytest.mark.parametrize("weight", ["null", '"1"', "[1]", "1e400", "NaN", "-Infinity", "1e40"])
def test_preset_weights_that_are_not_weights(small_rig, weight):
    (small_rig / "presets.json").write_text('{"happy": {"mouthSmile_L": %s}}' % weight)
    msg = _refused(load_obj_folder, small_rig)
    assert "presets.json" in msg


def test_presets_nested_100000_deep(small_rig):
    (small_rig / "presets.json").write_text("[" * 100_000 + "]" * 100_000)
    _refused(load_obj_folder, small_rig, "nested too deeply")


def test_marker_map_nested_deep_or_with_non_numeric_entries(tmp_path, take_dir):
    deep = tmp_path / "deep.json"
    deep.write_text('{"markers": ' + "[" * 100_000 + "]" * 100_000 + "}")
    _refused(load_marker_map, deep, "nested too deeply")
    good = json.loads((take_dir / "marker_map.json").read_text())
    for bad_entry in ({"face": "12", "bary": [1, 0, 0]}, {"face": 12, "bary": ["a", 0, 0]},
                      {"face": 12, "bary": [0.5]}, [1, 2], 1.5, True):
        doc = dict(good, markers=dict(good["markers"], M00=bad_entry))
        path = tmp_path / "map.json"
        path.write_text(json.dumps(doc))
        _refused(load_marker_map, path, "M00")


def test_gltf_nested_deep_and_of_the_wrong_types(tmp_path):
    deep = tmp_path / "deep.gltf"
    deep.write_text('{"asset": {"version": "2.0"}, "meshes": ' + "[" * 100_000 + "]" * 100_000 + "}")
    _refused(load_rig, deep)
    for doc in ({"asset": {"version": "2.0"}, "meshes": "x"},
                {"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": "0"}}]}]},
                {"asset": {"version": "2.0"}, "accessors": [{"count": -1.5}]},
                {"asset": {"version": "2.0"}, "nodes": [{"matrix": [1, 2]}]}):
        path = tmp_path / "types.gltf"
        path.write_text(json.dumps(doc))
        _refused(load_rig, path)


def test_marker_csv_cell_over_131072_characters(tmp_path):
    path = tmp_path / "take.csv"
    path.write_text("frame,A_X,A_Y,A_Z\n0,1,2," + "3" * 140_000 + "\n")
    _refused(load_take, path)


def test_trc_coordinate_of_1e308_is_refused_not_solved(tmp_path, take_dir):
    src = (take_dir / "take.trc").read_text().splitlines()
    row = src[6].split("\t")
    row[2] = "1e308"
    src[6] = "\t".join(row)
    path = tmp_path / "take.trc"
    path.write_text("\n".join(src) + "\n")
    _refused(load_take, path, "coordinates beyond")
    shutil.copy(take_dir / "marker_map.json", tmp_path / "map.json")
    proc = run_cli("solve", take_dir.parent.parent / "ict-facekit", path, "--map", tmp_path / "map.json",
                   "-o", tmp_path / "w.csv", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "take.trc" in proc.stderr


@pytest.mark.parametrize("value", ["nan", "inf", "1e308"])
def test_live_link_face_weights_that_are_not_weights(tmp_path, llf_csv, value):
    lines = llf_csv.read_text().splitlines()
    cells = lines[5].split(",")
    cells[4] = value
    lines[5] = ",".join(cells)
    path = tmp_path / "llf.csv"
    path.write_text("\n".join(lines) + "\n")
    _refused(read_livelink_csv, path)


def test_live_link_face_cell_over_131072_characters(tmp_path, llf_csv):
    lines = llf_csv.read_text().splitlines()
    lines[3] = lines[3] + "9" * 140_000
    path = tmp_path / "llf.csv"
    path.write_text("\n".join(lines) + "\n")
    _refused(read_livelink_csv, path)


def test_trc_header_counts_that_are_not_counts(tmp_path, take_dir):
    """Found by the long fuzzing run: a NumMarkers of 'inf' raised OverflowError."""
    lines = (take_dir / "take.trc").read_text().splitlines()
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    values[keys.index("NumMarkers")] = "inf"
    lines[2] = "\t".join(values)
    path = tmp_path / "take.trc"
    path.write_text("\n".join(lines) + "\n")
    _refused(load_take, path, "NumMarkers")


@pytest.mark.parametrize("name", ["take.c3d", "take.trc", "take.csv"])
def test_a_fifo_named_as_a_take_is_refused_unread(tmp_path, name):
    import os
    fifo = tmp_path / name
    os.mkfifo(fifo)
    proc = run_cli("take-info", fifo, check=False, timeout=60)   # opening a FIFO for reading would block
    assert proc.returncode == 2 and "not a regular file" in proc.stderr and "Traceback" not in proc.stderr
