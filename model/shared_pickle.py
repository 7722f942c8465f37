"""An object pickled once into a memory file that every process of this machine can map, its numpy arrays read in
place from the file instead of copied into each process: how a local batch's job (the rig, ~40 MB for ICT, 2.3 GB
of deltas for the 422k-vertex studio rig) reaches its driver and its workers (``model.batch_driver``).

``dump`` writes the object with pickle protocol 5 (PEP 574), its contiguous arrays as out-of-band buffers laid out
after the pickle stream, each on a 64-byte boundary; ``load`` maps the file copy-on-write (``MAP_PRIVATE``) and
unpickles the stream with views into the map as those buffers: the arrays share the file's pages (the page cache's
one copy for every process) and stay writeable, a write making a private copy of that page only. ``SharedObject``
is a handle to such a file held open by a process: pickled it is a few bytes; unpickled in another process of the
same user on this machine (Linux: through ``/proc/<pid>/fd/<fd>``) it is the object, mapped, which keeps the
handle as its attribute ``HANDLE_ATTRIBUTE`` so that it can be passed on as the handle again (Dask's broadcast hands
the scattered job from one worker to the next).

Layout: ``MAGIC``, the header's offset and length (two little-endian uint64), the pickle stream, the buffers, the
header (a pickled ``(stream length, [(offset, length) of each buffer])``).
"""
from __future__ import annotations

import mmap
import os
import pickle
import struct

MAGIC = b"BSSHARE1"
_PREFIX = struct.Struct("<8sQQ")
_ALIGN = 64


def _padding(offset: int) -> int:
    return -offset % _ALIGN


def dump(obj, f) -> int:
    """Write ``obj`` to the binary file ``f`` (at its start) in the layout ``load`` maps; returns the bytes written."""
    buffers: list[pickle.PickleBuffer] = []
    stream = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    offset = _PREFIX.size + len(stream)
    spans = []
    for b in buffers:
        offset += _padding(offset)
        n = b.raw().nbytes
        spans.append((offset, n))
        offset += n
    header = pickle.dumps((len(stream), spans), protocol=5)
    f.write(_PREFIX.pack(MAGIC, offset, len(header)))
    f.write(stream)
    written = _PREFIX.size + len(stream)
    for b, (start, n) in zip(buffers, spans):
        f.write(b"\0" * (start - written))
        f.write(b.raw())
        written = start + n
    f.write(header)
    return written + len(header)


def load(fd: int):
    """The object ``dump`` wrote to the file open as ``fd`` (the descriptor may be closed afterwards: the map keeps
    the file), its arrays views into a copy-on-write map of the file. ValueError for a file ``dump`` did not write."""
    size = os.fstat(fd).st_size
    if size < _PREFIX.size:
        raise ValueError("not a shared pickle (too short)")
    # pages are mapped as they are first read (16 at a time: Linux's fault-around; populating the whole map up front
    # took longer, and MAP_POPULATE on a copy-on-write map copies every page)
    mm = mmap.mmap(fd, size, access=mmap.ACCESS_COPY)
    view = memoryview(mm)
    magic, header_at, header_len = _PREFIX.unpack_from(mm, 0)
    if magic != MAGIC or header_at + header_len != size:
        raise ValueError("not a shared pickle (its header does not fit)")
    stream_len, spans = pickle.loads(view[header_at:header_at + header_len])
    buffers = [view[start:start + n] for start, n in spans]
    return pickle.loads(view[_PREFIX.size:_PREFIX.size + stream_len], buffers=buffers)


def descriptor_path(pid: int, fd: int) -> str:
    return f"/proc/{pid}/fd/{fd}"


def reachable(fd: int) -> bool:
    """Whether other processes of this user can open this process's descriptor ``fd`` by its ``/proc`` path (Linux;
    not where /proc is hidden or missing)."""
    try:
        os.close(os.open(descriptor_path(os.getpid(), fd), os.O_RDONLY))
    except OSError:
        return False
    return True


HANDLE_ATTRIBUTE = "_shared_handle"


def _open_shared(pid: int, fd: int):
    opened = os.open(descriptor_path(pid, fd), os.O_RDONLY)
    try:
        obj = load(opened)
    finally:
        os.close(opened)
    if hasattr(obj, "__dict__"):          # a class may pickle itself as its handle again (``model.batch.BatchJob``)
        obj.__dict__[HANDLE_ATTRIBUTE] = SharedObject(pid, fd)
    return obj


def memory_file(obj, name: str) -> int:
    """The descriptor of a new anonymous memory file ``name`` holding ``obj`` as ``dump`` writes it (Linux:
    ``os.memfd_create``); the caller closes it."""
    fd = os.memfd_create(name, os.MFD_CLOEXEC)
    try:
        with open(fd, "wb", closefd=False) as f:
            dump(obj, f)
    except BaseException:
        os.close(fd)
        raise
    return fd


def share(obj, name: str):
    """(``obj`` written to a new anonymous memory file and mapped back from it, its descriptor): the returned object
    reads its arrays from the file, so the caller can drop ``obj`` and keep the arrays in memory once, shared with
    every process that maps the file (``SharedObject``). The descriptor stays open for this process's life (the
    handle names it); the file lives as long as a process holds or maps it."""
    fd = memory_file(obj, name)
    try:       # where other processes can open it, it is passed on as its handle
        return (_open_shared(os.getpid(), fd) if reachable(fd) else load(fd)), fd
    except BaseException:
        os.close(fd)
        raise


def handle_of(obj) -> "SharedObject | None":
    """The handle of an object mapped from a shared file (``share``, ``SharedObject``), else None."""
    return getattr(obj, "__dict__", {}).get(HANDLE_ATTRIBUTE)


class SharedObject:
    """The object ``dump`` wrote to the file that process ``pid`` holds open as descriptor ``fd``, by reference:
    pickling it pickles the reference; unpickling it (in any process of this user on this machine, while ``pid``
    holds the file) maps the file and gives the object itself (``load``)."""

    def __init__(self, pid: int, fd: int) -> None:
        self.pid, self.fd = int(pid), int(fd)

    def __reduce__(self):
        return _open_shared, (self.pid, self.fd)

    def __repr__(self) -> str:
        return f"SharedObject(pid={self.pid}, fd={self.fd})"
