"""Outputs the command line cannot write -- a folder where a file goes, a file where a folder goes, a pipe, a path
through a file, one file named for two outputs -- are refused before any work, in one sentence naming the path,
with exit code 2: nothing the user had is replaced and no temporary or journal is left behind."""
from __future__ import annotations

import os
import sys

import pytest

from tests.cli_runner import run_cli
from tests.rig_files import write_rig_folder


def _refused(proc, sentence: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr == f"error: {sentence}\n", proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""


def _listing(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_solve_refuses_a_report_that_is_a_folder_and_keeps_the_old_outputs(ict_dir, take_dir, tmp_path):
    """The audit's case: `--report DIR` beside existing outputs. Before, the take was solved, w.csv and c.pc2 were
    replaced, then the move onto DIR failed (exit 1, a crash log) and a temporary and a journal were left."""
    d = tmp_path / "d"
    (d / "rdir").mkdir(parents=True)
    (d / "w.csv").write_text("old weights\n")
    (d / "c.pc2").write_bytes(b"old cache")
    before = _listing(d)
    common = ["solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "--global"]
    proc = run_cli(*common, "-o", d / "w.csv", "--cache", d / "c.pc2", "--report", d / "rdir", check=False)
    _refused(proc, f"{d / 'rdir'}: is a folder, not a file.")
    assert (d / "w.csv").read_text() == "old weights\n" and (d / "c.pc2").read_bytes() == b"old cache"
    assert _listing(d) == before
    # one file named for two outputs: before, the report silently took the weights' place
    proc = run_cli(*common, "-o", d / "w.csv", "--report", d / "w.csv", check=False)
    _refused(proc, f"{d / 'w.csv'}: is given for both -o and --report; each output needs its own file.")
    assert (d / "w.csv").read_text() == "old weights\n" and _listing(d) == before


@pytest.mark.parametrize("command, target", [
    (["render", "{rig}", "-o", "{out}"], "folder"),
    (["export", "{rig}", "-o", "{out}"], "folder"),
    (["segment", "{rig}", "-o", "{out}"], "folder"),
    (["corrective", "{rig}", "--drivers", "raise,push", "--target", "{rig}/raise.obj", "-o", "{out}"], "folder"),
    (["personalize", "{rig}", "--scans", "{rig}/raise.obj", "-o", "{tmp}/actor.bsproj", "--report", "{out}"],
     "folder"),
    (["export", "{rig}", "-o", "{out}/posed.obj"], "file above"),
    (["render", "{rig}", "-o", "{out}"], "pipe"),
    (["sample", "-o", "{out}"], "file"),
    (["batch", "{rig}", "{tmp}/take.trc", "-o", "{out}"], "file"),
])
def test_every_command_refuses_an_output_it_cannot_write(tmp_path, command, target):
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    out = tmp_path / "out"
    if target == "folder":
        out.mkdir()
        (out / "keep.txt").write_text("mine")
        sentence = f"{out}: is a folder, not a file."
    elif target == "pipe":
        if not hasattr(os, "mkfifo"):
            pytest.skip("no named pipes here")
        os.mkfifo(out)
        sentence = f"{out}: is not a regular file (a device, pipe or socket); nothing was written."
    else:
        out.write_text("mine")
        sentence = f"{out}/posed.obj: {out} is a file, not a folder." if target == "file above" else \
            f"{out}: is a file, not a folder."
    before = _listing(tmp_path)
    proc = run_cli(*[a.format(rig=rig, out=out, tmp=tmp_path) for a in command], check=False)
    _refused(proc, sentence)
    assert _listing(tmp_path) == before
    if target != "pipe":
        assert (out / "keep.txt" if out.is_dir() else out).read_text() == "mine"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX paths")
def test_an_output_in_a_folder_named_by_its_trailing_slash_is_refused(tmp_path):
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    proc = run_cli("segment", rig, "-o", f"{tmp_path}/regions/", check=False)
    _refused(proc, f"{tmp_path}/regions/: is a folder, not a file.")
    assert not (tmp_path / "regions").exists()


@pytest.mark.parametrize("command, sentence", [
    # the take itself: its markers or weights were replaced by the solve's weights
    (["solve", "{rig}", "{tmp}/take.csv", "-o", "{tmp}/take.csv"],
     "{tmp}/take.csv: is TAKE itself, which this command reads; give -o another file."),
    (["export", "{rig}", "-o", "{tmp}/take.csv", "--animation", "{tmp}/take.csv"],
     "{tmp}/take.csv: is --animation itself, which this command reads; give -o another file."),
    (["personalize", "{tmp}/p.bsproj", "--neutral-scan", "{rig}/neutral.obj", "-o", "{tmp}/p.bsproj"],
     "{tmp}/p.bsproj: is RIG itself, which this command reads; give -o another file."),
    # the rig's own neutral: the rig's every shape silently measured from a posed face
    (["export", "{rig}", "--weights", "raise=1", "-o", "{rig}/neutral.obj"],
     "{rig}/neutral.obj: is in {rig}, which RIG reads, and would overwrite a file it reads; give -o a file "
     "elsewhere."),
    # a new OBJ in the rig's folder is one more shape the next time the rig is read
    (["export", "{rig}/neutral.obj", "-o", "{rig}/posed.obj"],
     "{rig}/posed.obj: is in {rig}, which RIG reads, and would be read there as one more shape; give -o a file "
     "elsewhere."),
    (["render", "{rig}", "--size", "64,64", "-o", "{rig}/raise.png"],
     "{rig}/raise.png: is in {rig}, which RIG reads, and would be read there as the texture of raise; give -o a "
     "file elsewhere."),
    (["personalize", "{rig}", "--scans", "{tmp}/scans", "-o", "{tmp}/scans/actor.obj"],
     "{tmp}/scans/actor.obj: is in {tmp}/scans, which --scans reads, and would be read there as one more scan; give "
     "-o a file elsewhere."),
    # the sample into a folder holding a rig: its neutral.obj was written over the user's
    (["sample", "-o", "{rig}"], "{rig}: already holds neutral.obj and 2 more; write the sample rig into a new or "
                                "empty folder."),
])
def test_no_command_writes_over_what_it_reads(tmp_path, command, sentence):
    """An output naming one of the command's inputs was written over it: `solve RIG take.csv -o take.csv` replaced
    the take, `export RIG -o RIG/neutral.obj --weights ...` the rig's neutral (every shape then measured from a posed
    face), `sample -o DIR` the rig in DIR; a new OBJ in the rig's folder became one more shape. Each is refused before
    any work, one sentence, exit 2, every file as it was."""
    from model.project import Project, save_project
    from model.readers import load_rig
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    (tmp_path / "take.csv").write_text("frame,raise\n0,0.5\n1,1\n")
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "s0.obj").write_bytes((rig / "raise.obj").read_bytes())
    save_project(Project(rig=load_rig(rig)), tmp_path / "p.bsproj")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    proc = run_cli(*[a.format(rig=rig, tmp=tmp_path) for a in command], check=False)
    _refused(proc, sentence.format(rig=rig, tmp=tmp_path))
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_a_file_the_rigs_folder_does_not_read_may_be_written_there_again(tmp_path):
    """Only what the rig's reader reads is refused in its folder: a render's preview.png or a segmentation's
    regions.json there is no part of the rig, and writing it again is fine."""
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    for _ in range(2):
        run_cli("render", rig, "--size", "32,32", "-o", rig / "preview.png")
        run_cli("segment", rig, "--min-size", "5", "-o", rig / "regions.json")


def test_corrective_may_add_to_the_project_it_reads(tmp_path):
    """`corrective P.bsproj ... -o P.bsproj` adds the corrective to the project in place (saved atomically): the one
    output that may be its input."""
    from model.project import Project, load_project, save_project
    from model.readers import load_rig
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    save_project(Project(rig=load_rig(rig)), tmp_path / "p.bsproj")
    run_cli("corrective", tmp_path / "p.bsproj", "--drivers", "raise,push", "--target", rig / "raise.obj",
            "-o", tmp_path / "p.bsproj")
    assert [c.name for c in load_project(tmp_path / "p.bsproj").rig.correctives] == ["raise+push"]


def _gltf_with_files_beside(folder):
    """The third-party MorphStressTest.gltf with its buffer in 'Morph Stress.bin' (the uri percent-encoded, as glTF
    writes a space) and its TinyGrid image in 'tiny grid.png' beside it, in ``folder``."""
    import base64
    import json
    from tests.conftest import DATA, require_data
    gltf = json.loads(require_data(DATA / "thirdparty" / "gltf" / "MorphStressTest.gltf").read_text())
    blob = base64.b64decode(gltf["buffers"][0]["uri"].split(",", 1)[1])
    folder.mkdir()
    (folder / "Morph Stress.bin").write_bytes(blob)
    gltf["buffers"][0]["uri"] = "Morph%20Stress.bin"
    image = next(i for i in gltf["images"] if i["name"] == "TinyGrid")
    view = gltf["bufferViews"][image.pop("bufferView")]
    start = view.get("byteOffset", 0)
    (folder / "tiny grid.png").write_bytes(blob[start:start + view["byteLength"]])
    image["uri"] = "tiny%20grid.png"
    (folder / "stress.gltf").write_text(json.dumps(gltf))
    return folder / "stress.gltf"


def test_no_command_writes_over_the_files_a_gltf_rig_reads(tmp_path):
    """A .gltf rig's external buffers and images are read with it, but only the .gltf itself was guarded: `segment
    rig.gltf -o rig.bin` wrote the regions over the rig's geometry and `render rig.gltf -o its_texture.png` the
    picture over its texture. Each is refused before any work, one sentence naming both, exit 2, every file as it
    was; an output beside them that the glTF does not name is written."""
    rig = _gltf_with_files_beside(tmp_path / "rig")
    before = {p: p.read_bytes() for p in rig.parent.iterdir()}
    _refused(run_cli("segment", rig, "-o", rig.parent / "Morph Stress.bin", check=False),
             f"{rig.parent}/Morph Stress.bin: is the buffer file 'Morph%20Stress.bin' that RIG ({rig}) reads; give -o "
             "another file.")
    _refused(run_cli("render", rig, "--size", "32,32", "-o", rig.parent / "tiny grid.png", check=False),
             f"{rig.parent}/tiny grid.png: is the image file 'tiny%20grid.png' that RIG ({rig}) reads; give -o "
             "another file.")
    assert {p: p.read_bytes() for p in rig.parent.iterdir()} == before
    run_cli("render", rig, "--size", "32,32", "-o", rig.parent / "preview.png")
    assert (rig.parent / "preview.png").is_file()
    # a uri no file can have (a NUL) is the reader's to refuse, not a crash of the output check
    import json
    gltf = json.loads(rig.read_text())
    gltf["buffers"][0]["uri"] = "bad%00name.bin"
    rig.write_text(json.dumps(gltf))
    _refused(run_cli("render", rig, "--size", "32,32", "-o", rig.parent / "nul.png", check=False),
             f"{rig}: the glTF is damaged (ValueError: embedded null byte).")


@pytest.mark.parametrize("command, out", [
    (["export", "{rig}", "-o", "{out}"], "{ro}/posed.glb"),
    (["export", "{rig}", "-o", "{out}"], "{ro}/new/posed.obj"),          # a folder to make inside it
    (["solve", "{rig}", "{tmp}/take.csv", "-o", "{tmp}/w.csv", "--report", "{out}"], "{ro}/report.json"),
    (["segment", "{rig}", "-o", "{out}"], "{ro}/regions.json"),
    (["personalize", "{rig}", "--scans", "{rig}/raise.obj", "-o", "{out}"], "{ro}/actor.bsproj"),
    (["sample", "-o", "{out}"], "{ro}/sample"),
    (["batch", "{rig}", "{tmp}/take.csv", "-o", "{out}"], "{ro}"),
])
def test_an_output_in_a_folder_that_takes_no_new_file_is_refused_before_any_work(tmp_path, monkeypatch, capsys,
                                                                                  command, out):
    """The audit's case: every command writing into a folder the user may not write in (or on a read-only disk) did
    all its work, then stopped at the write with an unexpected error (exit 1, "failed unexpectedly", a crash log);
    `solve -o w.csv --report RO/r.json` had its work done for nothing. Refused before any work: one sentence naming
    the output and the folder, exit 2, nothing written. (As root a folder's permissions do not stop a write: the
    folder's answer to ``os.access`` is what the check asks, so it is made to say no.)"""
    from app import cli
    rig, ro = tmp_path / "rig", tmp_path / "ro"
    write_rig_folder(rig)
    (tmp_path / "take.csv").write_text("frame,raise\n0,0.5\n1,1\n")
    ro.mkdir()
    os.chmod(ro, 0o555)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if os.path.abspath(p) == str(ro) and mode & os.W_OK
                        else real_access(p, mode, **kw))
    before = _listing(tmp_path)
    try:
        target = out.format(ro=ro)
        code = cli.main([a.format(rig=rig, out=target, tmp=tmp_path) for a in command])
    finally:
        os.chmod(ro, 0o755)
    err = capsys.readouterr().err
    where = "" if target == str(ro) else f"cannot be written: {ro} "
    assert code == 2 and err == f"error: {target}: {where}is a folder you may not write in; nothing was written.\n", \
        (code, err)
    assert _listing(tmp_path) == before


@pytest.mark.parametrize("takes, options, sentence", [
    # an earlier batch's weights given as a take: take01.csv's weights went over it (the take in -o is not solved)
    (["{tmp}/out/take01/weights.csv", "{tmp}/take01.csv"], [],
     "{tmp}/out/take01/weights.csv: is TAKES itself, which this command reads; give -o another folder."),
    # the summary among a folder of takes given: it was read there as one more take by the next batch of the folder
    (["{tmp}/day1", "{tmp}/take01.csv"], [],
     "{tmp}/day1/batch.csv: is in {tmp}/day1, which TAKES reads, and would be read there as one more take; give -o "
     "another folder."),
    (["{tmp}/take01.csv"], ["--map", "{tmp}/day1/batch.json"],
     "{tmp}/day1/batch.json: is --map itself, which this command reads; give -o another folder."),
])
def test_batch_writes_none_of_its_files_over_what_it_reads(tmp_path, takes, options, sentence):
    """`batch` checked its output folder only as a folder: a take given inside it is left out of the solve, but a
    file of another take's set could be it (`batch RIG out/take01/weights.csv take01.csv -o out` wrote take01's
    weights over that take), and its summary could land over the marker map or among a folder of takes given. Each
    is refused before any work, one sentence, exit 2, every file as it was."""
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    (tmp_path / "take01.csv").write_text("frame,raise\n0,0.5\n1,1\n")
    (tmp_path / "out" / "take01").mkdir(parents=True)
    (tmp_path / "out" / "take01" / "weights.csv").write_text("frame,push\n0,0.25\n1,0.75\n")
    (tmp_path / "day1").mkdir()
    (tmp_path / "day1" / "a.csv").write_text("frame,push\n0,1\n")
    (tmp_path / "day1" / "batch.json").write_text('{"markers": {"M00": 0}}')   # a marker map so named
    out = tmp_path / ("day1" if "day1" in sentence.split(":")[0] else "out")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    proc = run_cli("batch", rig, *[t.format(tmp=tmp_path) for t in takes], *[o.format(tmp=tmp_path) for o in options],
                   "-o", out, "--workers", "1", check=False)
    _refused(proc, sentence.format(tmp=tmp_path))
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_personalize_writes_its_project_and_report_as_one_set(tmp_path, monkeypatch, capsys):
    """`personalize -o A.bsproj --report R.json` wrote the project, then the report: a report that failed to be
    written (here: the disk full as its temporary is written) left the new project behind a failed command. Now both
    are written as one set (``model.output_set.write_set``, as solve's outputs): neither is there."""
    import errno

    from app import cli
    from model import atomic, output_set
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    real = atomic.write_temporary

    def full_disk(path, writer):
        if path.name == "report.json":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, writer)
    monkeypatch.setattr(atomic, "write_temporary", full_disk)
    monkeypatch.setattr(output_set, "write_temporary", full_disk)
    before = _listing(tmp_path)
    code = cli.main(["personalize", str(rig), "--scans", str(rig / "raise.obj"), "-o", str(tmp_path / "actor.bsproj"),
                     "--report", str(tmp_path / "report.json")])
    assert code == 2 and "the disk is full" in capsys.readouterr().err   # one sentence (tests/test_disk_errors.py)
    assert _listing(tmp_path) == before


def _rig_with_materials_and_a_linked_shape(tmp_path):
    """An OBJ rig folder whose neutral names its material library (face.mtl) and one of whose shapes, face.obj, is
    a link to a file kept elsewhere (a library of shapes shared by rigs): an OBJ written over that link is not in
    the rig's folder by its real path, but the .mtl written beside it (face.mtl) is the rig's own materials."""
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    (rig / "neutral.obj").write_text("mtllib face.mtl\n" + (rig / "neutral.obj").read_text())
    (rig / "face.mtl").write_text("newmtl skin\nKd 0.8 0.6 0.5\n")
    (tmp_path / "library").mkdir()
    (tmp_path / "library" / "face.obj").write_text((rig / "raise.obj").read_text())
    os.symlink(os.path.join("..", "library", "face.obj"), rig / "face.obj")
    return rig


def test_an_obj_export_refuses_a_material_library_it_would_write_over_an_input(tmp_path):
    """`export -o X.obj` also writes X.mtl beside it (the rig's materials' colours), over any file there: the rig's own
    material library was replaced, unchecked. It is checked as the OBJ is: refused in one sentence naming it, exit 2,
    nothing written."""
    rig = _rig_with_materials_and_a_linked_shape(tmp_path)
    before = {p: (p.read_bytes(), p.is_symlink()) for p in tmp_path.rglob("*") if p.is_file()}
    proc = run_cli("export", rig, "-o", rig / "face.obj", check=False)
    _refused(proc, f"{rig / 'face.mtl'} (the material library written with {rig / 'face.obj'}): is in {rig}, which "
                   "RIG reads, and would overwrite a file it reads; give -o a file elsewhere.")
    assert {p: (p.read_bytes(), p.is_symlink()) for p in tmp_path.rglob("*") if p.is_file()} == before
    run_cli("export", rig, "-o", tmp_path / "face.obj", check=True)      # elsewhere: both written
    assert (tmp_path / "face.mtl").is_file() and "mtllib face.mtl" in (tmp_path / "face.obj").read_text()
