"""Every file other tools wrote (../shared/data/thirdparty, see its README) is read as independent readers
read it, or refused in one sentence naming the file and the problem: no traceback, no silent difference.

C3D: the reference is ezc3d; where ezc3d fails or misreads a file (listed below with the reason, checked by
the test), py-c3d; where both fail, a reference library reads a copy with the one defect repaired. TRC: the
reference is a plain pandas reading of the table. The counts (read exactly / with a warning / refused) are
the README's (Formats).
"""
from __future__ import annotations

import re
import struct
import warnings as pywarnings

import numpy as np
import pytest

from model.errors import RigInputError
from model.take_c3d import read_c3d
from model.take_trc import read_trc
from tests.conftest import DATA, require_data

ezc3d = pytest.importorskip("ezc3d")
pyc3d = pytest.importorskip("c3d")
pd = pytest.importorskip("pandas")

THIRDPARTY = DATA / "thirdparty"
C3D_FILES = sorted(p.name for p in (THIRDPARTY / "c3d").glob("*")) if (THIRDPARTY / "c3d").is_dir() else []
TRC_FILES = sorted(p.name for p in (THIRDPARTY / "trc").glob("*.trc")) if (THIRDPARTY / "trc").is_dir() else []

# ezc3d 1.7 refuses these; it is not even asked, since on the non-standard ones it allocates about 12 GB
# before it gives up. py-c3d is the reference.
EZC3D_REFUSES = {
    **{name: "SGI/MIPS processor type" for name in ("Sample01__Eb015si.c3d", "Sample01__Eb015sr.c3d",
                                                    "Sample02__sgi_int.c3d", "Sample02__sgi_real.c3d")},
    "Sample13__Dance.c3d": "an ANALOG:OFFSET parameter that is not an integer",
    "Sample22__BKINtechnologies.c3d": "a parameter section it calls non-standard",
}
# ezc3d reads these without an error but wrongly; py-c3d reads them as we do.
EZC3D_MISREADS = {
    "Sample20__phasespace_sample.c3d": "an empty parameter section: ezc3d reads 0 points, the header says 40",
    "Sample28__dynamic.C3D": "no ANALOG:RATE: ezc3d reads the 6 analog words after each frame as point data",
    "Sample28__standing.C3D": "no ANALOG:RATE: ezc3d reads the 6 analog words after each frame as point data",
}
# Neither library reads these as they are (ezc3d crashes the process on Sample18): the reference reads a copy
# with the defect repaired: (byte offset, bytes expected there, replacement, library, what it repairs).
REPAIRED = {
    "Sample27__kyowadengyo.c3d": (566, b"\x0c\x00", b"\x0b\x00", "ezc3d",
                                  "POINT:USED says 12 points; the header's 11 fill the file exactly"),
    "Sample11__evart.c3d": (3074, b"\x7a\x45\x00\x00", b"\x7f\x45\x00\x00", "ezc3d",
                            "ANALOG:RATE 1000 is not a whole multiple of 60 (ezc3d takes 16 samples per frame and "
                            "reads analog data as points from frame 2 on); the header's 17 fill the file "
                            "exactly, and the repair sets ANALOG:RATE to 17 x 60 = 1020 (a DEC float)"),
    "Sample18__bad_parameter_section.c3d": (5572, b"\xc7\x00", b"\x00\x00", "py-c3d",
                                            "the last parameter (EVENT:LABELS) points past the section into the "
                                            "frames; the repair makes it the last entry"),
    "Sample06__MACsample.c3d": (2979, b"\x3c\xb0\x77\x13", b"\x3d\x61\xbe\xd7", "py-c3d",
                                "POINT:SCALE 0.0215 (a big-endian float) disagrees with the header's 0.0551 and "
                                "py-c3d refuses the file; the repair writes the header's scale into POINT:SCALE"),
}
# Refused, with the reason the sentence must give.
REFUSED = {
    "Sample00__Cometa_Systems__EMG_Data_Cometa.c3d": "no 3D points",
    "Sample30__emgwl.c3d": "no 3D points",
}
# Vicon Nexus / Plug-in Gait and pyCGM2 store model outputs (joint angles, forces, moments, powers, ...) as points and
# list their labels in these POINT parameters: not markers.
MODEL_OUTPUTS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")
# What the README's Formats table reports.
C3D_COUNTS = {"exact": 41, "warning": 34, "refused": 2}
TRC_COUNTS = {"exact": 11, "warning": 1, "refused": 0}


def _ezc3d_reading(path) -> dict:
    c = ezc3d.c3d(str(path))
    point = c["parameters"]["POINT"]
    labels, k = list(point["LABELS"]["value"]) if "LABELS" in point else [], 2
    while f"LABELS{k}" in point:
        labels += list(point[f"LABELS{k}"]["value"])
        k += 1
    outputs = {s for g in MODEL_OUTPUTS for s in point.get(g, {}).get("value", [])}
    return {"positions": c["data"]["points"][:3].transpose(2, 1, 0), "labels": labels, "outputs": outputs,
            "rate": float(point["RATE"]["value"][0]), "units": list(point.get("UNITS", {}).get("value", []))}


def _pyc3d_reading(path) -> dict:
    with pywarnings.catch_warnings(), open(path, "rb") as handle:
        pywarnings.simplefilter("ignore")
        r = pyc3d.Reader(handle)
        frames = [p for _, p, _ in r.read_frames()]
        pos = np.stack([p[:, :3] for p in frames]).astype(np.float64)
        pos[np.stack([p[:, 3] for p in frames]) < 0] = np.nan
        units = r.get("POINT:UNITS")
        labels = r.get("POINT:LABELS")
        outputs = {s.strip() for g in MODEL_OUTPUTS if r.get(f"POINT:{g}") for s in r.get(f"POINT:{g}").string_array}
        return {"positions": pos, "labels": [s.strip() for s in labels.string_array] if labels else [],
                "outputs": outputs, "rate": float(r.point_rate),
                "units": [units.string_value.replace("\x00", " ").strip()] if units else []}


def _reference(name: str, tmp_path) -> dict:
    path = THIRDPARTY / "c3d" / name
    if name in REPAIRED:
        offset, was, now, library, _ = REPAIRED[name]
        data = bytearray(path.read_bytes())
        assert data[offset:offset + len(was)] == was, f"{name}: the repaired bytes are not what the test expects"
        data[offset:offset + len(was)] = now
        path = tmp_path / name
        path.write_bytes(bytes(data))
        return _ezc3d_reading(path) if library == "ezc3d" else _pyc3d_reading(path)
    if name in EZC3D_MISREADS or name in EZC3D_REFUSES:
        return _pyc3d_reading(path)
    try:
        return _ezc3d_reading(path)
    except Exception:   # ezc3d refuses it (SGI/MIPS files, non-standard parameter sections)
        return _pyc3d_reading(path)


def _check_one_sentence(message: str, name: str) -> None:
    assert name in message and "\n" not in message and message.endswith(".")
    assert "Traceback" not in message


_CLASSIFIED: dict[str, str] = {}   # name -> exact / warning / refused, once per session


def _classify_c3d(name: str, tmp_path) -> str:
    if name not in _CLASSIFIED:
        _CLASSIFIED[name] = _check_c3d(name, tmp_path)
    return _CLASSIFIED[name]


def _check_c3d(name: str, tmp_path) -> str:
    path = THIRDPARTY / "c3d" / name
    try:
        take = read_c3d(path)
    except RigInputError as exc:
        assert name in REFUSED, f"{name} was refused: {exc}"
        _check_one_sentence(str(exc), name)
        assert re.search(REFUSED[name], str(exc)), str(exc)
        return "refused"
    assert name not in REFUSED, f"{name} should be refused ({REFUSED.get(name)})"
    for w in take.warnings:
        _check_one_sentence(w, name)
    ref = _reference(name, tmp_path)
    # model outputs (the labels POINT:ANGLES, FORCES, ... list) are left out, with a warning; markers keep their order
    markers = [i for i in range(ref["positions"].shape[1])
               if i >= len(ref["labels"]) or ref["labels"][i] not in ref["outputs"]]
    left_out = ref["positions"].shape[1] - len(markers)
    assert len(take.model_outputs) == left_out, name
    assert bool(left_out) == any("are model outputs listed in POINT:" in w for w in take.warnings), name
    pos = ref["positions"][:, markers].astype(np.float64)
    origin = (pos == 0).all(axis=2)             # gaps as many writers mark them: read as missing, with a warning
    pos[origin] = np.nan
    assert origin.any() == any("exactly (0, 0, 0)" in w for w in take.warnings), name
    assert take.positions.shape == pos.shape, (name, take.positions.shape, pos.shape)
    # gaps: the same samples missing
    np.testing.assert_array_equal(np.isnan(take.positions).any(axis=2), np.isnan(pos).any(axis=2), err_msg=name)
    if np.isfinite(pos).any():   # values, to float32 precision of the file's largest coordinate
        tol = 1e-6 * np.nanmax(np.abs(pos)) + 1e-9
        np.testing.assert_allclose(take.positions, pos, atol=tol, rtol=0, equal_nan=True, err_msg=name)
    assert take.rate == pytest.approx(ref["rate"], rel=1e-6), name
    if ref["units"] and ref["units"][0].strip():
        assert take.units == {"mm": "mm", "m": "m", "cm": "cm"}[ref["units"][0].strip()], name
    else:   # nothing in the file: millimetres, the C3D default, said aloud
        assert take.units == "mm" and any("POINT:UNITS" in w for w in take.warnings), name
    # labels: the file's, a repeated one made unique (LABEL_2, ...) with a warning; unnamed points named M00...
    labels = [ref["labels"][i] for i in markers if i < len(ref["labels"])][:take.n_markers]
    assert len(set(take.labels)) == take.n_markers
    for i, (ours, theirs) in enumerate(zip(take.labels, labels)):
        assert ours == theirs or (labels.index(theirs) < i and ours.startswith(theirs + "_")), (name, ours, theirs)
    if len(set(labels)) < len(labels):
        assert any("made unique" in w for w in take.warnings), name
    if len(labels) < take.n_markers:
        assert take.labels[len(labels):] == [f"M{i:02d}" for i in range(len(labels), take.n_markers)]
        assert any("POINT:LABELS names" in w for w in take.warnings), name
    return "warning" if take.warnings else "exact"


def test_thirdparty_corpus_is_there():
    require_data(THIRDPARTY / "c3d")
    require_data(THIRDPARTY / "trc")
    assert len(C3D_FILES) == sum(C3D_COUNTS.values()) and len(TRC_FILES) == sum(TRC_COUNTS.values())


@pytest.mark.parametrize("name", C3D_FILES)
def test_thirdparty_c3d(name, tmp_path):
    _classify_c3d(name, tmp_path)


def test_thirdparty_c3d_counts(tmp_path):
    require_data(THIRDPARTY / "c3d")
    counts = {"exact": 0, "warning": 0, "refused": 0}
    for name in C3D_FILES:
        counts[_classify_c3d(name, tmp_path)] += 1
    assert counts == C3D_COUNTS


def test_a_c3d_whose_two_scales_disagree_is_read_with_the_header_scale():
    """Sample06__MACsample.c3d (Motion Analysis, SGI/MIPS, int16 points): POINT:SCALE says 0.0215, the header 0.0551.
    It was refused; it is read with the header's scale, as BTK (Mokka) reads it, with a warning. Decoded here by
    hand (big-endian words from block 8, 33 points and 272 analog words a frame) at the header's scale, and so
    read the figure is an adult walking: shoulders 1.46 m up, heel to toe 0.19 m, shoulders 0.40 m apart, a
    stride of 1.3 m in 1.08 s. POINT:SCALE would make it a 0.57 m tall figure taking 0.5 m strides at that pace."""
    path = require_data(THIRDPARTY / "c3d" / "Sample06__MACsample.c3d")
    data = path.read_bytes()
    header_scale = struct.unpack(">f", data[12:16])[0]
    words = np.frombuffer(data, ">i2", count=180 * 404, offset=7 * 512).reshape(180, 404)[:, :132].reshape(180, 33, 4)
    ref = words[..., :3] * header_scale
    ref[words[..., 3] < 0] = np.nan
    take = read_c3d(path)
    assert take.n_frames == 180 and take.rate == 60.0 and take.units == "mm"
    np.testing.assert_allclose(take.positions, ref, rtol=1e-12, atol=0, equal_nan=True)
    assert take.warnings[0] == (f"{path}: POINT:SCALE (0.0215412) and the header's scale (0.0551136) disagree; the "
                                "header's was used (POINT:SCALE would make every coordinate 2.56 times smaller).")
    xyz = {s: take.positions[:, take.labels.index(s)] for s in ("RSHO", "LSHO", "RHEE", "RTOE")}

    def apart(a, b):
        return np.nanmedian(np.linalg.norm(xyz[a] - xyz[b], axis=1))
    assert 1400 < np.nanmedian(xyz["RSHO"][:, 2]) < 1500
    assert 170 < apart("RHEE", "RTOE") < 210 and 380 < apart("RSHO", "LSHO") < 420


def test_files_ezc3d_misreads_are_misread_by_it():
    """The exceptions above are ezc3d's errors, not ours: its reading jumps across the volume every frame
    (or is empty) where py-c3d's and ours are trajectories."""
    require_data(THIRDPARTY / "c3d")
    for name in EZC3D_MISREADS:
        ez = _ezc3d_reading(THIRDPARTY / "c3d" / name)["positions"]
        ours = read_c3d(THIRDPARTY / "c3d" / name).positions
        if ez.size == 0:
            assert ours.shape[1] > 0
            continue
        step = lambda x: np.nanmedian(np.abs(np.diff(x, axis=0)))   # noqa: E731
        assert step(ez) > 50 * step(ours), name


# --- TRC ------------------------------------------------------------------------------------------
def _pandas_trc(path) -> tuple[list[str], np.ndarray, float, str]:
    """A plain reading: the header with split(), the table with pandas (any whitespace, blanks and NaN
    spellings as missing)."""
    lines = path.read_text().splitlines()
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, values)}
    names = [s.strip() for s in lines[3].split("\t")[2:] if s.strip()]
    table = pd.read_csv(path, sep="\t", skiprows=5, header=None, skip_blank_lines=True,
                        na_values=["nan", "NaN", "NAN", "-nan", " nan", "-NaN"], keep_default_na=True)
    table = table.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=np.float64)
    table = table[~np.isnan(table[:, 0])]   # rows with a frame number
    xyz = table[:, 2:2 + 3 * len(names)]
    if xyz.shape[1] < 3 * len(names):
        xyz = np.hstack([xyz, np.full((len(xyz), 3 * len(names) - xyz.shape[1]), np.nan)])
    pos = xyz.reshape(len(table), len(names), 3)
    pos[np.isnan(pos).any(axis=2)] = np.nan
    return names, pos, float(header["DataRate"]), header["Units"]


@pytest.mark.parametrize("name", TRC_FILES)
def test_thirdparty_trc(name):
    path = THIRDPARTY / "trc" / name
    take = read_trc(path)
    for w in take.warnings:
        _check_one_sentence(w, name)
    names, pos, rate, units = _pandas_trc(path)
    assert take.labels == names
    assert take.rate == rate and take.units == {"mm": "mm", "m": "m", "cm": "cm"}[units.lower()]
    assert take.positions.shape == pos.shape, (take.positions.shape, pos.shape)
    np.testing.assert_array_equal(np.isnan(take.positions), np.isnan(pos))
    np.testing.assert_allclose(take.positions, pos, rtol=1e-12, atol=0, equal_nan=True)


def test_thirdparty_trc_counts():
    require_data(THIRDPARTY / "trc")
    counts = {"exact": 0, "warning": 0, "refused": 0}
    for name in TRC_FILES:
        try:
            counts["warning" if read_trc(THIRDPARTY / "trc" / name).warnings else "exact"] += 1
        except RigInputError:
            counts["refused"] += 1
    assert counts == TRC_COUNTS
