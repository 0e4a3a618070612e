"""brdfmodels.fileio.atomic_write: the one write-then-rename of a single file.

The order that makes it survive a power cut, watched through the system calls: the whole
temporary (beside the file) is fsynced before ``os.replace`` moves it over the file, and
the folder is fsynced after, so the rename itself is on disk. Linux only for the fd names
(``/proc/self/fd``)."""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

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
