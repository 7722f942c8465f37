"""PC2 point caches (the Blender / Maya / 3ds Max point-cache format), written atomically and streamed.

Layout (little-endian): ``b'POINTCACHE2\\0'`` (12 bytes), int32 version (1), int32 numPoints, float32
startFrame, float32 sampleRate, int32 numSamples, then float32 samples × points × 3. ``sampleRate`` is the
frame step between samples (1.0 = every frame), as Blender and Max write it.
"""
from __future__ import annotations

import struct
from pathlib import Path
from typing import Iterable

import numpy as np

from .atomic import atomic_write_with
from .errors import RigInputError
from .input_files import regular_file

MAGIC = b"POINTCACHE2\0"
HEADER = struct.Struct("<12siiffi")


def pc2_size(n_frames: int, n_points: int) -> int:
    """Bytes of a PC2 file of ``n_frames`` samples of ``n_points`` points (known before writing it)."""
    return HEADER.size + int(n_frames) * int(n_points) * 12


def check_room_for_pc2(path: str | Path, n_frames: int, n_points: int) -> None:
    """Refuse, before any frame is made, a PC2 of ``n_frames`` x ``n_points`` its disk has no room for
    (``model.free_space``): the command line's caches and the window's PC2 exports alike."""
    from .free_space import check_free_space
    check_free_space({path: pc2_size(n_frames, n_points)})


def write_pc2(path: str | Path, frames: np.ndarray | Iterable[np.ndarray], *, n_points: int | None = None,
              start_frame: float = 0.0, sample_rate: float = 1.0) -> int:
    """Write frames (F, N, 3) — an array, or any iterable of (N, 3) arrays for long takes, streamed one frame
    at a time — to a PC2 file atomically (a crash mid-write leaves any previous file intact).
    Returns the number of samples written."""
    writer, count = pc2_writer(path, frames, n_points=n_points, start_frame=start_frame, sample_rate=sample_rate)
    atomic_write_with(path, writer)
    return count[0]


def pc2_writer(path: str | Path, frames, *, n_points: int | None = None, start_frame: float = 0.0,
               sample_rate: float = 1.0):
    """(writer(file), count): what ``write_pc2`` writes, for ``model.output_set.write_set``; ``count[0]`` is the
    number of samples once the writer has run. ``frames``: an (F, N, 3) array, or an iterable of (N, 3) frames
    or of (n, N, 3) blocks of frames (written whole)."""
    if isinstance(frames, np.ndarray):
        if frames.ndim != 3 or frames.shape[2] != 3:
            raise RigInputError(f"{path}: a point cache needs frames of shape (F, N, 3), not {frames.shape}.")
        n_points = frames.shape[1] if n_points is None else n_points
    count = [0]

    def writer(f):
        f.write(HEADER.pack(MAGIC, 1, int(n_points or 0), float(start_frame), float(sample_rate), 0))
        npts = n_points
        blocks = (frames[i:i + 64] for i in range(0, frames.shape[0], 64)) if isinstance(frames, np.ndarray) \
            else frames
        for block in blocks:
            a = np.asarray(block, dtype="<f4")
            shown = a.shape
            a = a[None] if a.ndim == 2 else a
            if npts is None and a.ndim == 3:
                npts = a.shape[1]
            if a.ndim != 3 or a.shape[1:] != (npts, 3):
                raise RigInputError(f"{path}: frame {count[0]} has shape {shown[-2:] if len(shown) == 3 else shown}, "
                                    f"expected ({npts}, 3).")
            bad = ~np.isfinite(a).reshape(a.shape[0], -1).all(axis=1)
            if bad.any():
                raise RigInputError(f"{path}: frame {count[0] + int(np.argmax(bad))} has NaN or infinite coordinates.")
            f.write(np.ascontiguousarray(a).data)
            count[0] += a.shape[0]
        if npts is None:
            raise RigInputError(f"{path}: no frames to write and no point count given.")
        f.seek(0)
        f.write(HEADER.pack(MAGIC, 1, int(npts), float(start_frame), float(sample_rate), count[0]))
        f.seek(0, 2)

    return writer, count


def read_pc2_header(path: str | Path) -> dict:
    """{"n_points", "start_frame", "sample_rate", "n_samples"} of a PC2 file (validated against its size)."""
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(HEADER.size)
    if len(head) < HEADER.size:
        raise RigInputError(f"{path}: is too short to be a PC2 point cache.")
    magic, version, n_points, start, rate, n_samples = HEADER.unpack(head)
    if magic != MAGIC:
        raise RigInputError(f"{path}: is not a PC2 point cache (no POINTCACHE2 signature).")
    if version != 1 or n_points < 0 or n_samples < 0:
        raise RigInputError(f"{path}: has an unsupported or corrupt PC2 header (version {version}).")
    expected = HEADER.size + 12 * n_points * n_samples
    if size < expected:
        raise RigInputError(f"{path}: is truncated ({size} bytes, the header promises {expected}).")
    return {"n_points": n_points, "start_frame": start, "sample_rate": rate, "n_samples": n_samples}


def read_pc2(path: str | Path, *, mmap: bool = False) -> tuple[np.ndarray, float, float]:
    """(frames (F, N, 3) float32, start_frame, sample_rate) of a PC2 file; ``mmap`` maps it read-only."""
    h = read_pc2_header(path)
    shape = (h["n_samples"], h["n_points"], 3)
    if mmap:
        data = np.memmap(path, dtype="<f4", mode="r", offset=HEADER.size, shape=shape)
    else:
        data = np.fromfile(path, dtype="<f4", count=int(np.prod(shape)), offset=HEADER.size).reshape(shape)
    return data, h["start_frame"], h["sample_rate"]
