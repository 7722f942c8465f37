"""Take readers (C3D, TRC, CSV, Live Link Face), marker maps and rigid alignment, on the real data."""
from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from model.errors import RigInputError
from model.livelink import read_livelink_csv
from model.marker_map import MarkerMap, auto_marker_map, load_marker_map
from model.take_c3d import read_c3d, write_c3d
from model.take_csv import read_marker_csv, write_marker_csv
from model.take_trc import read_trc
from model.takes import MarkerTake, load_take
from solvers.rigid import kabsch, umeyama


@pytest.fixture(scope="module")
def c3d(take_dir):
    return read_c3d(take_dir / "take.c3d")


@pytest.fixture(scope="module")
def trc(take_dir):
    return read_trc(take_dir / "take.trc")


# --- C3D / TRC ---------------------------------------------------------------------------------
def test_c3d_header_and_parameters(c3d):
    assert c3d.positions.shape == (358, 60, 3)
    assert c3d.labels[:3] == ["M00", "M01", "M02"] and len(set(c3d.labels)) == 60
    assert c3d.rate == 60.0 and c3d.units == "mm"


def test_c3d_and_trc_agree(c3d, trc):
    assert trc.labels == c3d.labels
    assert trc.rate == c3d.rate and trc.units == c3d.units
    assert np.array_equal(np.isnan(trc.positions), np.isnan(c3d.positions))
    # TRC prints 4 decimals: equal to print precision
    assert np.nanmax(np.abs(trc.positions - c3d.positions)) < 1e-4 + 1e-9


def test_gaps_are_nan_whole_markers(c3d):
    miss = c3d.missing
    assert 0 < miss.sum() < 0.01 * miss.size  # a few occlusion gaps
    nan = np.isnan(c3d.positions)
    assert np.array_equal(nan.any(axis=2), nan.all(axis=2))  # a missing marker loses x, y and z
    assert np.isfinite(c3d.positions[~miss]).all()


def test_c3d_integer_format_round_trip(c3d, tmp_path):
    path = tmp_path / "int.c3d"
    write_c3d(path, c3d, integer=True, scale=0.01)
    back = read_c3d(path)
    assert back.labels == c3d.labels and back.rate == c3d.rate
    assert np.array_equal(np.isnan(back.positions), np.isnan(c3d.positions))
    assert np.nanmax(np.abs(back.positions - c3d.positions)) <= 0.005 + 1e-5  # half the int16 scale (+ float32 scale rounding)


@pytest.mark.parametrize("n_frames", [40000, 70001])
def test_long_c3d_takes_past_16_bit_frame_counts(c3d, tmp_path, n_frames):
    """Past 32,767 frames POINT:FRAMES is read unsigned; past 65,535 the TRIAL frame range gives the count
    (a 10-minute take at 120 frames/s has 72,000)."""
    reps = -(-n_frames // c3d.n_frames)
    long = MarkerTake(positions=np.tile(c3d.positions[:, :3], (reps, 1, 1))[:n_frames], labels=c3d.labels[:3],
                      rate=120.0, units=c3d.units)
    path = tmp_path / "long.c3d"
    write_c3d(path, long)
    back = read_c3d(path)
    assert back.n_frames == n_frames
    np.testing.assert_array_equal(np.isnan(back.positions), np.isnan(long.positions))
    np.testing.assert_allclose(back.positions[-1], long.positions[-1], atol=1e-5, equal_nan=True)


def test_truncated_c3d_names_the_file(take_dir, tmp_path):
    data = (take_dir / "take.c3d").read_bytes()
    bad = tmp_path / "cut.c3d"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(RigInputError, match="cut.c3d.*truncated"):
        read_c3d(bad)
    head_only = tmp_path / "head.c3d"
    head_only.write_bytes(data[:520])
    with pytest.raises(RigInputError, match="head.c3d"):
        read_c3d(head_only)


def test_empty_and_not_c3d(tmp_path):
    empty = tmp_path / "empty.c3d"
    empty.write_bytes(b"")
    with pytest.raises(RigInputError, match="empty.c3d.*empty"):
        read_c3d(empty)
    junk = tmp_path / "junk.c3d"
    junk.write_bytes(b"hello" * 200)
    with pytest.raises(RigInputError, match="junk.c3d.*not a C3D"):
        read_c3d(junk)


def test_trc_missing_columns(take_dir, tmp_path):
    lines = (take_dir / "take.trc").read_text().splitlines()
    lines[4] = "\t".join(lines[4].split("\t")[:-6])  # drop the last markers' X/Y/Z headers
    bad = tmp_path / "short.trc"
    bad.write_text("\n".join(lines))
    with pytest.raises(RigInputError, match="short.trc.*X/Y/Z columns"):
        read_trc(bad)


def test_trc_unknown_units_and_empty(take_dir, tmp_path):
    lines = (take_dir / "take.trc").read_text().splitlines()
    lines[2] = lines[2].replace("\tmm\t", "\tfurlongs\t")
    bad = tmp_path / "units.trc"
    bad.write_text("\n".join(lines))
    with pytest.raises(RigInputError, match="units.trc.*unknown units 'furlongs'"):
        read_trc(bad)
    empty = tmp_path / "empty.trc"
    empty.write_text("")
    with pytest.raises(RigInputError, match="empty.trc.*empty"):
        read_trc(empty)


def test_a_marker_csv_the_application_writes_reads_back_at_its_rate_and_units(c3d, tmp_path):
    """write_marker_csv wrote the plain ``frame,A_X,...`` layout, which has no place for a rate or units: a take
    written at 30 fps read back at 60 with the 'assumed' warning, and one in cm was read as mm. It writes a Vicon
    Nexus Trajectories section now (rate and units in the file), which every version's reader reads."""
    for rate, units, scale in ((30.0, "mm", 1.0), (29.97002997002997, "cm", 0.1)):
        take = MarkerTake(c3d.positions[:50] * scale, c3d.labels, rate, units=units, first_frame=7)
        path = tmp_path / f"at_{rate:.0f}.csv"
        write_marker_csv(path, take)
        back = load_take(path)
        assert back.rate == rate and back.units == units and back.warnings == [] and back.rate_from_file
        assert back.labels == take.labels and back.first_frame == 7
        assert np.array_equal(np.isnan(back.positions), np.isnan(take.positions))
        assert np.nanmax(np.abs(back.positions - take.positions)) < 1e-6


def test_marker_csv_round_trip_and_dispatch(c3d, tmp_path):
    path = tmp_path / "traj.csv"
    write_marker_csv(path, c3d)
    back = load_take(path)
    assert isinstance(back, MarkerTake) and back.labels == c3d.labels
    assert np.array_equal(np.isnan(back.positions), np.isnan(c3d.positions))
    assert np.nanmax(np.abs(back.positions - c3d.positions)) < 1e-5
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,A_X,A_Y\n0,1,2\n")
    with pytest.raises(RigInputError, match="bad.csv"):
        read_marker_csv(bad)


@pytest.mark.parametrize("cell", ["inf", "-inf", "Infinity", "1e999"])
@pytest.mark.parametrize("kind", ["csv", "trc"])
def test_an_infinite_cell_of_a_text_take_is_refused_not_a_gap(take_dir, tmp_path, kind, cell):
    """``inf`` in a marker CSV (or a TRC) was read as a missing sample, silently: it is no spelling of a gap (an
    empty cell, or NaN, is) and no position either. One sentence naming the file and the line; NaN stays a gap."""
    if kind == "csv":
        text = "frame,A_X,A_Y,A_Z,B_X,B_Y,B_Z\n0,1,2,3,4,5,6\n1,1,2,3,{},5,6\n2,1,2,3,4,5,6\n"
    else:
        lines = (take_dir / "take.trc").read_text().splitlines()
        row = lines[6].split("\t")
        row[3] = "{}"
        lines[6] = "\t".join(row)
        text = "\n".join(lines[:9]) + "\n"
    path = tmp_path / f"take.{kind}"
    path.write_text(text.format("nan"))
    assert np.isnan(load_take(path).positions[1 if kind == "csv" else 0]).any()
    path.write_text(text.format(cell))
    with pytest.raises(RigInputError) as err:
        load_take(path)
    assert str(err.value) == f"{path}: line {3 if kind == 'csv' else 7} has an infinite number ('{cell}'); a " \
                             "missing sample is an empty cell."


@pytest.mark.parametrize("content, why", [
    (bytes(range(256)) * 8, "it holds binary data, not lines of text."),
    (b"PK\x03\x04\x14\x00\x00\x00\x08\x00" + bytes(200), "it holds binary data, not lines of text."),
    ("\u00ff\u00fe".encode("latin-1") * 300, "it holds binary data, not lines of text."),
    (b"Dear reader,\n", None),           # a comma: a CSV of one cell pair, refused by its header as before
    (b"hello world\nthis is just text\nno structure here\n",
     "none of its lines is cells separated by commas or semicolons."),
])
def test_a_csv_file_that_is_no_csv_says_so(tmp_path, content, why):
    """A .csv holding binary data or prose was refused with the marker header's sentence ("after the frame column
    the header needs X, Y and Z columns per marker"), true of no such file: it is not a CSV take."""
    path = tmp_path / "take.csv"
    path.write_bytes(content)
    with pytest.raises(RigInputError) as err:
        load_take(path)
    if why is None:
        assert "is not a CSV take" not in str(err.value)
    else:
        assert str(err.value) == f"{path}: is not a CSV take: {why}"


# --- Live Link Face ------------------------------------------------------------------------------
def test_livelink_maps_to_ict(llf_csv, ict_rig):
    take = read_livelink_csv(llf_csv, ict_rig.shape_names)
    assert take.weights.shape == (328, ict_rig.n_shapes) and take.names == ict_rig.shape_names
    assert take.rate == 60.0 and len(take.timecodes) == 328
    assert take.unmapped == ["TongueOut"]
    raw = read_livelink_csv(llf_csv)
    col = {n: raw.weights[:, i] for i, n in enumerate(raw.names)}
    k = ict_rig.shape_names.index
    assert np.array_equal(take.weights[:, k("eyeBlink_L")], col["EyeBlinkLeft"])
    assert np.array_equal(take.weights[:, k("mouthSmile_R")], col["MouthSmileRight"])
    for side in ("_L", "_R"):  # one ARKit column drives both ICT sides
        assert np.array_equal(take.weights[:, k("browInnerUp" + side)], col["BrowInnerUp"])
        assert np.array_equal(take.weights[:, k("cheekPuff" + side)], col["CheekPuff"])
    assert not take.weights[:, k("cheekRaiser_L")].any()  # no ARKit column drives it
    assert {"HeadYaw", "LeftEyePitch"} <= set(take.channels)


def test_livelink_on_a_smaller_rig_and_edited_mapping(llf_csv):
    names = ["jawOpen", "eyeBlink_L", "mouthSmile"]
    take = read_livelink_csv(llf_csv, names, mapping={"MouthSmileLeft": "mouthSmile"})
    assert take.weights.shape == (328, 3)
    assert "EyeBlinkRight" in take.unmapped and "MouthSmileLeft" not in take.unmapped
    raw = read_livelink_csv(llf_csv)
    assert np.array_equal(take.weights[:, 2], raw.weights[:, raw.names.index("MouthSmileLeft")])
    with pytest.raises(RigInputError, match="does not have"):
        read_livelink_csv(llf_csv, names, mapping={"JawOpen": "nope"})


def test_livelink_bad_input(tmp_path):
    bad = tmp_path / "bad_llf.csv"
    bad.write_text("Timecode,BlendShapeCount,JawOpen\n00:00:00:01.000,1,0.5,9\n")
    with pytest.raises(RigInputError, match="bad_llf.csv.*columns"):
        read_livelink_csv(bad)


# --- marker maps ---------------------------------------------------------------------------------
def test_marker_map_binding_and_validation(take_dir, ict_rig, c3d):
    mm = load_marker_map(take_dir / "marker_map.json")
    assert mm.rig_units == "cm" and mm.take_units == "mm" and len(mm.labels) == 60
    B = mm.binding(ict_rig)
    verts = [mm.markers[label] for label in mm.labels]
    assert np.allclose(B @ ict_rig.neutral, ict_rig.neutral[verts])
    assert mm.validate(ict_rig, c3d) == []
    bad = MarkerMap(markers={"M00": ict_rig.n_vertices + 5}, source="far.json")
    with pytest.raises(RigInputError, match="far.json.*vertex 26724.*26719 vertices"):
        bad.binding(ict_rig)
    alien = MarkerMap(markers={"X1": 3, "X2": 4}, source="alien.json")
    with pytest.raises(RigInputError, match="alien.json.*none of its 2 marker labels"):
        alien.match(c3d)
    partial = MarkerMap(markers={**{label: mm.markers[label] for label in mm.labels}, "EXTRA": 5})
    assert any("EXTRA" in w for w in partial.validate(ict_rig, c3d))


def test_marker_map_bary_and_file_errors(ict_rig, tmp_path):
    corners = ict_rig.polygons()[100]
    mm = MarkerMap(markers={"A": {"face": 100, "bary": [0.2, 0.3, 0.5]}})
    p = (mm.binding(ict_rig) @ ict_rig.neutral)[0]
    assert np.allclose(p, ict_rig.neutral[corners[:3]].T @ [0.2, 0.3, 0.5])
    path = tmp_path / "m.json"
    mm.save(path)
    assert load_marker_map(path).markers == mm.markers
    empty = tmp_path / "empty.json"
    empty.write_text("")
    with pytest.raises(RigInputError, match="empty.json.*empty"):
        load_marker_map(empty)
    (tmp_path / "x.json").write_text(json.dumps({"markers": {"A": 1}, "rig_units": "parsecs"}))
    with pytest.raises(RigInputError, match="x.json.*unknown units"):
        load_marker_map(tmp_path / "x.json")


def test_auto_marker_map_recovers_the_given_map(take_dir, ict_rig, c3d):
    given = load_marker_map(take_dir / "marker_map.json")
    auto, info = auto_marker_map(ict_rig, c3d)
    exact = sum(auto.markers[label] == given.markers[label] for label in c3d.labels)
    dist = np.array([np.linalg.norm(ict_rig.neutral[auto.markers[label]] - ict_rig.neutral[given.markers[label]])
                     for label in c3d.labels])
    assert exact >= 55, exact
    assert dist.max() < 0.1  # cm: every marker within 1 mm of the given vertex
    assert abs(info["scale"] - 1.0) < 0.01 and info["rms"] < 0.05


# --- rigid ---------------------------------------------------------------------------------------
def test_umeyama_recovers_similarity_batched_and_weighted():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(4, 30, 3))
    ang = rng.uniform(-1, 1, size=(4, 3))
    from scipy.spatial.transform import Rotation
    R = Rotation.from_rotvec(ang).as_matrix()
    t = rng.normal(size=(4, 3))
    Y = 0.1 * np.einsum("fij,fnj->fni", R, X) + t[:, None]
    Y[:, :5] += 10.0  # outliers, given zero weight
    w = np.ones((4, 30))
    w[:, :5] = 0.0
    s2, R2, t2 = umeyama(X, Y, w, scale=True)
    assert np.allclose(s2, 0.1) and np.allclose(R2, R) and np.allclose(t2, t)
    R3, t3 = kabsch(X[0, 5:], np.einsum("ij,nj->ni", R[0], X[0, 5:]) + t[0])
    assert np.allclose(R3, R[0]) and np.allclose(t3, t[0]) and np.isclose(np.linalg.det(R3), 1.0)


# --- marker CSV layouts of the common exporters ---------------------------------------------------
VICON_NEXUS_CSV = """Devices
1000
,,Force Plate::Force,,
Frame,Sub Frame,Fx,Fy,Fz
,,N,N,N
1,0,0.1,0.2,0.3

Trajectories
100
,,Actor:LASI,,,Actor:RASI,,,Actor:LASI,,
Frame,Sub Frame,X,Y,Z,X,Y,Z,X,Y,Z
,,mm,mm,mm,mm,mm,mm,mm,mm,mm
1,0,-391.888,-6180.01,1734.43,-378.647,-6190.14,1713.82,1,2,3
2,0,-391.978,-6180.03,1734.43,,,,4,5,6
3,0,-392.012,-6180.04,1734.48,-378.718,-6189.96,1714.06,7,8,9

Model Outputs
100
"""

MOTIVE_CSV = """Format Version,1.23,Take Name,Take 2024-03-01 10.00.00 AM,Capture Frame Rate,240.000000,Export Frame Rate,120.000000,Capture Start Time,2024-03-01 10.00.00.000 AM,Total Frames in Take,3,Total Exported Frames,3,Rotation Type,Quaternion,Length Units,Meters,Coordinate Space,Global

,Type,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Marker,Marker,Marker,Marker,Marker,Marker
,Name,Head,Head,Head,Head,Head,Head,Head,Face:Brow_L,Face:Brow_L,Face:Brow_L,Face:Chin,Face:Chin,Face:Chin
,ID,1,1,1,1,1,1,1,2,2,2,3,3,3
,,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,Position,Position,Position,Position,Position,Position
Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,X,Y,Z,X,Y,Z
0,0.000000,0,0,0,1,0.1,1.6,0.2,0.031,1.702,0.090,0.002,1.581,0.101
1,0.008333,0,0,0,1,0.1,1.6,0.2,0.032,1.703,0.091,,,
2,0.016667,0,0,0,1,0.1,1.6,0.2,0.033,1.704,0.092,0.004,1.583,0.103
"""


def test_vicon_nexus_marker_csv(tmp_path):
    path = tmp_path / "nexus.csv"
    path.write_text(VICON_NEXUS_CSV)
    take = load_take(path)
    assert take.rate == 100.0 and take.units == "mm" and take.first_frame == 1
    # the subject prefix goes, the repeated LASI is kept apart and said aloud; the Devices section is not markers
    assert take.labels == ["LASI", "RASI", "LASI_2"]
    assert any("LASI -> LASI_2" in w for w in take.warnings)
    assert take.positions.shape == (3, 3, 3)
    np.testing.assert_allclose(take.positions[0, 0], [-391.888, -6180.01, 1734.43])
    np.testing.assert_allclose(take.positions[2, 2], [7, 8, 9])
    assert np.isnan(take.positions[1, 1]).all() and take.missing.sum() == 1


def test_optitrack_motive_marker_csv(tmp_path):
    path = tmp_path / "motive.csv"
    path.write_text(MOTIVE_CSV)
    take = load_take(path)
    # the export rate, metres, and only the measured markers (the rigid body's pose is not a marker)
    assert take.rate == 120.0 and take.units == "m" and take.first_frame == 0
    assert take.labels == ["Brow_L", "Chin"] and take.warnings == []
    np.testing.assert_allclose(take.positions[:, 0, 1], [1.702, 1.703, 1.704])
    np.testing.assert_allclose(take.positions[2, 1], [0.004, 1.583, 0.103])
    assert np.isnan(take.positions[1, 1]).all() and take.missing.sum() == 1
    bad = tmp_path / "motive_bad.csv"
    bad.write_text(MOTIVE_CSV.replace("Length Units,Meters", "Length Units,Furlongs"))
    with pytest.raises(RigInputError, match="motive_bad.csv.*unknown units 'Furlongs'"):
        load_take(bad)
    cut = tmp_path / "motive_cut.csv"
    cut.write_text("\n".join(MOTIVE_CSV.splitlines()[:6]))
    with pytest.raises(RigInputError, match="motive_cut.csv.*'Frame, Time \\(Seconds\\)'"):
        load_take(cut)


# --- Live Link Face timing -----------------------------------------------------------------------
def _llf_file(path, codes, jaw):
    lines = ["Timecode,BlendShapeCount,JawOpen,EyeBlinkLeft,HeadYaw"]
    lines += [f"{c},2,{j:.4f},0.1,0.0" for c, j in zip(codes, jaw)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _codes(frames, tc_rate, start=(14, 2, 59), sub=0.0):
    h, m, s = start
    out = []
    for f in frames:   # f counts timecode frames from the start
        sec, ff = divmod(f, tc_rate)
        total = h * 3600 + m * 60 + s + sec
        out.append(f"{total // 3600:02d}:{total // 60 % 60:02d}:{total % 60:02d}:{int(ff):02d}.{int(sub * 1000):03d}")
    return out


def test_livelink_30_fps_plays_in_real_time(tmp_path):
    """A recording at 30 fps (FF 00..29) is 30 fps: 90 rows last 3 s, not 1.5 s as at a fixed 60."""
    jaw = np.linspace(0, 1, 90)
    take = read_livelink_csv(_llf_file(tmp_path / "llf30.csv", _codes(range(90), 30), jaw))
    assert take.rate == 30.0 and take.n_frames == 90 and take.warnings == []
    assert take.times()[-1] == pytest.approx(89 / 30)
    np.testing.assert_allclose(take.weights[:, take.names.index("JawOpen")], np.round(jaw, 4))
    take60 = read_livelink_csv(_llf_file(tmp_path / "llf60.csv", _codes(range(150), 60, sub=0.867), np.zeros(150)))
    assert take60.rate == 60.0 and take60.n_frames == 150


def test_livelink_dropped_frames_keep_time(tmp_path):
    """Rows 10-12 and 40 were dropped by the phone: the take still has a frame every 1/30 s, the frames after
    a gap sit at their timecodes' times, and the dropped ones are interpolated (and said to be)."""
    kept = [f for f in range(60) if f not in (10, 11, 12, 40)]
    jaw = np.array(kept) / 100.0   # a ramp: interpolation across a gap gives the ramp back
    take = read_livelink_csv(_llf_file(tmp_path / "drop.csv", _codes(kept, 30), jaw), ["jawOpen", "eyeBlink_L"])
    assert take.rate == 30.0 and take.n_frames == 60
    np.testing.assert_allclose(take.weights[:, 0], np.arange(60) / 100.0, atol=1e-12)
    assert take.filled.tolist() == [f in (10, 11, 12, 40) for f in range(60)]
    assert take.timecodes[13] == _codes([13], 30)[0] and take.timecodes[11] == ""
    assert len(take.warnings) == 1 and "4 dropped frames" in take.warnings[0] and "drop.csv" in take.warnings[0]
    # 60 fps recorded under a 30 fps timecode: half-frame steps
    half = [c.replace(".000", f".{500 * (k % 2):03d}") for k, c in enumerate(_codes([k // 2 for k in range(130)], 30))]
    take = read_livelink_csv(_llf_file(tmp_path / "half.csv", half, np.zeros(130)))
    assert take.rate == 60.0 and take.n_frames == 130 and take.warnings == []


def test_livelink_timecodes_that_go_back_or_are_not_timecodes(tmp_path):
    codes = _codes(range(10), 30)
    codes[5] = codes[3]
    with pytest.raises(RigInputError, match="back.csv.*row 7.*does not come after row 6"):
        read_livelink_csv(_llf_file(tmp_path / "back.csv", codes, np.zeros(10)))
    codes = _codes(range(10), 30)
    codes[2] = "soon"
    with pytest.raises(RigInputError, match="words.csv.*row 4.*'soon'"):
        read_livelink_csv(_llf_file(tmp_path / "words.csv", codes, np.zeros(10)))


# --- C3D files that bend the standard (built here, one bend at a time) ----------------------------
def _bent_c3d(path, pos, labels, *, units=(b"mm", (2,)), scale_dims=(), rate_dims=(), analog_used=0,
              analog_ratio=1, header_analog=None, cut=0, point=None, data_start=None):
    """A float C3D of ``pos`` with the given parameter shapes; analog channels hold noise. ``point`` replaces
    POINT parameters by name with (type, dims, payload); ``data_start`` overrides POINT:DATA_START."""
    import struct
    from model.take_c3d import BLOCK, _group, _param
    F, M, _ = pos.shape
    width = max(len(s) for s in labels)
    point = point or {}

    def pt(name, dtype, dims, payload):
        return _param(1, name, *point.get(name, (dtype, dims, payload)))
    plist = [_group(1, "POINT"), pt("USED", 2, (), struct.pack("<h", M)),
             pt("FRAMES", 2, (), struct.pack("<H", F)),
             pt("SCALE", 4, scale_dims, struct.pack("<f", -0.1)),
             pt("RATE", 4, rate_dims, struct.pack("<f", 60.0)),
             _param(1, "UNITS", -1, units[1], units[0]),
             _param(1, "LABELS", -1, (width, M), b"".join(s.encode().ljust(width) for s in labels)),
             _group(2, "ANALOG"), _param(2, "USED", 2, (), struct.pack("<h", analog_used)),
             _param(2, "RATE", 4, (), struct.pack("<f", 60.0 * analog_ratio))]
    body = b"".join(plist)
    n_blocks = (4 + len(body) + 16 + BLOCK - 1) // BLOCK
    body += _param(1, "DATA_START", 2, (), struct.pack("<h", 2 + n_blocks if data_start is None else data_start)) \
        + b"\x00\x00"
    psec = (bytes([1, 80, n_blocks, 84]) + body).ljust(n_blocks * BLOCK, b"\x00")
    words = analog_used * analog_ratio
    header = np.zeros(256, dtype="<u2")
    header[0], header[1], header[2], header[3], header[4] = 0x5002, M, words if header_analog is None else header_analog, 1, F
    header[8] = 2 + n_blocks
    hb = bytearray(header.tobytes())
    hb[12:16], hb[20:24] = struct.pack("<f", -0.1), struct.pack("<f", 60.0)
    frames = np.zeros((F, 4 * M + words), dtype="<f4")
    frames[:, :4 * M] = np.concatenate([np.nan_to_num(pos), np.where(np.isnan(pos).any(2), -1.0, 0.0)[..., None]],
                                       axis=2).reshape(F, 4 * M)
    frames[:, 4 * M:] = np.random.default_rng(0).uniform(-5, 5, size=(F, words))
    data = bytes(hb) + psec + frames.tobytes()
    path.write_bytes(data[:len(data) - cut])
    return path


@pytest.fixture(scope="module")
def bent_positions():
    rng = np.random.default_rng(7)
    F, M = 50, 4
    pos = np.cumsum(rng.normal(scale=0.5, size=(F, M, 3)), axis=0) + rng.uniform(-500, 500, size=(1, M, 3))
    pos[10:14, 2] = np.nan
    return pos


def test_c3d_analog_samples_only_in_the_analog_group(bent_positions, tmp_path):
    """The header says no analog samples follow a frame; ANALOG:USED 3 at twice the frame rate says 6 do."""
    path = _bent_c3d(tmp_path / "analog.c3d", bent_positions, ["A", "B", "C", "D"], analog_used=3, analog_ratio=2,
                     header_analog=0)
    take = read_c3d(path)
    assert take.n_frames == 50 and take.warnings == []
    np.testing.assert_allclose(take.positions, bent_positions.astype(np.float32), equal_nan=True)


def test_c3d_parameters_as_arrays_nul_padded_and_abbreviated(bent_positions, tmp_path):
    path = _bent_c3d(tmp_path / "arrays.c3d", bent_positions, ["A", "B", "C", "D"], scale_dims=(1,), rate_dims=(1,),
                     units=(b"mete\x00\x00", (6, 1)))
    take = read_c3d(path)
    assert take.units == "m" and take.rate == 60.0 and take.warnings == []
    np.testing.assert_allclose(take.positions, bent_positions.astype(np.float32), equal_nan=True)
    bad = _bent_c3d(tmp_path / "inches.c3d", bent_positions, ["A", "B", "C", "D"], units=(b"in", (2,)))
    with pytest.raises(RigInputError, match="inches.c3d.*unknown units 'in' in POINT:UNITS"):
        read_c3d(bad)


def test_c3d_duplicate_labels_and_a_short_file(bent_positions, tmp_path):
    path = _bent_c3d(tmp_path / "dup.c3d", bent_positions, ["A", "B", "A", "D"], cut=10)
    take = read_c3d(path)
    assert take.labels == ["A", "B", "A_2", "D"] and take.n_frames == 49
    said = " ".join(take.warnings)
    assert len(take.warnings) == 2 and "1 repeated marker label was made unique (A -> A_2)" in said
    assert "50 frames declared but 49 whole frames present" in said
    np.testing.assert_allclose(take.positions, bent_positions[:49].astype(np.float32), equal_nan=True)
    with pytest.raises(RigInputError, match="half.c3d.*truncated: 50 frames declared but only 19 complete"):
        read_c3d(_bent_c3d(tmp_path / "half.c3d", bent_positions, ["A", "B", "C", "D"], cut=30 * 4 * 4 * 4 + 8))


def test_c3d_damaged_parameters_never_crash_or_loop(take_dir, tmp_path):
    """A next-entry offset pointing backwards ends the walk (with a warning); random damage to the header
    and the parameter section gives a reading or one sentence, never a traceback or a hang."""
    import struct
    data = bytearray((take_dir / "take.c3d").read_bytes())
    start = (data[0] - 1) * 512 + 4
    name_len = abs(struct.unpack_from("b", data, start)[0])
    struct.pack_into("<h", data, start + 2 + name_len, -6)   # the first entry points back before itself
    back = tmp_path / "back.c3d"
    back.write_bytes(bytes(data))
    take = read_c3d(back)   # the header still tells the layout
    assert take.n_frames == 358 and any("points backwards" in w for w in take.warnings)
    rng = np.random.default_rng(16)
    clean = (take_dir / "take.c3d").read_bytes()
    for trial in range(150):
        damaged = bytearray(clean)
        for at in rng.integers(0, 3 * 512, size=rng.integers(1, 12)):
            damaged[at] = rng.integers(0, 256)
        path = tmp_path / f"damaged{trial}.c3d"
        path.write_bytes(bytes(damaged))
        try:
            read_c3d(path)
        except RigInputError as exc:
            assert path.name in str(exc) and "\n" not in str(exc)


@pytest.mark.parametrize("name,param", [
    ("scale_inf", ("SCALE", (4, (), struct.pack("<f", float("inf"))))),
    ("rate_1e38", ("RATE", (4, (), struct.pack("<f", 1e38)))),
    ("used_negative", ("USED", (2, (), struct.pack("<h", -32768)))),
    ("frames_array", ("FRAMES", (2, (3,), struct.pack("<3H", 50, 7, 9)))),
])
def test_c3d_parameters_no_file_holds(bent_positions, tmp_path, name, param):
    """The tester's C3D cases (issue 17): SCALE=inf, RATE=1e38, USED=-32768, FRAMES as an array. Each is read
    from what the rest of the file proves (header, file size) or refused in one sentence, never garbage."""
    key, value = param
    path = _bent_c3d(tmp_path / f"{name}.c3d", bent_positions, ["A", "B", "C", "D"], point={key: value})
    try:
        take = read_c3d(path)
    except RigInputError as exc:
        assert path.name in str(exc) and "\n" not in str(exc)
        return
    assert take.n_frames == 50 and take.labels == ["A", "B", "C", "D"] and 0 < take.rate <= 100_000
    np.testing.assert_allclose(take.positions, bent_positions.astype(np.float32), equal_nan=True)


@pytest.mark.parametrize("data_start", [0, -5])
def test_c3d_data_start_at_or_below_zero(bent_positions, tmp_path, data_start):
    path = _bent_c3d(tmp_path / "start.c3d", bent_positions, ["A", "B", "C", "D"], data_start=data_start)
    try:
        take = read_c3d(path)
    except RigInputError as exc:
        assert path.name in str(exc) and "\n" not in str(exc)
        return
    np.testing.assert_allclose(take.positions, bent_positions.astype(np.float32), equal_nan=True)


@pytest.mark.parametrize("integer", [False, True])
def test_c3d_gaps_written_as_the_origin_are_read_as_missing(tmp_path, integer):
    """The actor take with its gaps written as (0, 0, 0) and a residual of 0, as many capture systems write them:
    read back with the same gaps (NaN), with a warning, not as markers at the origin (read as positions, they made
    a solve of this take twice as far from the true weights)."""
    from tests.conftest import DATA, require_data
    take = read_c3d(require_data(DATA / "mocap" / "actor_take" / "take.c3d"))
    gaps = np.isnan(take.positions).any(axis=2)
    assert 0 < gaps.sum() < gaps.size
    zeros = MarkerTake(positions=np.nan_to_num(take.positions, nan=0.0), labels=take.labels, rate=take.rate,
                       units=take.units, source="zeros")
    write_c3d(tmp_path / "zeros.c3d", zeros, integer=integer)
    back = read_c3d(tmp_path / "zeros.c3d")
    np.testing.assert_array_equal(np.isnan(back.positions).any(axis=2), gaps)
    np.testing.assert_allclose(back.positions[~gaps], take.positions[~gaps], atol=0.01 if integer else 1e-4)
    assert [w for w in back.warnings if "exactly (0, 0, 0)" in w] == \
        [f"{tmp_path / 'zeros.c3d'}: {int(gaps.sum())} samples at exactly (0, 0, 0) were read as missing, the way many "
         "writers mark a gap."]


def test_a_c3d_whose_markers_spread_over_kilometres_is_refused(c3d, tmp_path):
    """Coordinates under the ±1e9 a take may hold loaded however absurd: an integer C3D whose POINT:SCALE (and the
    header's) was damaged from 0.01 to 100 read the shared face take kilometres wide, a float file with one sample 5 km
    off likewise. No capture volume is a kilometre across (the 77 real files span at most 8.7 m): refused in one
    sentence naming the file, the spread and the scale."""
    good = tmp_path / "int.c3d"
    write_c3d(good, c3d, integer=True, scale=0.01)
    raw = good.read_bytes()
    assert raw.count(struct.pack("<f", 0.01)) == 2            # the header's scale and POINT:SCALE
    damaged = tmp_path / "damaged.c3d"
    damaged.write_bytes(raw.replace(struct.pack("<f", 0.01), struct.pack("<f", 100.0)))
    with pytest.raises(RigInputError) as err:
        read_c3d(damaged)
    said = str(err.value)
    assert said.startswith(f"{damaged}: its markers spread over ") and "POINT:SCALE 100" in said and " km:" in said
    far = c3d.positions.copy()
    far[10, 3] = [5e6, 0.0, 0.0]          # 5 km from the face, in mm
    write_c3d(tmp_path / "far.c3d", MarkerTake(far, c3d.labels, c3d.rate, units="mm"))
    with pytest.raises(RigInputError, match=r"far\.c3d: its markers spread over 5e\+06 mm \(its float points\), 5 km"):
        read_c3d(tmp_path / "far.c3d")
    write_c3d(tmp_path / "near.c3d", MarkerTake(far / 10.0, c3d.labels, c3d.rate, units="mm"))   # 500 m: read
    assert read_c3d(tmp_path / "near.c3d").n_frames == c3d.n_frames
