"""The file-I/O layer of all three packages (brdfmodels, scenes, hazard): atomic writes
(:func:`atomic_write`: a temporary file in the target folder, fsynced, then ``os.replace``;
the one write-then-rename of a single file), bounded input files (regular files of bounded
size, bounded nesting) and TOML reading with one clear error line. Sets of files replaced
as one unit (output folders, ``hazard fit``'s files): :mod:`brdfmodels.output_sets`.

Large new files written piece by piece and made durable, past the page cache where the
system allows (:class:`SyncedFile`, :func:`write_synced`): see the notes at
:data:`DIRECT_BUFFER_BYTES`.

Input limits (:data:`LIMITS`) protect against memory bombs and endless reads; each can be
raised with an environment variable ``HAZARD_MAX_<NAME>`` (e.g. ``HAZARD_MAX_OBSERVERS=2e6``),
and every error that hits a limit says so.
"""

from __future__ import annotations

import csv
import errno
import math
import mmap
import os
import re
import tempfile
import tomllib
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no O_DIRECT either
    fcntl = None  # type: ignore[assignment]

import numpy as np

__all__ = ["LIMITS", "LIMIT_CEILING", "DEPTH_CEILING", "limit", "check_limit", "check_input_file", "read_input_text",
           "toml_depth", "toml_depth_at", "data_depth", "parse_toml", "current_umask", "fsync_dir", "fsync_file",
           "atomic_write", "atomic_write_text", "SyncedFile", "write_synced", "DIRECT_BUFFER_BYTES", "read_toml",
           "read_csv_columns", "count_values"]

# name -> (default, what it bounds); HAZARD_MAX_<NAME> overrides the default
LIMITS = {
    "FILE_MB": (256, "size of an input file [MB]"),
    "SCENE_MB": (32, "size of a scene's TOML text [MB] (parsing takes about 0.8 s of CPU per MB)"),
    "DEPTH": (32, "nesting depth of arrays and tables in an input file"),
    "ARRAYS": (2_000_000, "arrays and tables of a TOML file ('[' and '{' counted before parsing; about 7 us and 0.3 kB each "
               "to parse: a 32 MB scene of arrays 32 deep took 110 s of CPU and 4.5 GB)"),
    "OBSERVERS": (1_000_000, "observer points of a scene"),
    "POINTS": (100_000, "explicit observer points (points_m): each is a feature of the map outputs"),
    "TARGETS": (100, "targets of a scene"),
    "RISK_EVALUATIONS": (1e8, "point evaluations of a risk analysis ((draws + sensitivity sets) x (points + map cells))"),
    "BEAM_SAMPLES": (65_536, "rays across the beam cross-section (analysis.beam_samples)"),
    "TIME_STEPS": (100_000, "time steps of a dynamic analysis (time_end_s / time_step_s)"),
    "OBSERVER_STEPS": (200_000_000, "observer points x time steps of a dynamic analysis (the flagship map is 1e8)"),
    "MOTION_SAMPLES": (2_000_000, "time samples of a moving path (the motion span / motion.time_step_s; a beam crossing's refinement)"),
    "TABLE_NODES": (2_000_000, "nodes of a BRDF table gridded from samples (grid_deg; a MERL table has 1.46e6)"),
    "KEEPOUT_CELLS": (10_000_000, "worst-case keep-out direction cells per lobe ((90/g) x (360/g) x 4^refine_levels; the finest "
                      "convergence levels make 8.3e6); about 0.5 kB each while a level is evaluated: 5e7 passed 9.3 GB"),
    "KEEPOUT_STATE_CELLS": (2e9, "worst-case keep-out cells x time steps of a dynamic lobe (each cell's maximum over the states)"),
    "SCENARIOS": (1_000, "scenarios of a study (each a whole run: 1.3 s of CPU for the small power_sweep example)"),
    "SAMPLES": (2_000_000, "pixels or samples read from a measurement file (each array of a screen test: a fit took about "
                "0.6 kB per value; 5e7, the limit before, passed 11.6 GB)"),
    "SCATTERED_SAMPLES": (200_000, "measured samples triangulated into a scattered BRDF table (1e5 took 35 s to build)"),
    "CSV_ROWS": (2_000_000, "lines of a CSV file read as columns (a history, pyrometer, oxidation or BRDF-angle table); "
                 "counted before parsing: a 250 MB history of 1e7 rows took past 4.4 GB"),
    "MESH_TRIANGLES": (1_000_000, "triangles of the mesh files of a scene (targets, occluders; at 3.2e5 in front of the beam: "
                       "run 18 s CPU, 0.8 GB)"),
    "TEXT_VALUES": (2_000_000, "numbers in a measured BRDF text file (.bsdf, ASTM), counted before parsing "
                    "(a 16 MB .bsdf of 4e6 values took 13 s of CPU and 2.5 GB)"),
    "FOOTPRINT_WORK": (4e9, "terrain nodes x beam samples x spots of the ground footprint (its near-field pairs at most; "
                       "range_geo at 5 m: 7.4e8)"),
    "WORK_CPU_S": (1200, "estimated CPU seconds of a run: spots x (observer points x time steps, keep-out cells, keep-out "
                   "cells x time steps, terrain nodes x beam samples, each times its measured cost; scenes.spec.WORK_S): "
                   "the products the single limits leave unbounded"),
    "TERRAIN_NODES": (2_000_000, "terrain grid nodes ((extent / resolution + 1)^2, or a height map's size; 16e6 took 43 s and 5 GB)"),
}
LIMIT_CEILING = 1e15  # a HAZARD_MAX_* value above this is refused (1e308 overflowed an integer conversion)
DEPTH_CEILING = 200  # nesting the parsers can follow (Python's recursion limit is 1000)


def limit(name: str) -> float:
    """The current value of limit ``name`` (environment ``HAZARD_MAX_<NAME>`` or the default)."""
    default = LIMITS[name][0]
    text = os.environ.get(f"HAZARD_MAX_{name}")
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"HAZARD_MAX_{name}={text!r}: expected a number") from None
    ceiling = DEPTH_CEILING if name == "DEPTH" else LIMIT_CEILING
    if not 0 < value <= ceiling:
        raise ValueError(f"HAZARD_MAX_{name}={text!r}: expected a positive number up to {ceiling:g}")
    return value


def check_limit(name: str, value, what: str) -> None:
    """ValueError naming ``what``, the limit and how to raise it when ``value`` exceeds it."""
    lim = limit(name)
    if not value <= lim:  # also catches nan
        shown = f"{value:.4g}" if isinstance(value, float) else f"{value}"
        raise ValueError(f"{what} = {shown} exceeds the limit {lim:g} ({LIMITS[name][1]}); "
                         f"if intended, raise it with the environment variable HAZARD_MAX_{name}")


def check_input_file(path, what: str | None = None) -> Path:
    """``path`` if it is a regular file within the size limit; ValueError otherwise
    (missing files, folders, devices such as /dev/zero, FIFOs, oversized files)."""
    import stat

    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read{' the ' + what if what else ''} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise ValueError(f"{path}: {kind}; expected a regular file{' (' + what + ')' if what else ''}")
    mb = st.st_size / 1e6
    if mb > limit("FILE_MB"):
        check_limit("FILE_MB", mb, f"{path}: size [MB]")
    return path


def read_input_text(path, what: str | None = None) -> str:
    """UTF-8 text of a bounded regular file; ValueError with one line otherwise."""
    path = check_input_file(path, what)
    try:
        with open(path, "rb") as fh:
            data = fh.read(int(limit("FILE_MB") * 1e6) + 1)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read{' the ' + what if what else ''} ({exc.strerror})") from None
    if len(data) > limit("FILE_MB") * 1e6:
        check_limit("FILE_MB", len(data) / 1e6, f"{path}: size [MB]")
    try:  # a leading byte-order mark (Excel's "CSV UTF-8", Notepad) is no content: the first keyword or column was misread
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def count_values(text: str, separators: str = " \t\r\n,;", *, block: int = 1 << 24) -> int:
    """Fields of ``text`` split at runs of ``separators`` (its numbers, for a table of
    numbers), counted in blocks of ``block`` characters without making a string of each
    (a reader that splits first spends about 0.6 kB per field before it can refuse)."""
    import numpy as np

    seps = np.frombuffer(separators.encode("ascii"), np.uint8)
    count, prev_sep = 0, True
    for lo in range(0, len(text), block):
        b = np.frombuffer(text[lo:lo + block].encode("utf-8", "replace"), np.uint8)
        if not len(b):
            continue
        sep = np.isin(b, seps)
        count += int(np.count_nonzero(~sep[1:] & sep[:-1])) + int(prev_sep and not sep[0])
        prev_sep = bool(sep[-1])
    return count


def toml_depth(text: str) -> int:
    """Deepest nesting of ``[`` / ``{`` in TOML values (strings and comments skipped;
    table headers do not count). Linear time, no recursion."""
    return toml_depth_at(text)[0]


def toml_depth_at(text: str) -> tuple[int, int]:
    """(deepest nesting of ``[`` / ``{`` in TOML values, the 1-based line where it is
    first reached; 0 without any): :func:`toml_depth` with the place, for the error."""
    depth = best = 0
    at = 0
    i, n = 0, len(text)
    line_start = True
    while i < n:
        c = text[i]
        if c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if c in "\"'":
            triple = text.startswith(c * 3, i)
            if triple:
                j = text.find(c * 3, i + 3)
                i = n if j < 0 else j + 3
                while i < n and text[i] == c:  # up to two quotes may close the string
                    i += 1
            else:
                j = i + 1
                while j < n and text[j] != c and text[j] != "\n":
                    j += 2 if (c == '"' and text[j] == "\\") else 1
                i = j + 1
            line_start = False
            continue
        if c == "\n":
            line_start = depth == 0
        elif c in " \t\r":
            pass
        elif c == "[" and line_start and depth == 0:
            # a table header [a] / [[a]]: skip to the end of the line
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "[{":
            depth += 1
            if depth > best:
                best, at = depth, i
            line_start = False
        elif c in "]}":
            depth = max(depth - 1, 0)
            line_start = False
        else:
            line_start = False
        i += 1
    return best, (text.count("\n", 0, at) + 1 if best else 0)


def data_depth(data) -> int:
    """Deepest nesting of dicts and lists in parsed data (iterative)."""
    best = 0
    stack = [(data, 0)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, dict):
            node = list(node.values())
        elif not isinstance(node, list):
            continue
        best = max(best, d + 1)
        stack.extend((v, d + 1) for v in node)
    return best


def parse_toml(text: str, source: str) -> dict:
    """Parse TOML text with bounded nesting and arrays; ValueError with one line naming ``source``."""
    check_limit("ARRAYS", text.count("[") + text.count("{"), f"{source}: arrays and tables ('[' and '{{' in the text)")
    depth, line = toml_depth_at(text)
    if depth > limit("DEPTH"):  # the line and its key, not its contents
        key = re.match(r"[ \t]*([A-Za-z0-9_.-]{1,64})[ \t]*=", text.split("\n", line)[line - 1][:300])  # a bare key only
        check_limit("DEPTH", depth, f"{source}: line {line}{f' (key {key[1]})' if key else ''}: nesting depth")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise ValueError(f"{source}: nesting too deep for the parser (at most {DEPTH_CEILING} levels)") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise ValueError(f"{source}: not valid TOML: {' '.join(str(exc).split()[:12])} (a number with too many digits?)") from None
    depth = data_depth(data)
    if depth > limit("DEPTH") + 1:  # tables add one level to the arrays counted above
        check_limit("DEPTH", depth, f"{source}: nesting depth")
    return data


def current_umask() -> int:
    """The process's file-mode creation mask, read without changing it where the system
    says it (Linux >= 4.7: ``/proc/self/status``); elsewhere set and put back at once
    (``os.umask`` has no read-only form), a moment in which another thread's new file
    would get the mask 0."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def fsync_dir(path) -> None:
    """Flush folder ``path``'s entries (a rename in it) to disk; a no-op where folders
    cannot be opened or synced (Windows, some network file systems)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def fsync_file(path) -> None:
    """Flush file ``path``'s data to disk (whatever wrote it: numpy, matplotlib, rasterio)."""
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())


def atomic_write(path, write, *, keep_suffix: bool = False) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, fsync it, then
    ``os.replace`` it into place (and fsync the folder): readers see the old file or the
    whole new one, never a part, also after a power cut. The file gets the usual
    permissions (0666 minus the umask). ``keep_suffix``: the temporary ends with ``.tmp``
    plus ``path``'s suffix (for writers that choose the format by it, matplotlib).
    The one write-then-rename of a file; a set of files or a folder of outputs:
    :mod:`brdfmodels.output_sets`.

    Parameters
    ----------
    path : str or Path
        The final file.
    write : callable
        ``write(tmp_path)`` writes the whole new content to ``tmp_path`` (a str).
    keep_suffix : bool
        End the temporary's name with ``path``'s suffix.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    suffix = ".tmp" + (path.suffix if keep_suffix else "")
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=folder)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~current_umask())
        fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    fsync_dir(folder)
    return path


def atomic_write_text(path, text: str) -> Path:
    """:func:`atomic_write` of a UTF-8 text."""

    def write(tmp):
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)

    return atomic_write(path, write)


# A new file written piece by piece and made durable (fsynced), past the page cache where it can.
#
# A run's large outputs (observers.csv: ~250 bytes an observer, 247 MB at 1e6) cost the kernel
# more than the text costs Python when they go through the page cache: every page of the file is
# a new page of memory, copied into and, on a virtual machine, first given by the host
# (``copy_folio_from_iter_atomic``: 0.07 s of system time for 247 MB when those pages were warm,
# 0.4-0.65 s when they were not; measured with ``perf record`` on this project's 2-core machine).
# With ``O_DIRECT`` the bytes go from one reused, page-aligned buffer to the disk: 0.01-0.02 s of
# system time, and the writer's thread waits for the disk without holding a core (0.14-0.20 s
# wall for 247 MB, while the other threads go on making text).
#
# ``O_DIRECT`` needs the buffer, the length and the file offset aligned to the disk's block: the
# buffer is an anonymous ``mmap`` (page-aligned), whole buffers are written while the file grows,
# and the last partial buffer is written with ``O_DIRECT`` switched off (``fcntl``). Where
# ``O_DIRECT`` is missing (not Linux) or refused (a file system without it: ``EINVAL``), the
# same bytes go through the page cache with write-back started every ``step`` bytes
# (:class:`_Flushed`). Either way the file is fsynced before :meth:`SyncedFile.close` returns.

# the aligned buffer: 8 MiB (a whole number of every disk block size), written at once when full
DIRECT_BUFFER_BYTES = 8 << 20


class _Flushed:
    """Write-back of a file being written started every ``step`` bytes
    (``posix_fadvise(DONTNEED)``: the kernel starts writing the dirty pages out without
    waiting for them, and drops them from the cache once clean), so that the fsync at the
    end waits for the last part only (0.11-0.13 -> 0.03 s for 247 MB) and the cache holds no
    more of the file than it must. The fsync still makes the whole file durable; without
    ``posix_fadvise`` (not Linux) nothing is done here."""

    def __init__(self, fd: int, step: int = 32 << 20):
        self.fd, self.step, self.done, self.written = fd, step, 0, 0
        self.advise = getattr(os, "posix_fadvise", None)

    def wrote(self, n: int) -> None:
        self.written += n
        if self.advise is not None and self.written - self.done >= self.step:
            self.advise(self.fd, self.done, self.written - self.done, os.POSIX_FADV_DONTNEED)
            self.done = self.written


def _write_all(fd: int, data) -> None:
    """``os.write`` until every byte of ``data`` (a bytes-like object) is written."""
    view = memoryview(data).cast("B")
    while len(view):
        view = view[os.write(fd, view):]


class SyncedFile:
    """A new file at ``path`` (created or truncated), written by :meth:`write` and made
    durable by :meth:`close` (fsync). ``direct``: try ``O_DIRECT`` (module docstring); false,
    every byte goes through the page cache. :attr:`direct` says which way the file went."""

    def __init__(self, path, direct: bool = True):
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)
        want = direct and hasattr(os, "O_DIRECT") and fcntl is not None
        self.fd = _open(path, flags, os.O_DIRECT if want else 0)
        self.direct = want and bool(fcntl.fcntl(self.fd, fcntl.F_GETFL) & os.O_DIRECT)
        self.buffer = mmap.mmap(-1, DIRECT_BUFFER_BYTES) if self.direct else None
        self._bytes = None if self.buffer is None else np.frombuffer(self.buffer, np.uint8)  # numpy copies without the GIL
        self.held = 0  # bytes in the buffer not yet written
        self.flushed = _Flushed(self.fd)

    def write(self, data) -> None:
        """Append ``data`` (a bytes-like object) to the file."""
        view, size = memoryview(data).cast("B"), DIRECT_BUFFER_BYTES
        while len(view) and self.direct:  # into the aligned buffer, written whenever it is full
            n = min(size - self.held, len(view))
            self._bytes[self.held:self.held + n] = np.frombuffer(view[:n], np.uint8)
            self.held, view = self.held + n, view[n:]
            if self.held == size:
                self._write_buffer()
        if len(view):  # through the page cache (O_DIRECT not taken, or refused on the way)
            _write_all(self.fd, view)
            self.flushed.wrote(len(view))

    def _write_buffer(self) -> None:
        """The full buffer to the disk with ``O_DIRECT``; refused (``EINVAL``: an alignment
        the disk does not take), the rest of it and of the file through the page cache."""
        view = memoryview(self.buffer)
        try:
            while len(view):
                view = view[os.write(self.fd, view):]
        except OSError as exc:
            if exc.errno != errno.EINVAL:
                raise
            self._buffered()
            _write_all(self.fd, view)  # what O_DIRECT had not written of the buffer
        finally:
            view.release()
        self.held = 0

    def _buffered(self) -> None:
        """Switch ``O_DIRECT`` off: the rest goes through the page cache."""
        fcntl.fcntl(self.fd, fcntl.F_SETFL, fcntl.fcntl(self.fd, fcntl.F_GETFL) & ~os.O_DIRECT)
        self.direct = False

    def close(self) -> None:
        """Write what the buffer holds, fsync the file and close it."""
        try:
            if self.buffer is not None:
                if self.held:
                    if self.direct:
                        self._buffered()  # the last, partial block is not aligned
                    _write_all(self.fd, memoryview(self.buffer)[:self.held])
                self._release()
            os.fsync(self.fd)
        finally:
            os.close(self.fd)

    def abandon(self) -> None:
        """Close without syncing (the file is being discarded)."""
        if self.buffer is not None:
            self._release()
        os.close(self.fd)

    def _release(self) -> None:
        """Unmap the aligned buffer (its numpy view first: an exported buffer cannot close)."""
        self._bytes = None
        self.buffer.close()
        self.buffer = None


def _open(path, flags: int, direct: int) -> int:
    """``os.open`` with ``direct`` added to ``flags``; refused for it (``EINVAL``), without."""
    if direct:
        try:
            return os.open(path, flags | direct, 0o666)
        except OSError as exc:
            if exc.errno != errno.EINVAL:
                raise
    return os.open(path, flags, 0o666)


def write_synced(path, data, direct: bool = True, stop=None) -> None:
    """Write ``data`` (bytes-like, or an iterable of bytes-like pieces one after another) to a
    new file at ``path`` and fsync it (:class:`SyncedFile`). ``stop`` (a
    :class:`threading.Event`, or None): set, the writing ends before the next piece and the
    file is closed unsynced (its caller discards it); so does an error."""
    out = SyncedFile(path, direct=direct)
    try:
        for piece in [data] if isinstance(data, (bytes, bytearray, memoryview)) else data:
            if stop is not None and stop.is_set():
                out.abandon()
                return
            out.write(piece)
    except BaseException:
        out.abandon()
        raise
    out.close()


def read_toml(path) -> dict:
    """Parse a TOML file; ValueError naming the file on a read or syntax error."""
    path = Path(path)
    return parse_toml(read_input_text(path), str(path))


def read_csv_columns(path, columns, what: str = "CSV file") -> dict:
    """Named numeric columns of a CSV file whose first line names them: ``{name: (N,) array}``
    for each of ``columns`` (others ignored). Every error is one line naming the file, the
    line and the column and what was expected; nothing of the file is quoted (an empty
    file, a missing column, a short row, a cell that is not a finite number, no rows)."""
    path = Path(path)
    text = read_input_text(path, what)
    check_limit("CSV_ROWS", text.count("\n") + 1, f"{path}: lines")  # before any row is parsed (FILE_MB alone allowed 4 GB)
    lines = text.splitlines()
    start = next((k for k, ln in enumerate(lines) if ln.strip()), None)
    if start is None:
        raise ValueError(f"{path}: empty file; expected a header line naming the columns {', '.join(columns)}")
    names = [c.strip() for c in next(csv.reader([lines[start]]))]
    missing = [c for c in columns if c not in names]
    if missing:
        raise ValueError(f"{path}: line {start + 1}: expected CSV columns {', '.join(columns)}; missing {', '.join(missing)} "
                         f"(the header has {len(names)} column(s))")
    twice = [c for c in columns if names.count(c) > 1]
    if twice:
        raise ValueError(f"{path}: line {start + 1}: column {twice[0]} appears {names.count(twice[0])} times; expected once")
    rows = [(k + 1, r) for k, r in enumerate(csv.reader(lines[start + 1:]), start=start + 1) if any(x.strip() for x in r)]
    if not rows:
        raise ValueError(f"{path}: no data rows after the header (line {start + 1})")
    short = next(((no, r) for no, r in rows if len(r) != len(names)), None)
    if short is not None:
        raise ValueError(f"{path}: line {short[0]}: {len(short[1])} cells, expected {len(names)} (one per header column)")
    out = {}
    for c in columns:
        j = names.index(c)
        try:
            v = np.array([r[j] for _, r in rows], dtype=float)
        except ValueError:
            v = None
        if v is None or not np.all(np.isfinite(v)):
            bad = next(no for no, r in rows if not _finite_text(r[j]))
            raise ValueError(f"{path}: line {bad}, column {j + 1} ({c}): expected a finite number")
        out[c] = v
    return out


def _finite_text(text) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False
