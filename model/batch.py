"""Batch solving: many marker takes onto one rig with one set of solve settings, on a Dask cluster (issue 21).
Qt-free; the ``batch`` command (app.cli_batch) and the GUI's File ▸ Batch Solve… (app.batch_controller) call it.

- ``find_takes`` expands files, folders and glob patterns into take files; ``take_names`` names each take's
  output folder ``OUTDIR/<take>/``.
- ``BatchJob`` is what every take shares: the rig (and, built where a take needs it, its float64 pose evaluator),
  the segmentation of a per-region solve, the marker map, the settings and the preview's framing. ``run_batch``
  scatters it to every worker once.
- ``solve_take_file`` is one take's job (on a worker): the same ``TakeWorkspace`` solve as ``solve``, its weights
  CSV, report, preview PNG and (optionally) PC2 cache written as one set (``model.output_set.write_set``) with a
  done-marker (``done.json``) last, so a killed run never leaves half a take. A bad take (unreadable, a map
  that does not fit) returns a failed row with its one-sentence error. On a cluster it runs as ``solve_and_report``,
  which also sends its row to the client as a Dask event, ahead of the news that the take is done.
- ``completed_row`` is the resumability check: a take whose done-marker matches the take file and the settings
  is skipped unless forced.
- ``run_batch`` runs the jobs on a local cluster (worker processes forked from one fork server that imported what a
  take needs, started early by the command: ``start_fork_server``; the scheduler forked from it too,
  ``model.batch_scheduler``; one thread each, Dask's housekeeping made rarer: ``local_cluster_config``; the whole
  cluster driven from a process forked from the same fork server, ``model.batch_driver``, so that the command never
  imports Dask) or a scheduler address, with retries, and reports progress (``solve_on_cluster``, the same code in
  the driver and in-process); ``write_summary`` writes ``batch.json`` and ``batch.csv``. Each worker draws its
  previews on the CPU (``app.cli_batch.preview_image``: no OpenGL context to ready) and keeps the take solver's per-rig
  preparation across its takes (``BatchJob.prepared``), starting from the one the job carries (made once, with the
  job, as are the preview's hidden back sides and normals).
"""
from __future__ import annotations

import csv
import dataclasses
import glob
import hashlib
import io
import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import batch_driver, shared_pickle
from .atomic import check_output_file, check_output_folder, disk_error, process_alive
from .batch_driver import ClusterOutcome
from .errors import RigInputError
from .fork_server import start_fork_server
from .marker_map import MarkerMap
from .output_set import finish_interrupted_sets, write_set
from .pose import PoseEvaluator
from .rig import Rig
from .rig_prep import focus_vertices, shape_reach
from .takes import TAKE_SUFFIXES

DONE = "done.json"                      # the done-marker, written last in a take's set
OUTPUTS = {"weights": "weights.csv", "report": "report.json", "preview": "preview.png", "cache": "cache.pc2"}
SUMMARY_JSON, SUMMARY_CSV = "batch.json", "batch.csv"
STATUSES = ("solved", "skipped", "failed")
ROW_KEYS = ("take", "status", "error", "frames", "rate", "frames_per_second", "marker_rmse", "motion_explained",
            "seconds", "path", "output", "warnings")     # warnings: the take reader's sentences (a file cut short)
PREVIEW_SIZE = (480, 360)
# the Dask event topic under which the takes send their rows (``solve_and_report``): one name for every batch, so
# that a long-lived scheduler keeps one bounded log of them (Dask keeps each topic's last events), not one per batch
ROW_TOPIC = "blendshape-studio-batch-rows"
_TMP_PREFIX = ".bs-batch-"


# --- which takes, under which names ------------------------------------------------------------------
def find_takes(items: list[str], exclude: str | Path | None = None, notes: list[str] | None = None) -> list[Path]:
    """Take files from files, folders (their .c3d, .trc and .csv files) and glob patterns, in the order given,
    each once. Under ``exclude`` (a batch's own output folder) what a folder or a pattern finds is left out: a
    batch's own outputs there (its summary, each take's weights CSV) would be read as takes. A file named there is
    solved like any other, unless it is one of a batch's own outputs (``batch_output``: a shell's expansion of
    ``day1/**/*.csv`` names them), which is left out with one sentence appended to ``notes`` saying so (it was left
    out without a word, whatever it was). RigInputError when an item names nothing."""
    found: list[tuple[Path, bool]] = []     # (take file, named as itself)
    for item in items:
        p = Path(item)
        if p.is_dir():
            hits = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in TAKE_SUFFIXES)
            if not hits:
                raise RigInputError(f"{item}: the folder holds no take (.c3d, .trc or .csv).")
        elif p.is_file():
            hits = [p]
        elif glob.has_magic(item):
            hits = sorted(Path(q) for q in glob.glob(item, recursive=True)
                          if Path(q).is_file() and Path(q).suffix.lower() in TAKE_SUFFIXES)
            if not hits:
                raise RigInputError(f"{item}: the pattern matches no take (.c3d, .trc or .csv).")
        else:
            raise RigInputError(f"{item}: does not exist.")
        found.extend((hit, p.is_file()) for hit in hits)
    seen, out, outputs = set(), [], []
    skip = Path(exclude).resolve() if exclude is not None else None
    for p, named in found:
        key = p.resolve()
        if skip is not None and key.is_relative_to(skip) and (not named or batch_output(key, skip)):
            if named and p not in outputs:
                outputs.append(p)
            continue
        if key not in seen:
            seen.add(key)
            out.append(key)
    if outputs and notes is not None:
        more = f" and {len(outputs) - 1} more file{'s' if len(outputs) > 2 else ''} given" if len(outputs) > 1 else ""
        many = len(outputs) > 1
        notes.append(f"{outputs[0]}{more}: {'are' if many else 'is'} a batch's own output{'s' if many else ''} in "
                     f"the output folder {exclude}, not {'takes' if many else 'a take'} to solve; left out (copy "
                     f"{'them' if many else 'it'} elsewhere to solve {'them' if many else 'it'}).")
    if found and not out:   # `batch RIG day1 -o day1`: every take left out as an output, and nothing solved (exit 0)
        raise RigInputError(f"{exclude}: every take given is in the output folder, where a batch's own outputs are "
                            "left out; give -o a folder of its own.")
    return out


def batch_output(path: Path, out_dir: Path) -> bool:
    """Whether ``path`` (resolved, inside the resolved ``out_dir``) is one of the files a batch into ``out_dir``
    writes (``batch_files``): its summary, or a file of a take's set in ``<out_dir>/<take>/``."""
    parts = path.relative_to(out_dir).parts
    return parts in ((SUMMARY_JSON,), (SUMMARY_CSV,)) or (len(parts) == 2 and parts[1] in {*OUTPUTS.values(), DONE})


@dataclass
class DroppedItems:
    """What files dropped on the Batch Solve dialog are (``sort_dropped``)."""

    takes: list[Path] = field(default_factory=list)   # take files and folders of takes, in the order dropped
    marker_map: Path | None = None
    results: Path | None = None                       # a batch's summary (batch.json) or the folder holding one


def sort_dropped(paths: list[str | Path]) -> DroppedItems:
    """Sort dropped paths by what the batch does with them: a ``batch.json`` (or a folder holding one) is an
    earlier batch's results, another ``.json`` file the marker map, a take file (.c3d, .trc, .csv) or another
    folder takes to solve. Anything else, or two maps or two results at once, is one sentence (RigInputError)
    naming the path; nothing is read but the folders' listings."""
    items = DroppedItems()
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            if (p / SUMMARY_JSON).is_file():
                kind = "results"
            else:
                items.takes.append(p)
                continue
        elif not p.is_file():
            raise RigInputError(f"{p}: does not exist.")
        elif p.name.lower() == SUMMARY_JSON:
            kind = "results"
        elif p.suffix.lower() == ".json":
            kind = "marker_map"
        elif p.suffix.lower() in TAKE_SUFFIXES:
            items.takes.append(p)
            continue
        else:
            raise RigInputError(f"{p}: is not a take (.c3d, .trc or .csv), a marker map (.json) or a batch's "
                                f"results (batch.json).")
        if getattr(items, kind) is not None:
            what = "marker maps" if kind == "marker_map" else "batch results"
            raise RigInputError(f"{getattr(items, kind)}, {p}: two {what} were dropped; drop one.")
        setattr(items, kind, p)
    return items


def take_names(paths: list[Path]) -> list[str]:
    """One output folder name per take: the file's stem; takes sharing a stem get as many parent folder names
    as tell them apart (``actor_take_take``), then their extension (``take_trc``)."""
    paths = [Path(p) for p in paths]

    def name(p: Path, depth: int, ext: bool) -> str:
        parts = list(p.parent.parts[-depth:]) if depth else []
        n = "_".join([*parts, p.stem]) + (f"_{p.suffix[1:]}" if ext else "")
        return n.replace(os.sep, "_").strip(". ") or "take"

    by_stem: dict[str, list[int]] = {}
    for i, p in enumerate(paths):
        by_stem.setdefault(p.stem, []).append(i)
    names = [""] * len(paths)
    for group in by_stem.values():
        depth_max = max(len(paths[i].parent.parts) for i in group)
        for depth in range(depth_max + 1):
            for ext in (False, True):
                cand = [name(paths[i], depth, ext) for i in group]
                if len(set(cand)) == len(cand):
                    break
            else:
                continue
            break
        for i, n in zip(group, cand):
            names[i] = n
    used: dict[str, int] = {}
    for i, n in enumerate(names):           # a clash across stems (rare): number the later ones
        k = used.get(n, 0)
        used[n] = k + 1
        if k:
            names[i] = f"{n}_{k + 1}"
    return names


def batch_files(out_dir: str | Path, names: list[str], cache: bool) -> list[Path]:
    """Every file a batch into ``out_dir`` writes (``run_batch``) for takes named ``names`` (``take_names``): the
    summary (``batch.json``, ``batch.csv``) and each take's ``<name>/`` set (``OUTPUTS``, the cache only with
    ``cache``, ``done.json``). The front ends check each against their inputs before any work
    (``model.beside_inputs``): a take given in ``out_dir`` is not solved, but a file of another take's set can be it
    (``out/take01/weights.csv``, a take of an earlier batch, written over by ``take01.c3d``'s weights)."""
    out = Path(out_dir)
    per_take = [f for key, f in OUTPUTS.items() if cache or key != "cache"] + [DONE]
    return [out / SUMMARY_JSON, out / SUMMARY_CSV] + [out / name / f for name in names for f in per_take]


# --- what every take shares -------------------------------------------------------------------------
def _digest(*arrays) -> str:
    h = hashlib.sha1()
    for a in arrays:     # the array's own memory, not a copy of it (2.3 GB for the 422k-vertex studio rig's deltas)
        h.update(np.ascontiguousarray(a).reshape(-1).view(np.uint8))
    return h.hexdigest()[:16]


@dataclass
class BatchJob:
    """Everything the takes of a batch share, built once in the client and scattered to the workers."""

    rig: Rig
    settings: dict
    segmentation: object = None
    marker_map: MarkerMap | None = None
    cache: bool = False
    preview: Callable | None = None       # preview(points, counts, indices, focus=, view=) -> PNG bytes, or None
    focus: np.ndarray | None = None       # the points the preview frames
    signature: dict = field(default_factory=dict)
    antagonists: list | None = None       # the pairs the solves keep apart (``solve_pairs``), found once
    preload: tuple = ()                   # modules a local cluster's workers load before their first take
    solver_prep: dict | None = None       # the take solver's preparation for the map's markers (``prepare_solver``)
    preview_view: object = None           # the preview's faces prepared (``model.rig_prep.DefaultView``)

    @classmethod
    def prepare(cls, rig: Rig, settings: dict, *, segmentation=None, marker_map: MarkerMap | None = None,
                cache: bool = False, preview: Callable | None = None, focus: np.ndarray | None = None,
                preload: tuple = ()) -> "BatchJob":
        """The shared part of a batch. What every worker's first take would otherwise find again is found here,
        once: the take solver's preparation for takes that carry every marker of ``marker_map``
        (``model.take_workspace.prepare_solver``) and the preview's hidden back sides and normals
        (``model.rig_prep.default_view``), ~0.05 s of each worker's first take on ICT. The rig's float64 pose
        evaluator is not built here but where a take first needs it (``evaluator``: in each worker; at studio scale
        it is the rig's deltas again). ``preload``: modules whose import readies a worker for ``preview`` (see
        ``start_client``)."""
        map_id = "automatic" if marker_map is None else hashlib.sha1(
            json.dumps(marker_map.to_json(), sort_keys=True).encode()).hexdigest()[:16]
        signature = {"settings": {k: settings[k] for k in sorted(settings)}, "marker_map": map_id,
                     "rig": _digest(rig.neutral, rig.deltas, *[c.delta for c in rig.correctives]),
                     "rig_units": rig.units, "cache": bool(cache), "preview": preview is not None}
        from .antagonists import solve_pairs
        from .rig_prep import default_view
        from .take_workspace import prepare_solver
        return cls(rig=rig, settings=dict(settings),
                   segmentation=segmentation, marker_map=marker_map, cache=cache, preview=preview,
                   focus=focus, signature=json.loads(json.dumps(signature)),
                   antagonists=solve_pairs(rig, settings),    # once per batch, not once per take
                   preload=tuple(preload),
                   solver_prep=prepare_solver(rig, marker_map, settings) if marker_map is not None else None,
                   preview_view=default_view(rig) if preview is not None else None)

    def preview_faces(self) -> tuple[np.ndarray, np.ndarray]:
        """(face counts, face indices) a preview draws: the rig's faces without its helper shells, as ``render``
        draws them by default (``model.parts``); found once per process."""
        faces = getattr(self, "_preview_faces", None)
        if faces is None:
            from .parts import drawn_faces
            faces = self._preview_faces = drawn_faces(self.rig)[1:]
        return faces

    def __getstate__(self) -> dict:
        """Pickled (scattered to every worker) without the evaluator, where one was built: pickled, its matrix would
        be the rig's deltas again (69 MB instead of 39 MB on ICT). Where the job is unpickled, the evaluator is made
        from the rig when first asked for, in the first take: it reads the rig's float64 deltas in place
        (``PoseEvaluator``; a rig with in-betweens or correctives gets its own matrix, ~0.05 s on ICT)."""
        state = dict(self.__dict__)
        state.pop("prepared", None)                     # this process's own
        state.pop("evaluator", None)
        return state

    def __reduce_ex__(self, protocol):
        """A job mapped from a local batch's memory file (``model.batch_driver``) is passed on as that file's handle
        (``model.shared_pickle.SharedObject``): Dask's broadcast scatters it to one worker, which hands it to the
        next; that one maps the file too instead of unpickling a copy of the rig."""
        handle = self.__dict__.get(shared_pickle.HANDLE_ATTRIBUTE)
        if handle is not None:
            return handle.__reduce__()
        return super().__reduce_ex__(protocol)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)                      # no evaluator yet: ``__getattr__`` builds it

    def __getattr__(self, name: str):
        if name == "prepared":      # the take solver's preparation for this rig, kept across this process's takes
            self.prepared = dict(self.solver_prep or {})
            return self.prepared
        if name == "evaluator":     # the rig's float64 pose evaluator, built on first use in this process
            self.evaluator = PoseEvaluator(self.rig, dtype=np.float64)
            return self.evaluator
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


# --- one take ---------------------------------------------------------------------------------------
def _take_identity(path: Path) -> dict:
    st = path.stat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _row(name: str, path: Path, out_dir: Path | None, status: str, error: str | None = None, **values) -> dict:
    """A summary row; ``out_dir`` None when nothing was written."""
    row = dict.fromkeys(ROW_KEYS)
    row.update(take=name, path=str(path), output=None if out_dir is None else str(out_dir), status=status,
               error=error)
    row.update(values)
    return row


def completed_row(job: BatchJob, take_path: str | Path, out_dir: str | Path, name: str | None = None) -> dict | None:
    """The take's row as ``skipped`` when its outputs are complete for this take file and these settings (its
    done-marker says so and every output it lists exists), else None. Finishes an interrupted set first."""
    take_path, out_dir = Path(take_path), Path(out_dir)
    if not out_dir.is_dir():
        return None
    finish_interrupted_sets(out_dir)
    try:
        done = json.loads((out_dir / DONE).read_text())
        ok = (done["signature"] == job.signature and done["take_file"] == _take_identity(take_path)
              and all((out_dir / f).is_file() for f in done["outputs"]))
        row = dict(done["row"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not ok:
        return None
    row.update(status="skipped", error=None, take=name or row.get("take"), path=str(take_path), output=str(out_dir))
    return row


_BLAS_LIMITED = False


def _limit_blas_once() -> None:
    """One BLAS thread in a worker, as ``solve`` runs (and as results stay identical to it)."""
    global _BLAS_LIMITED
    if not _BLAS_LIMITED:
        from threadpoolctl import threadpool_limits
        threadpool_limits(1, user_api="blas")
        _BLAS_LIMITED = True


def _sweep_temporaries(out_dir: Path) -> None:
    """Remove the private folders of this take's writers that are gone (a killed worker's)."""
    for d in out_dir.glob(f"{_TMP_PREFIX}*"):
        try:
            pid = int(d.name[len(_TMP_PREFIX):].split("-")[0])
        except ValueError:
            continue
        if not process_alive(pid):
            shutil.rmtree(d, ignore_errors=True)


def preview_focus(rig: Rig) -> np.ndarray | None:
    """The points a preview frames, as the window's cameras and ``render`` frame them (``rig_prep.focus_vertices``):
    the face where the shapes act on a part inside the model, else None (the posed surface, whole). Was its own rule,
    the neutral where a shape moves a vertex over 5% of the largest displacement, which cut half of a glTF cube whose
    one side moves out of its picture."""
    if not rig.n_shapes:
        return None
    return focus_vertices(rig.neutral, shape_reach(rig))   # one shape at a time: no (K, V, 3) temporaries


def preview_frame(weights: np.ndarray) -> int:
    """The frame the preview shows: the most expressive one (largest sum of weights)."""
    return int(np.argmax(np.asarray(weights).sum(axis=1))) if len(weights) else 0


def solve_take_file(job: BatchJob, take_path: str, out_dir: str, name: str | None = None) -> dict:
    """Solve one take as ``solve`` does and write its outputs into ``out_dir`` as one set, the done-marker last.
    Returns the summary row; a bad take gives a failed row with its one-sentence error (nothing is written).
    Anything unexpected propagates (the cluster retries the take, then reports it)."""
    from .take_exports import check_solve_output_space, solve_output_writers
    from .take_workspace import TakeWorkspace

    _limit_blas_once()
    take_path, out_dir = Path(take_path), Path(out_dir)
    name = name or out_dir.name
    start = time.perf_counter()
    try:
        check_output_folder(out_dir)              # no file where the take's folder goes: fail before any work
        ws = TakeWorkspace(job.rig)
        cache = out_dir / OUTPUTS["cache"] if job.cache else None       # room for it, checked before the solve
        solved = ws.prepare_solve(take_path, job.marker_map, job.settings,   # False: a weight take, played as it is
                                  check_outputs=lambda w: check_solve_output_space(w, cache))
        identity = _take_identity(take_path)
        sol = ws.solve(job.settings, segmentation=job.segmentation, evaluator=job.evaluator,
                       antagonists=job.antagonists, prepared=job.prepared) if solved else None
    except RigInputError as exc:
        return _row(name, take_path, None, "failed", str(exc), seconds=time.perf_counter() - start)
    made = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    _sweep_temporaries(out_dir)          # the private folders earlier versions wrote a take into first
    # what ``solve`` writes (``solve_output_writers``), with the preview and done.json, as one set: each file
    # written once, straight into its temporary beside its target
    writers, report = solve_output_writers(ws, out_dir / OUTPUTS["weights"],
                                           cache_path=cache,
                                           report_path=out_dir / OUTPUTS["report"], evaluator=job.evaluator)
    weights = ws.playing_weights()
    frame, preview_error = preview_frame(weights), None
    if job.preview is not None:
        try:          # a preview that cannot be drawn (e.g. points that are not finite) costs the take its picture only
            surface = sol.dense(frame) if sol is not None else job.evaluator.pose(weights[frame])
            png = job.preview(surface, *job.preview_faces(), focus=job.focus, view=job.preview_view)
            writers[out_dir / OUTPUTS["preview"]] = lambda f: f.write(png)
        except Exception as exc:
            preview_error = f"the preview could not be rendered ({type(exc).__name__}: {exc})"
    measured = {k: None if report.get(k) is None else float(report[k])
                for k in ("frames_per_second", "marker_rmse", "motion_explained")}
    row = _row(name, take_path, out_dir, "solved", frames=int(report["frames"]), rate=float(report["rate"]),
               **measured, preview_frame=frame, preview_error=preview_error, warnings=list(report["warnings"]))
    row["seconds"] = time.perf_counter() - start
    done = {"take_file": identity, "signature": job.signature, "outputs": [Path(p).name for p in writers],
            "row": row}
    writers[out_dir / DONE] = lambda f: f.write((json.dumps(done, indent=1) + "\n").encode())
    try:
        write_set(writers)     # refuses, before writing any, a set with a folder where one of its files goes
    except RigInputError as exc:   # a full disk too: nothing of the set is left, nor the take's folder made for it
        if made and not any(out_dir.iterdir()):
            out_dir.rmdir()
        return _row(name, take_path, None, "failed", str(exc), seconds=time.perf_counter() - start)
    return row


def solve_and_report(job: BatchJob, take_path: str, out_dir: str, name: str) -> dict:
    """``solve_take_file`` as a cluster's task: its row is also sent to the client as a Dask event under ``ROW_TOPIC``
    (``Worker.log_event``: it rides the worker's stream to the scheduler ahead of the task's completion, and the
    scheduler's stream to the client ahead of the news that the task is done), so that the client has it when it
    hears the take is done, without asking the worker for the task's result: that round trip through the scheduler
    and back was a third of Dask's own CPU time per take (issue 21: ~2% of a 2-worker run). The row is returned
    too, for a client that has not heard it (``solve_on_cluster`` then asks for it as before).

    An error nobody expected (a bug, not the take: ``solve_take_file`` turns a bad take into a failed row) fails the
    take here, with its traceback in the row's ``"traceback"`` for the front end's crash log: raised, Dask retried
    the take on every worker (the same error each time) and printed a worker's traceback for each try. A worker
    that dies is still retried."""
    try:
        row = solve_take_file(job, take_path, out_dir, name)
    except Exception as exc:      # noqa: BLE001 (not BaseException: a worker shut down mid-take is Dask's to retry)
        import traceback
        full = disk_error(Path(out_dir) if getattr(exc, "filename", None) is None else None, exc)
        row = _row(name, Path(take_path), None, "failed", str(full)) if full is not None else \
            _row(name, Path(take_path), None, "failed", _unexpected(Path(take_path), exc),
                 traceback="".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    try:
        from distributed import get_worker
        worker = get_worker()
        worker.log_event(ROW_TOPIC, {"key": worker.get_current_task(), "row": row})
    except (ImportError, ValueError, TypeError):    # not on a Dask worker, or a row msgpack cannot carry: the
        pass                                        # client asks for the result instead; the take stands
    return row


# --- the summary ------------------------------------------------------------------------------------
def write_summary(out_dir: str | Path, rows: list[dict], meta: dict | None = None) -> None:
    """``batch.json`` (``{"takes": [rows]}`` plus ``meta``) and ``batch.csv`` (one line per take), as one set."""
    out_dir = Path(out_dir)
    doc = dict(meta or {})
    doc["takes"] = [{k: r.get(k) for k in ROW_KEYS} for r in rows]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(ROW_KEYS)
    for r in doc["takes"]:
        w.writerow(["" if r[k] is None else (repr(r[k]) if isinstance(r[k], float) else
                                             " ".join(map(str, r[k])) if isinstance(r[k], list) else r[k])
                    for k in ROW_KEYS])
    write_set({out_dir / SUMMARY_JSON: lambda f: f.write((json.dumps(doc, indent=1) + "\n").encode()),
               out_dir / SUMMARY_CSV: lambda f: f.write(buf.getvalue().encode())})


def status_counts(rows: list[dict]) -> dict[str, int]:
    """How many rows are solved, skipped and failed."""
    return {s: sum(r["status"] == s for r in rows) for s in STATUSES}


def counts_text(rows: list[dict]) -> str:
    """The rows' counts as the command and the dialog say them: 'solved 11, skipped 0 (complete), failed 1'."""
    c = status_counts(rows)
    return f"solved {c['solved']}, skipped {c['skipped']} (complete), failed {c['failed']}"


SUMMARY_MAX_BYTES = 256 << 20    # a summary of 10,000 takes is ~5 MB; a larger "batch.json" is not one


def read_summary(path: str | Path) -> tuple[Path, dict]:
    """(the batch's folder, its summary) from a ``batch.json`` or the folder that holds one, as ``write_summary``
    wrote it (a run of the ``batch`` command, on this machine or a cluster): its settings and counts, and
    ``takes``, one row a take with every ``ROW_KEYS`` key (None where the file has none). A file that is not
    such a summary -- not JSON, no list of takes, a row without a name or a status -- is one sentence
    (RigInputError); nothing the rows name is read here."""
    from .input_files import regular_file
    p = Path(path)
    p = regular_file(p / SUMMARY_JSON if p.is_dir() else p)
    try:
        size = p.stat().st_size
        if size > SUMMARY_MAX_BYTES:
            raise RigInputError(f"{p}: is not a batch summary ({size / 2 ** 20:.0f} MB).")
        data = p.read_bytes()
    except OSError as exc:
        raise RigInputError(f"{p}: cannot be read ({exc.strerror or exc}).") from None
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise RigInputError(f"{p}: is not a batch summary (not JSON text).") from None
    takes = doc.get("takes") if isinstance(doc, dict) else None
    if not isinstance(takes, list):
        raise RigInputError(f"{p}: is not a batch summary (no list of takes).")
    rows = []
    for i, r in enumerate(takes):
        if not (isinstance(r, dict) and isinstance(r.get("take"), str) and r.get("status") in STATUSES):
            raise RigInputError(f"{p}: is not a batch summary (take {i + 1} has no name or no status).")
        row = {k: r.get(k) for k in ROW_KEYS}
        for k in ("frames", "rate", "frames_per_second", "marker_rmse", "motion_explained", "seconds"):
            v = row[k]
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v)):
                row[k] = None                   # a value that is not a number is shown as none
        for k in ("error", "path", "output"):
            row[k] = row[k] if isinstance(row[k], str) else None
        if not (isinstance(row["warnings"], list) and all(isinstance(w, str) for w in row["warnings"])):
            row["warnings"] = None              # a summary written before takes recorded their warnings
        rows.append(row)
    summary = {k: v for k, v in doc.items() if k != "takes"}
    summary["takes"] = rows
    return p.parent, summary


def preview_path(batch_dir: str | Path, take: str) -> Path | None:
    """The preview PNG of the take named ``take`` in the batch folder ``batch_dir`` (``<batch_dir>/<take>/
    preview.png``), or None if it has none there. Found by the take's name inside the folder the user chose,
    never by a path a summary holds: a name that is not one plain folder name has none."""
    if not take or take in (".", "..") or any(c in take for c in ("/", "\\", "\0")):
        return None
    p = Path(batch_dir) / take / OUTPUTS["preview"]
    return p if p.is_file() else None


# --- the cluster ------------------------------------------------------------------------------------
@dataclass
class BatchProgress:
    """What a progress display shows after each take: counts, frames solved and time so far, the last row."""

    done: int                      # takes finished (solved, failed or skipped)
    total: int
    frames: int                    # frames solved in this run
    elapsed: float                 # seconds since the takes went to the cluster
    finished: int = 0              # takes the cluster finished in this run
    row: dict | None = None
    dashboard: str | None = None

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.elapsed if self.elapsed > 0 else 0.0

    @property
    def eta(self) -> float | None:
        """Seconds left, from the mean time of the takes finished so far in this run (None before the first)."""
        return None if self.finished <= 0 else self.elapsed / self.finished * (self.total - self.done)


def _unexpected(path: Path, exc: BaseException) -> str:
    from distributed import KilledWorker
    if isinstance(exc, KilledWorker):
        return f"{path}: every worker that solved it died ({exc})."
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{path}: the solve stopped unexpectedly ({type(exc).__name__}{': ' + text if text else ''})."


def local_cluster_config() -> dict:
    """Dask settings for the local cluster, for as long as it runs (its nannies read them when they start or
    restart a worker). With as many workers as cores, every CPU second spent beside the takes is taken from one:

    - the workers are forked from one fork server that imported ``WORKER_MODULES`` and the job's ``preload`` once
      and froze them for the garbage collector (``start_fork_server``, ``model.batch_preloaded``), instead of each
      worker starting a fresh interpreter and importing Dask, numpy, the solver and VTK itself (1.2-1.7 s of CPU a
      worker, most of it in its first take, and again in its deserialisation of the job and its interpreter's
      teardown at the end);
    - the workers' housekeeping runs less often: Dask's statistical profiler samples a worker's stack every 10 ms
      (off: the dashboard's Profile page stays empty), the event-loop health tick runs every 20 ms in every
      process (1 s), the system monitor every 0.5 s (5 s)."""
    import multiprocessing
    config = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
              "distributed.admin.system-monitor.interval": "5s"}
    if "forkserver" in multiprocessing.get_all_start_methods():
        config["distributed.worker.multiprocessing-method"] = "forkserver"
    return config


def _skip_dask_forkserver_preload() -> None:
    """Dask builds its own preload list for a fork server the first time it asks for its multiprocessing context,
    importing pandas and lz4 into this process to see whether they are installed (~0.2 s); the fork server is
    already running with ours (``start_fork_server``), so that list would never be used."""
    import distributed.utils
    if hasattr(distributed.utils, "_forkserver_preload_set"):
        distributed.utils._forkserver_preload_set = True


NANNY_START_POLL = 0.005     # seconds between a local worker's nanny's looks at whether its worker has started


def _poll_worker_starts_often() -> None:
    """A nanny learns that its worker process has started (and registered with the scheduler) by polling a queue,
    every 50 ms by Dask's default (``distributed.nanny.WorkerProcess._init_msg_interval``): the local cluster was up
    0-50 ms after its last worker had registered, 12-58 ms in the development machine's timelines (a batch on 2
    workers takes ~2 s). Every ``NANNY_START_POLL`` s instead: a few dozen more looks at a queue while the cluster
    starts. Left alone where Dask no longer has that attribute."""
    from distributed.nanny import WorkerProcess
    if isinstance(getattr(WorkerProcess, "_init_msg_interval", None), float):
        WorkerProcess._init_msg_interval = min(WorkerProcess._init_msg_interval, NANNY_START_POLL)


def start_client(workers: int | None = None, scheduler: str | None = None, *, timeout: float | None = None,
                 dashboard_address: str = "127.0.0.1:8787", preload: tuple = ()):
    """(Dask client, local cluster or None): a scheduler's address, or a LocalCluster of ``workers`` processes
    with one thread each on 127.0.0.1 (default: the machine's cores), to be run under ``local_cluster_config()``:
    its workers are forked from a fork server that imported ``WORKER_MODULES`` and ``preload`` (the fork server
    is this process's, started by ``start_fork_server`` or here, and kept for later clusters). ``timeout`` (seconds) for a
    scheduler to answer and show a worker: Dask's connect timeout by default
    (``distributed.comm.timeouts.connect``)."""
    import logging

    import dask
    from dask.utils import parse_timedelta
    from distributed import Client, LocalCluster
    if timeout is None:
        timeout = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="s")
    if scheduler:
        try:
            client = Client(scheduler, timeout=timeout)
            client.wait_for_workers(1, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            raise RigInputError(f"--scheduler {scheduler}: no scheduler with workers answered within "
                                f"{timeout:g} s ({type(exc).__name__}).") from None
        return client, None
    n = workers or os.cpu_count() or 1
    forked = (dask.config.get("distributed.worker.multiprocessing-method") == "forkserver"
              and start_fork_server(preload))
    if forked:
        _skip_dask_forkserver_preload()
    _poll_worker_starts_often()
    # One core a worker (Dask's nanny already sets one BLAS/OpenMP thread). The workers also preload ``preload`` the
    # Dask way, as they start: nothing more where they were forked from the fork server that imported it, the
    # preview's modules while the job is on its way where they were spawned.
    options = dict(n_workers=n, threads_per_worker=1, host="127.0.0.1", dashboard_address=dashboard_address,
                   silence_logs=logging.ERROR, preload=list(preload))
    cluster = _forked_scheduler_cluster(**options) if forked else LocalCluster(processes=True, **options)
    return Client(cluster), cluster


def _forked_scheduler_cluster(*, n_workers: int, threads_per_worker: int, host: str, dashboard_address: str | None,
                              silence_logs: int, preload: list):
    """The ``LocalCluster`` of these arguments (worker processes) with its scheduler in a process forked from the
    fork server (``model.batch_scheduler``) instead of this one: Dask's ``SpecCluster`` with the scheduler and the
    workers (nannies, their processes forked from the fork server) that ``LocalCluster`` would make."""
    import logging

    from distributed import Nanny, SpecCluster
    from distributed.worker_memory import parse_memory_limit

    from .batch_scheduler import ForkedScheduler
    scheduler = {"cls": ForkedScheduler, "options": dict(
        log_level=silence_logs, host=host, port=0, protocol="tcp://", dashboard=dashboard_address is not None,
        dashboard_address=dashboard_address)}
    worker = {"cls": Nanny, "options": dict(
        host=host, nthreads=threads_per_worker, protocol="tcp://", dashboard=False, silence_logs=silence_logs,
        preload=preload,
        memory_limit=parse_memory_limit("auto", 1, n_workers, logger=logging.getLogger("distributed")))}
    return SpecCluster(scheduler=scheduler, workers={i: worker for i in range(n_workers)}, worker=worker,
                       silence_logs=silence_logs)


def check_caches_space(job: BatchJob, takes: list[Path], take_dirs: list[Path], out_dir: Path) -> None:
    """Refuse a batch with ``--cache`` (``job.cache``) before any take is solved when the caches of all the
    ``takes`` to solve (each its frames × the rig's vertices × 12 bytes, ``model.pc2``), written into ``take_dirs``,
    do not fit on their disk together: each take's own check (``check_solve_output_space``) passed while the disk
    had room for any one of them, and the takes then filled it. A take's old cache (an earlier run's) is freed when
    its new one replaces it: only what a take's cache adds to it counts. A take that cannot be read is left to fail
    alone."""
    if not job.cache or len(takes) < 2:
        return
    from .free_space import check_free_space
    from .pc2 import pc2_size
    from .takes import load_take
    sizes, replaced = {}, False
    for take, folder in zip(takes, take_dirs):
        try:
            frames = load_take(take, rate=job.settings.get("rate")).n_frames
        except RigInputError:
            continue
        cache = folder / OUTPUTS["cache"]
        old = cache.stat().st_size if cache.is_file() else 0
        replaced |= old > 0
        sizes[cache] = pc2_size(frames, job.rig.n_vertices) - old
    if len(sizes) < 2:      # one take's cache: its own check says it, naming it
        return
    check_free_space(sizes, named=f"{out_dir}: the caches ({OUTPUTS['cache']}) of the {len(sizes)} takes to solve"
                                  + (", beyond the old ones they replace," if replaced else ""))


def longest_first(indices: list[int], takes: list[Path]) -> list[int]:
    """``indices`` of ``takes`` in the order to submit them: the largest files (the longest takes) first, ties in the
    given order. The workers take the submitted takes in order, so the last ones to start are the shortest, and a
    worker that runs out of takes waits less for the last one to end (longest processing time first, Graham 1969).
    A file that cannot be read sorts last (its take fails fast)."""
    def size(i: int) -> int:
        try:
            return takes[i].stat().st_size
        except OSError:
            return -1
    return sorted(indices, key=lambda i: -size(i))


def solve_on_cluster(job_source: Callable[[], BatchJob], tasks: list[tuple[int, str, str, str]], *, total: int,
                     done: int, preload: tuple = (), workers: int | None = None, scheduler: str | None = None,
                     retries: int = 2, progress: Callable[[BatchProgress], None] | None = None,
                     stop: Callable[[], str | None] | None = None,
                     dashboard_address: str = "127.0.0.1:8787") -> ClusterOutcome:
    """Solve ``tasks`` ((index, take file, output folder, name), in the order to submit them) on a local cluster of
    ``workers`` (its workers' fork server imports ``preload``) or on ``scheduler``'s; ``job_source()`` gives the job
    once the cluster is up (it may still be arriving meanwhile: ``model.batch_driver``). The job is scattered once;
    each take is retried ``retries`` times where its worker died. ``progress`` after each take (``done`` of
    ``total`` were finished before); ``stop()`` after each take: 'cancelled' stops the run (the takes still
    queued are cancelled); Ctrl-C (KeyboardInterrupt) stops it as 'interrupted'. Either way the cluster is
    closed before this returns."""
    outcome = ClusterOutcome()
    import dask
    import distributed  # noqa: F401  (its defaults join Dask's configuration here, not inside the block below,
    #                     whose end would take them out again: a second batch in this process would then fail)
    with dask.config.set(local_cluster_config() if not scheduler else {}):   # for the cluster's whole life
        client, cluster = start_client(workers, scheduler, dashboard_address=dashboard_address, preload=preload)
        try:
            from distributed import as_completed
            try:
                outcome.dashboard = client.dashboard_link
            except Exception:   # no dashboard (bokeh missing, or the scheduler runs none)
                outcome.dashboard = None
            if progress is not None:
                progress(BatchProgress(done, total, 0, 0.0, dashboard=outcome.dashboard))
            # to every worker; from this process straight to the workers of a local cluster (through the
            # scheduler, as for a remote one whose workers this process may not reach, it takes ~2x as long)
            shared = client.scatter(job_source(), broadcast=True, hash=False, direct=cluster is not None)
            run = uuid.uuid4().hex[:8]
            keys = {i: f"solve-{name}-{run}" for i, _, _, name in tasks}
            ours, reported = set(keys.values()), {}       # the rows the takes send (``solve_and_report``)

            def heard(event) -> None:   # on the client's event loop; rows of other batches on the scheduler: not ours
                message = event[1]
                if isinstance(message, dict) and message.get("key") in ours:
                    row = message["row"]
                    if isinstance(row, dict) and isinstance(row.get("warnings"), tuple):   # msgpack: a list comes
                        row = {**row, "warnings": list(row["warnings"])}                  # back as a tuple
                    reported[message["key"]] = row

            client.subscribe_topic(ROW_TOPIC, heard)
            futures = {client.submit(solve_and_report, shared, take, out, name, key=keys[i], pure=False,
                                     retries=retries): i
                       for i, take, out, name in tasks}
            paths = {i: Path(take) for i, take, _, _ in tasks}
            names = {i: name for i, _, _, name in tasks}
            t0 = time.perf_counter()
            finished = 0
            try:
                for fut in as_completed(list(futures)):
                    i = futures[fut]
                    row = reported.pop(fut.key, None) if fut.status == "finished" else None
                    if row is None:
                        try:
                            row = fut.result()
                        except Exception as exc:       # retried and still failing, or every worker it met died
                            row = _row(names[i], paths[i], None, "failed", _unexpected(paths[i], exc))
                    outcome.rows[i] = row
                    done += 1
                    finished += 1
                    if row["status"] == "solved":
                        outcome.frames += int(row["frames"] or 0)
                    outcome.seconds = time.perf_counter() - t0
                    if progress is not None:
                        progress(BatchProgress(done, total, outcome.frames, outcome.seconds, finished, row,
                                               outcome.dashboard))
                    outcome.stopped = stop() if stop is not None else None
                    if outcome.stopped:
                        client.cancel(list(futures))
                        break
            except KeyboardInterrupt:  # Ctrl-C: the cluster closes, the summary says what was done, then it stops
                outcome.stopped = "interrupted"
            outcome.seconds = time.perf_counter() - t0
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    return outcome


def share_job(job: BatchJob) -> BatchJob:
    """The job mapped back from the in-memory file that a local cluster's driver and workers will map
    (``model.shared_pickle.share``; ``run_batch`` then hands that file on as it is): once the caller drops its own
    rig, the rig's arrays are in memory once for the whole run (the ``batch`` command on the 422k-vertex studio rig:
    2.2 GiB less). The job itself where there are no in-memory files (not Linux)."""
    if not hasattr(os, "memfd_create"):
        return job
    return shared_pickle.share(job, batch_driver.JOB_FILE)[0]


def portable_job(job: BatchJob) -> BatchJob:
    """The job as a cluster on other machines must receive it: pickled whole, not as the handle of this machine's
    in-memory file that a job from ``share_job`` pickles as."""
    return dataclasses.replace(job) if shared_pickle.handle_of(job) is not None else job


def run_batch(job: BatchJob, takes: list[Path], out_dir: str | Path, *, names: list[str] | None = None,
              force: bool = False, workers: int | None = None, scheduler: str | None = None, retries: int = 2,
              progress: Callable[[BatchProgress], None] | None = None, cancel: Callable[[], bool] | None = None,
              dashboard_address: str = "127.0.0.1:8787") -> list[dict]:
    """Solve ``takes`` into ``out_dir/<name>/`` and write the summary; returns the rows in the order of ``takes``.
    Complete takes are skipped unless ``force``; the rest go to the cluster with the job scattered once
    (``solve_on_cluster``). A local cluster is run from a process forked from the fork server where it can be
    (``model.batch_driver``: this process then never imports Dask), else from this one.
    ``cancel()`` true stops the run (unfinished takes are failed rows, 'cancelled'); so does Ctrl-C (SIGINT:
    'interrupted'), after which the summary is written and KeyboardInterrupt raised again."""
    out_dir = Path(out_dir)
    check_output_folder(out_dir)           # before any take: the folder and its summary can be written
    for summary in (SUMMARY_JSON, SUMMARY_CSV):
        check_output_file(out_dir / summary)
    takes = [Path(t).resolve() for t in takes]
    names = names or take_names(takes)
    rows: list[dict | None] = [None] * len(takes)
    for i, (path, name) in enumerate(zip(takes, names)):
        if not force:
            rows[i] = completed_row(job, path, out_dir / name, name)
    pending = longest_first([i for i, r in enumerate(rows) if r is None], takes)
    check_caches_space(job, [takes[i] for i in pending], [out_dir / names[i] for i in pending], out_dir)
    started = time.time()
    done = len(takes) - len(pending)
    outcome = ClusterOutcome()
    if progress is not None and not pending:
        progress(BatchProgress(done, len(takes), 0, 0.0))
    if pending:
        out_dir.mkdir(parents=True, exist_ok=True)
        tasks = [(i, str(takes[i]), str(out_dir / names[i]), names[i]) for i in pending]
        options = dict(total=len(takes), done=done, preload=job.preload, workers=workers, retries=retries,
                       dashboard_address=dashboard_address)
        if not scheduler and batch_driver.available(job.preload):
            outcome = batch_driver.solve_in_driver(job, tasks, solve=solve_on_cluster, progress=progress,
                                                   cancel=cancel, **options)
        else:
            job = portable_job(job)
            outcome = solve_on_cluster(lambda: job, tasks, scheduler=scheduler, progress=progress,
                                       stop=lambda: "cancelled" if cancel is not None and cancel() else None,
                                       **options)
        for i, row in outcome.rows.items():
            rows[i] = row
    frames, stopped = outcome.frames, outcome.stopped or "cancelled"
    for i, r in enumerate(rows):
        if r is None:       # a take a worker finished after the last one this process heard of is complete on disk
            r = completed_row(job, takes[i], out_dir / names[i], names[i])
            if r is not None and (out_dir / names[i] / DONE).stat().st_mtime >= started:
                r["status"] = "solved"
                frames += int(r["frames"] or 0)
            rows[i] = r or _row(names[i], takes[i], None, "failed", f"{takes[i]}: {stopped} before it was solved.")
    out_dir.mkdir(parents=True, exist_ok=True)
    meta = {"rig": job.rig.name, "rig_units": job.rig.units, "settings": job.signature["settings"],
            "marker_map": job.marker_map.source if job.marker_map is not None else "automatic",
            **status_counts(rows), "seconds": outcome.seconds,
            "frames_per_second": frames / max(outcome.seconds, 1e-9) if frames else None,
            "dashboard": outcome.dashboard}
    write_summary(out_dir, rows, meta)
    if outcome.stopped == "interrupted":
        raise KeyboardInterrupt
    return rows
