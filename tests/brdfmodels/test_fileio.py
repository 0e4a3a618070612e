"""brdfmodels.fileio.atomic_write: the one write-then-rename of a single file.

The order that makes it survive a power cut, watched through the system calls: the whole
temporary (beside the file) is fsynced before ``os.replace`` moves it over the file, and
the folder is fsynced after, so the rename itself is on disk. Linux only for the fd names
(``/proc/self/fd``)."""

from __future__ import annotations

import errno
import os
import stat
import sys
from pathlib import Path

import numpy as np
import pytest

from brdfmodels import fileio


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="names fsynced descriptors through /proc/self/fd")
def test_temporary_synced_then_replaced_then_folder_synced(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", str(src), str(dst), Path(src).read_text(encoding="utf-8")))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    final = tmp_path / "report.txt"
    final.write_text("old", encoding="utf-8")
    fileio.atomic_write_text(final, "new text")
    assert [e[0] for e in events] == ["fsync", "replace", "fsync"]
    tmp = events[0][1]
    assert Path(tmp).parent == tmp_path and Path(tmp).name.startswith(".report.txt.")  # beside the file
    assert events[1][1:] == (tmp, str(final), "new text")  # the whole content before the rename
    assert events[2][1] == str(tmp_path)  # the folder holding the rename
    assert final.read_text(encoding="utf-8") == "new text"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.txt"]  # no temporary left


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    final = tmp_path / "model.json"
    final.write_text("old", encoding="utf-8")

    def write(tmp):
        Path(tmp).write_text("half", encoding="utf-8")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        fileio.atomic_write(final, write)
    assert final.read_text(encoding="utf-8") == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]


def test_new_file_gets_the_usual_permissions_and_keeps_its_suffix(tmp_path):
    mask = os.umask(0o022)
    try:
        seen = []
        fileio.atomic_write(tmp_path / "plot.png", lambda tmp: (seen.append(tmp), Path(tmp).write_bytes(b"png")),
                            keep_suffix=True)
    finally:
        os.umask(mask)
    assert seen[0].endswith(".tmp.png")  # writers that choose the format by the suffix (matplotlib)
    assert stat.S_IMODE((tmp_path / "plot.png").stat().st_mode) == 0o644  # 0666 minus the umask, not mkstemp's 0600


# --- SyncedFile / write_synced: large files past the page cache (O_DIRECT), the same bytes either way ---

SMALL_BUFFER = 3 * 4096  # a whole number of every disk block size, so that a test crosses many buffers quickly


def _pieces(sizes, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in sizes]


PIECE_SIZES = {
    "empty file": [],
    "one byte": [1],
    "empty pieces between": [0, 5, 0, 4096, 0],
    "exactly one buffer": [SMALL_BUFFER],
    "exactly two buffers in odd pieces": [7, SMALL_BUFFER - 7, 1000, SMALL_BUFFER - 1000],
    "one piece of many buffers and a tail": [5 * SMALL_BUFFER + 513],
    "many small pieces across buffers": [97] * 1000,
}


@pytest.mark.parametrize("direct", [True, False])
@pytest.mark.parametrize("sizes", list(PIECE_SIZES.values()), ids=list(PIECE_SIZES))
def test_synced_file_writes_every_byte_in_order(tmp_path, monkeypatch, sizes, direct):
    """Whatever the pieces' sizes against the aligned buffer (none, smaller, exactly one
    buffer, many buffers in one piece, an unaligned tail), the file holds exactly the
    pieces one after another, through O_DIRECT or the page cache; bytes-like pieces of any
    kind (bytes, bytearray, memoryview, a numpy array's buffer) are taken."""
    monkeypatch.setattr(fileio, "DIRECT_BUFFER_BYTES", SMALL_BUFFER)
    pieces = _pieces(sizes)
    kinds = [bytes, bytearray, memoryview, lambda b: np.frombuffer(b, np.uint8)]
    path = tmp_path / "table.csv"
    fileio.write_synced(path, (kinds[k % 4](p) for k, p in enumerate(pieces)), direct=direct)
    assert path.read_bytes() == b"".join(pieces)
    fileio.write_synced(path, b"shorter")  # an existing file is truncated
    assert path.read_bytes() == b"shorter"


@pytest.mark.skipif(not hasattr(os, "O_DIRECT"), reason="no O_DIRECT on this system")
def test_synced_file_goes_past_the_page_cache_and_syncs_before_close(tmp_path, monkeypatch):
    """Where the file system takes O_DIRECT, whole aligned buffers are written with it and
    the last, partial one without (the flag switched off); the file is fsynced before
    close returns and the descriptor is closed."""
    monkeypatch.setattr(fileio, "DIRECT_BUFFER_BYTES", SMALL_BUFFER)
    writes, syncs = [], []
    real_write, real_fsync = os.write, os.fsync

    def write(fd, data):
        writes.append((bool(fcntl_flags(fd) & os.O_DIRECT), memoryview(data).nbytes))
        return real_write(fd, data)

    def fsync(fd):
        syncs.append(fd)
        return real_fsync(fd)

    monkeypatch.setattr(os, "write", write)
    monkeypatch.setattr(os, "fsync", fsync)
    out = fileio.SyncedFile(tmp_path / "t.bin")
    if not out.direct:
        out.abandon()
        pytest.skip(f"the file system of {tmp_path} refuses O_DIRECT")
    out.write(b"x" * (2 * SMALL_BUFFER + 100))
    out.close()
    assert writes == [(True, SMALL_BUFFER), (True, SMALL_BUFFER), (False, 100)]
    assert syncs == [out.fd]
    with pytest.raises(OSError):
        os.fstat(out.fd)  # closed
    assert (tmp_path / "t.bin").read_bytes() == b"x" * (2 * SMALL_BUFFER + 100)


def fcntl_flags(fd: int) -> int:
    import fcntl

    return fcntl.fcntl(fd, fcntl.F_GETFL)


@pytest.mark.skipif(not hasattr(os, "O_DIRECT"), reason="no O_DIRECT on this system")
@pytest.mark.parametrize("refused", ["open", "write"])
def test_synced_file_refused_direct_falls_back_to_the_page_cache(tmp_path, monkeypatch, refused):
    """A file system that refuses O_DIRECT (EINVAL at open, as tmpfs did before Linux 6.6,
    or at the first aligned write, a block size the buffer does not meet) gets the same
    bytes through the page cache; any other error is raised."""
    monkeypatch.setattr(fileio, "DIRECT_BUFFER_BYTES", SMALL_BUFFER)
    real_open, real_write = os.open, os.write

    def open_(path, flags, mode=0o777):
        if refused == "open" and flags & os.O_DIRECT:
            raise OSError(errno.EINVAL, "Invalid argument")
        return real_open(path, flags, mode)

    def write(fd, data):
        if refused == "write" and fcntl_flags(fd) & os.O_DIRECT:
            raise OSError(errno.EINVAL, "Invalid argument")
        return real_write(fd, data)

    monkeypatch.setattr(os, "open", open_)
    monkeypatch.setattr(os, "write", write)
    pieces = _pieces([SMALL_BUFFER + 11, 3 * SMALL_BUFFER, 5], seed=1)
    fileio.write_synced(tmp_path / "t.bin", pieces)
    assert (tmp_path / "t.bin").read_bytes() == b"".join(pieces)

    def broken(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "write", broken)
    with pytest.raises(OSError, match="No space left"):
        fileio.write_synced(tmp_path / "u.bin", pieces)


def test_synced_file_error_in_the_pieces_closes_the_file(tmp_path):
    """An error while the pieces are made goes on, and the file's descriptor is closed
    (the caller discards the staging folder holding it)."""
    before = len(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else None

    def pieces():
        yield b"a" * 10_000
        raise RuntimeError("the table failed")

    with pytest.raises(RuntimeError, match="the table failed"):
        fileio.write_synced(tmp_path / "t.bin", pieces())
    if before is not None:
        assert len(os.listdir("/proc/self/fd")) == before


def test_synced_file_stopped_ends_before_the_next_piece_unsynced(tmp_path, monkeypatch):
    """``stop`` set (a failed run: its staging folder is discarded), the writing ends before
    the next piece, with no fsync of the part written and the descriptor closed."""
    import threading

    syncs = []
    monkeypatch.setattr(os, "fsync", lambda fd: syncs.append(fd))
    stop, made = threading.Event(), []

    def pieces():
        for k in range(5):
            made.append(k)
            if k == 2:
                stop.set()
            yield bytes([65 + k]) * 3

    fileio.write_synced(tmp_path / "t.bin", pieces(), direct=False, stop=stop)
    assert made == [0, 1, 2] and syncs == []
    assert (tmp_path / "t.bin").read_bytes() == b"AAABBB"
