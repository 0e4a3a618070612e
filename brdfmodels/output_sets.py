"""Sets of output files replaced as one unit (a folder: :class:`OutputUnit`; files at
separate paths: :class:`FileSet`): the one helper every command writes through. A single
file: :func:`brdfmodels.fileio.atomic_write`.

A command writes its whole set of files into a staging folder ``.OUT.<pid>.<token>.tmp``
beside the output folder ``OUT``; :meth:`OutputUnit.commit` then switches it in:

* ``OUT`` absent: one rename (``tmp -> OUT``);
* ``OUT`` present: ``OUT -> .OUT.<pid>.<token>.old``, ``tmp -> OUT``, the old folder removed.

Before the switch, everything in ``OUT`` that the new set does not replace is carried into
the staging folder as hard links (the same files, never copied or rewritten): the files
of the tool's other commands (``hazard render`` pictures in a ``hazard run`` folder),
working folders (``.risk/``, ``scenarios/``), and, with ``force``, files the tool did not
write. Only the command's own previous outputs that it does not write again are dropped.

A crash can leave ``.OUT.*.tmp`` (a set never switched in) and ``.OUT.*.old`` (between the
two renames, or before the old folder was removed). :func:`recover` runs before every
unit and puts the folder back: when ``OUT`` is missing it renames the newest ``.old`` back
(the old complete set), then removes the stale ``.tmp``/``.old`` folders of dead
processes. A reader that finds ``OUT`` missing beside an ``.OUT.*.old`` folder may rename
that folder back itself: it is the previous complete set. ``OUT`` therefore always holds
the old complete set or the new one, never a mix and never nothing once recovered.

``OUT/.laser-hazard.json`` (the manifest) lists which command wrote each file; a folder
with files not listed there is refused unless ``force``. After a commit, :attr:`OutputUnit.kept`
names what stayed that this command did not write (other commands' files, and files not in
the manifest, kept as they were) and :attr:`OutputUnit.replaced_foreign` the files not in
the manifest that a new output of the same name replaced, so a command can say both.

A command may name its input (``source``, e.g. a digest of the scene file); the manifest
keeps each command's source. Another command's files made from a different source (the
pictures of ``hazard render`` of scene A beside a run of scene B) are never mixed in
silently: without ``force`` the folder is refused, with ``force`` they are dropped with
the command's own stale files and listed in :attr:`OutputUnit.dropped_stale`.
"""

from __future__ import annotations

import glob
import json
import os
import re
import secrets
import shutil
from contextlib import contextmanager
from pathlib import Path

from .fileio import current_umask, fsync_dir, fsync_file

__all__ = ["MANIFEST", "OutputUnit", "output_unit", "recover", "read_manifest", "read_sources", "OutputFolderError",
           "FileSet", "output_files"]

MANIFEST = ".laser-hazard.json"
_ACTIVE: set = set()  # staging folders of this process still being written
_ACTIVE_FILES: set = set()  # FileSet temporaries of this process still being written


class OutputFolderError(ValueError):
    """The output folder cannot take the outputs (foreign files, outputs without --force)."""


def _step(name: str) -> None:
    """A no-op between the steps of a switch; fault-injection tests replace it to raise."""


def _pattern(name: str):
    return re.compile(r"^\." + re.escape(name) + r"\.(\d+)\.([0-9a-f]{16})\.(tmp|old)$")


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return False  # this process' leftovers of a failed unit (its live ones are in _ACTIVE)
    if os.name == "nt":
        return True  # os.kill would end the process there: another pid's folders are left alone
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _target(out) -> Path:
    given = out
    out = Path(os.path.abspath(out))
    if out.is_symlink():  # switch the folder the link points to; the link stays valid
        out = Path(os.path.realpath(out))
    cwd = Path(os.path.realpath(os.getcwd()))
    if not out.name or Path(os.path.realpath(out)) in (cwd, *cwd.parents):
        raise OutputFolderError(f"-o {given}: the current folder (or one holding it) cannot be replaced as one unit; "
                                "expected a folder for the outputs, e.g. -o out")
    return out


def recover(out) -> list:
    """Put ``out`` back to a complete set after a crash; returns lines saying what was done.

    ``out`` missing beside a stale ``.out.*.old`` folder: the newest one is renamed back
    (the old complete set). Stale staging (``.tmp``) and old (``.old``) folders of
    processes no longer running are then removed. Nothing else is touched."""
    out = _target(out)
    parent = out.parent
    if not parent.is_dir():
        return []
    pat, said = _pattern(out.name), []
    stale = {"tmp": [], "old": []}
    for e in os.listdir(parent):
        m = pat.match(e)
        p = parent / e
        if m and p.is_dir() and not p.is_symlink() and p not in _ACTIVE and not _alive(int(m.group(1))):
            stale[m.group(3)].append(p)
    said += _legacy(out)
    olds = sorted(stale["old"], key=lambda p: p.stat().st_mtime)
    if olds and not os.path.lexists(out):
        os.rename(olds.pop(), out)  # crash between the two renames: the old set comes back
        said.append(f"{out}: restored the previous outputs after an interrupted switch")
    for p in olds + stale["tmp"]:
        shutil.rmtree(p, ignore_errors=True)
        said.append(f"{out}: removed the stale {p.name}")
    if said:
        fsync_dir(parent)
    return said


def _legacy(out: Path) -> list:
    """Put back / remove the leftovers of laser-hazard before 2026-11 (``tempfile.mkdtemp``
    names ``.OUT.<8 chars>.tmp`` holding only files, ``.OUT.<8 chars>.old`` holding only the
    old folder ``d``); anything else of that name is left alone."""
    pat, said = re.compile(r"^\." + re.escape(out.name) + r"\.[a-z0-9_]{8}\.(tmp|old)$"), []
    for e in sorted(os.listdir(out.parent)):
        m, p = pat.match(e), out.parent / e
        if not m or p.is_symlink() or not p.is_dir():
            continue
        inside = os.listdir(p)
        if m.group(1) == "tmp" and all((p / n).is_file() and not (p / n).is_symlink() for n in inside):
            shutil.rmtree(p, ignore_errors=True)
            said.append(f"{out}: removed the stale {e}")
        elif m.group(1) == "old" and set(inside) <= {"d"}:
            if inside and not os.path.lexists(out):
                os.rename(p / "d", out)
                said.append(f"{out}: restored the previous outputs after an interrupted switch")
            shutil.rmtree(p, ignore_errors=True)
            said.append(f"{out}: removed the stale {e}")
    return said


def read_sources(out: Path) -> dict:
    """command -> the source (input digest) its files in ``out`` were made from ({} when none)."""
    try:
        doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
        sources = doc.get("sources", {})
        return {str(k): str(v) for k, v in sources.items()} if isinstance(sources, dict) else {}
    except (OSError, ValueError, TypeError, AttributeError):
        return {}


def read_manifest(out: Path) -> dict:
    """name -> command that wrote it, from ``out``'s manifest ({} when none or unreadable)."""
    try:
        doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
        files = doc["files"]
        return {str(k): str(v) for k, v in files.items()} if isinstance(files, dict) else {}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst)
    except OSError:  # a file system without hard links: a copy (the original is still not touched)
        shutil.copy2(src, dst)


def _link_copy(src: Path, dst: Path) -> None:
    """``dst`` as hard links of ``src`` (a file, a symlink or a folder tree; copies where
    the file system has no hard links)."""
    if src.is_symlink():
        os.symlink(os.readlink(src), dst)
    elif src.is_dir():
        shutil.copytree(src, dst, symlinks=True, copy_function=_link_or_copy)
    else:
        _link_or_copy(src, dst)


class OutputUnit:
    """A set of output files staged in :attr:`stage`, switched into :attr:`out` by
    :meth:`commit` (see the module docstring).

    Parameters
    ----------
    out : str or Path
        The output folder (created if needed; a symlink to a folder switches that folder).
    command : str
        The command writing (``"run"``, ``"risk"``, ...): its previous files in ``out``
        are replaced, other commands' files are kept.
    overwrite : bool
        Allow replacing this command's previous outputs; otherwise an ``OutputFolderError``.
    force : bool
        Accept files in ``out`` the tool did not write (kept as they are, never deleted;
        a file of the same name as a new output is replaced).
    working : tuple of str
        Names in ``out`` the command keeps across runs (checkpoints such as ``.risk``):
        carried into the new set.
    claims : tuple of str
        In a folder without a manifest (written before manifests existed), these exact
        names count as this command's previous outputs: replaced, or dropped when not
        written again (a stale picture never stays beside a new report).
    source : str, optional
        What the outputs are made from (a digest of the scene file): another command's
        files recorded with a different source are stale beside the new set (refused
        without ``force``, dropped with it).
    """

    def __init__(self, out, *, command: str, overwrite: bool = False, force: bool = False, working=(), claims=(),
                 source: str | None = None):
        self.out, self.given = _target(out), Path(out)
        self.command, self.working = command, tuple(working)
        if os.path.lexists(self.out) and not self.out.is_dir():
            raise OutputFolderError(f"{self.out}: exists and is not a folder")
        self.notes = recover(self.out)
        self.owners = read_manifest(self.out) if self.out.is_dir() else {}
        self.sources, self.source = (read_sources(self.out) if self.out.is_dir() else {}), source
        if self.out.is_dir() and not (self.out / MANIFEST).exists():
            self.owners = {n: command for n in claims if (self.out / n).is_file()}
        try:
            self._check(overwrite, force)
        except OutputFolderError as exc:  # say what recovery did before the refusal
            raise OutputFolderError("; ".join([*self.notes, str(exc)])) from None
        parent = self.out.parent
        parent.mkdir(parents=True, exist_ok=True)
        self.stage = parent / f".{self.out.name}.{os.getpid()}.{secrets.token_hex(8)}.tmp"
        self.stage.mkdir()
        _ACTIVE.add(self.stage)
        self._carried: set = set()
        self.dropped_stale: list = self._stale()  # other commands' files made from another source: not carried
        self.kept: dict = {}  # after commit: name -> command that wrote it ("" not in the manifest), kept as it was
        self.replaced_foreign: list = []  # after commit: names not in the manifest replaced by a new output

    def _present(self) -> list:
        return sorted(os.listdir(self.out)) if self.out.is_dir() else []

    def _stale(self) -> list:
        """Names of other commands' files whose recorded source differs from this unit's."""
        if self.source is None:
            return []
        return sorted(n for n in self._present() if self.owners.get(n, self.command) != self.command
                      and self.sources.get(self.owners[n], self.source) != self.source)

    def _check(self, overwrite: bool, force: bool) -> None:
        stale = self._stale()
        if stale and not force:
            by = {}
            for n in stale:
                by.setdefault(self.owners[n], []).append(n)
            what = " and ".join(f"hazard {c} ({', '.join(ns[:5])}{' ...' if len(ns) > 5 else ''})" for c, ns in sorted(by.items()))
            raise OutputFolderError(f"{self.out} holds files of {what} made from another input: pass --force to replace "
                                    "them with this set, or choose another folder")
        names = [n for n in self._present() if n != MANIFEST and n not in self.working]
        foreign = [n for n in names if n not in self.owners]
        own = [n for n in names if self.owners.get(n) == self.command]
        if foreign and not force:
            shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
            raise OutputFolderError(f"{self.out} holds files hazard did not write ({shown}): choose another folder, or pass "
                                    "--force (they are kept as they are; only files of the same names as the outputs are replaced)")
        if own and not overwrite:
            raise OutputFolderError(f"{self.out / own[0]} exists: pass --force to overwrite")

    def final(self, path) -> Path:
        """Where ``path`` (in :attr:`stage`) will be once committed, under the folder as given."""
        path = Path(path)
        try:
            return self.given / path.relative_to(self.stage)
        except ValueError:
            return path

    def carry(self) -> list:
        """Hard-link into the stage the entries of ``out`` kept in the new set and not yet
        written there (other commands' files, working folders, foreign files with
        ``force``), e.g. so that a page written next can embed them; returns their names.
        Write over a carried name only by renaming a new file onto it (never in place)."""
        have, done = set(os.listdir(self.stage)), []
        for n in self._present():
            if (n in have or n == MANIFEST or self.owners.get(n) == self.command and n not in self.working
                    or n in self.dropped_stale):
                continue  # written anew, this command's previous output it does not write again, or stale
            _link_copy(self.out / n, self.stage / n)
            self._carried.add(n)
            done.append(n)
        return done

    def _owner(self, n: str) -> str:
        p, q = self.stage / n, self.out / n
        if n in self.working:
            return self.command
        if n in self._carried and (p.is_dir() or os.path.lexists(q) and os.path.samestat(os.lstat(p), os.lstat(q))):
            return self.owners.get(n, "")
        return self.command

    def _complete(self) -> None:
        """Carry the kept entries of ``out`` into the stage and write the manifest."""
        self.carry()
        owners = {n: self._owner(n) for n in os.listdir(self.stage) if n != MANIFEST}
        self.kept = {n: self.owners.get(n, "") for n in sorted(self._carried) if n not in self.working}
        self.replaced_foreign = sorted(n for n in self._present() if n != MANIFEST and n not in self.owners
                                       and n not in self._carried and n not in self.working)
        owners = {n: o for n, o in owners.items() if o}  # foreign files stay unlisted
        doc = {"tool": "laser-hazard", "note": "files written by laser-hazard in this folder and the command of each",
               "files": dict(sorted(owners.items()))}
        sources = {c: s for c, s in {**self.sources, self.command: self.source}.items() if s is not None and c in owners.values()}
        if sources:
            doc["sources"] = dict(sorted(sources.items()))
        with open(self.stage / MANIFEST, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(doc, indent=1))
            fh.flush()
            os.fsync(fh.fileno())
        for p in self.stage.iterdir():
            if p.is_file() and not p.is_symlink() and owners.get(p.name) == self.command:
                fsync_file(p)
        fsync_dir(self.stage)
        if self.out.is_dir():
            os.chmod(self.stage, os.stat(self.out).st_mode & 0o7777)
        else:
            os.chmod(self.stage, 0o777 & ~current_umask())  # read, not set: the process's mask never changes

    def commit(self) -> None:
        """Switch the staged set in (see the module docstring)."""
        self._complete()
        _step("staged")
        parent = self.out.parent
        if not self.out.is_dir():
            os.rename(self.stage, self.out)
            _step("switched")
        else:
            old = self.stage.with_name(self.stage.name[:-4] + ".old")
            try:
                os.rename(self.out, old)
            except OSError as exc:  # e.g. a mount point: nothing was changed
                raise OutputFolderError(f"{self.out}: cannot be replaced as one unit ({exc.strerror}); "
                                        "write to a folder inside it instead") from None
            _step("moved")
            try:
                os.rename(self.stage, self.out)
            except BaseException:
                if not os.path.lexists(self.out):
                    os.rename(old, self.out)
                raise
            _step("switched")
            shutil.rmtree(old, ignore_errors=True)
        _ACTIVE.discard(self.stage)
        fsync_dir(parent)

    def discard(self) -> None:
        """Remove the stage (nothing switched in)."""
        _ACTIVE.discard(self.stage)
        shutil.rmtree(self.stage, ignore_errors=True)


@contextmanager
def output_unit(out, *, command: str, overwrite: bool = False, force: bool = False, working=(), claims=(), source=None):
    """An :class:`OutputUnit`; the body writes into ``unit.stage``; committed on a normal
    exit, discarded on an exception (``out`` then keeps its previous set)."""
    unit = OutputUnit(out, command=command, overwrite=overwrite, force=force, working=working, claims=claims, source=source)
    try:
        yield unit
        unit.commit()
    except BaseException:
        _ACTIVE.discard(unit.stage)
        if unit.stage.exists():
            shutil.rmtree(unit.stage, ignore_errors=True)
        raise


class FileSet:
    """Files at separate, user-chosen paths (``hazard fit``'s model, envelope and samples)
    replaced as one unit: each is written to a temporary beside its final path
    (:meth:`stage`), then :meth:`commit` switches them all in, or none.

    The switch: every final file that exists is first hard-linked to a backup
    ``.NAME.<token>.old`` beside it; the temporaries are then renamed over the finals one
    by one; if any rename fails, the finals already switched are put back from their
    backups (or removed when they did not exist), so on an error none of the final files is
    created or replaced. The backups are removed after the switch. A process killed between
    the renames (not an exception) may leave a mix; its ``.NAME.*.old`` backups beside the
    files are the previous versions. A journal ``.NAME.<token>.journal`` beside each final
    file, written before the first rename and removed last, lists the whole set: the next
    :class:`FileSet` naming any of its files (the next ``hazard fit`` writing them) finishes
    an interrupted switch first (:func:`recover_file_sets`): forward when every temporary
    was renamed in (only the backups were left), else back to the previous versions (the
    backups restored, files that did not exist before removed). So a kill between the
    renames leaves a mix only until the next run touches the set."""

    def __init__(self, paths):
        finals = [Path(os.path.abspath(p)) for p in paths]
        if len(set(finals)) != len(finals):
            raise ValueError(f"output files {[str(p) for p in paths]}: the same file is named twice; expected separate paths")
        self.recovered = recover_file_sets(finals)  # what an interrupted earlier switch needed (said by the caller)
        self.token = secrets.token_hex(8)
        self.finals = finals
        # the writer's pid in every temporary's and backup's name: the next set removes those of dead processes
        self.temps = {p: p.parent / f".{p.name}.{os.getpid()}.{self.token}.tmp{p.suffix}" for p in finals}
        _ACTIVE_FILES.update(self.temps.values())

    def _journal(self, p: Path) -> Path:
        return p.parent / f".{p.name}.{self.token}.journal"

    def stage(self, path) -> Path:
        """The temporary to write instead of ``path`` (one of the set's paths; same suffix)."""
        return self.temps[Path(os.path.abspath(path))]

    def commit(self) -> None:
        """Switch every written temporary in (a path never staged is left alone)."""
        todo = [p for p in self.finals if self.temps[p].exists()]
        backups, done = {}, []
        try:
            for p in todo:
                if os.path.lexists(p):
                    backups[p] = p.parent / f".{p.name}.{os.getpid()}.{self.token}.old"
                    _link_or_copy(p, backups[p])
            self._write_journals(todo, backups)
            for k, p in enumerate(todo):
                _step(f"files: rename {k}")
                os.replace(self.temps[p], p)
                done.append(p)
            _step("files: renamed")
        except BaseException:
            for p in reversed(done):  # put back what was switched: old file, or none
                if p in backups:
                    os.replace(backups.pop(p), p)
                else:
                    os.unlink(p)
            raise
        finally:
            for b in backups.values():
                if os.path.lexists(b):
                    os.unlink(b)
            for p in todo:  # last: until here a kill is finished by the next FileSet
                if os.path.lexists(self._journal(p)):
                    os.unlink(self._journal(p))
            for p in {p.parent for p in todo}:
                fsync_dir(p)
            _ACTIVE_FILES.difference_update(self.temps[p] for p in todo)

    def _write_journals(self, todo, backups) -> None:
        """The set's journal beside each of its final files (written and synced before any rename)."""
        entries = [{"final": str(p), "temp": str(self.temps[p]), "backup": str(backups[p]) if p in backups else None} for p in todo]
        text = json.dumps({"token": self.token, "pid": os.getpid(), "files": entries})
        for p in todo:
            with open(self._journal(p), "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
        for d in {p.parent for p in todo}:
            fsync_dir(d)

    def discard(self) -> None:
        for t in self.temps.values():
            if os.path.lexists(t):
                os.unlink(t)
        _ACTIVE_FILES.difference_update(self.temps.values())


def recover_file_sets(paths) -> list[str]:
    """Finish every interrupted :class:`FileSet` switch whose journal lies beside one of
    ``paths``: forward when all its temporaries were renamed in (remove the backups), else
    back (restore every backup over its final file, remove the finals that had none, remove
    the temporaries). Then remove the temporaries and backups of ``paths`` that a process no
    longer running left outside any switch (killed while writing, before its journal).
    Returns what was done, one line per set or file."""
    finals = [Path(os.path.abspath(q)) for q in paths]
    done = _finish_journals(finals)
    for p in finals:
        pat = re.compile(r"^\." + re.escape(p.name) + r"\.(\d+)\.[0-9a-f]{16}\.(tmp" + re.escape(p.suffix) + r"|old)$")
        for e in sorted(os.listdir(p.parent)) if p.parent.is_dir() else ():
            m, q = pat.match(e), p.parent / e
            if m and q.is_file() and not q.is_symlink() and q not in _ACTIVE_FILES and not _alive(int(m.group(1))):
                os.unlink(q)
                done.append(f"removed the stale {e} beside {p.name} (left by an interrupted write)")
    return done


def _finish_journals(finals) -> list[str]:
    """The journal part of :func:`recover_file_sets`."""
    done = []
    for p in finals:
        for journal in sorted(p.parent.glob(f".{glob.escape(p.name)}.*.journal")):
            try:
                doc = json.loads(journal.read_text(encoding="utf-8"))
                entries, pid = doc["files"], int(doc["pid"])
            except (OSError, ValueError, KeyError, TypeError):
                continue  # not ours, or already finished by another set's recovery
            if _alive(pid):
                continue  # another running process is switching this set now
            done.append(_finish_switch(entries))
            for e in entries:
                j = Path(e["final"]).parent / f".{Path(e['final']).name}.{journal.name.split('.')[-2]}.journal"
                if os.path.lexists(j):
                    os.unlink(j)
    return done


def _finish_switch(entries) -> str:
    """Roll one interrupted switch forward or back (:func:`recover_file_sets`)."""
    forward = not any(os.path.lexists(e["temp"]) for e in entries)
    for e in entries:
        final, temp, backup = Path(e["final"]), Path(e["temp"]), e["backup"]
        if forward:
            if backup and os.path.lexists(backup):
                os.unlink(backup)
            continue
        if backup and os.path.lexists(backup):
            if os.path.lexists(final) and os.path.samefile(backup, final):
                os.unlink(backup)  # never switched: the final is the previous version (rename() of two links is a no-op)
            else:
                os.replace(backup, final)  # the previous version back
        elif not backup and not os.path.lexists(temp) and os.path.lexists(final):
            os.unlink(final)  # switched in, had no previous version
        if os.path.lexists(temp):
            os.unlink(temp)
    names = ", ".join(Path(e["final"]).name for e in entries)
    return f"an interrupted write of {names} was {'completed' if forward else 'rolled back to the previous files'}"


@contextmanager
def output_files(paths):
    """A :class:`FileSet` of ``paths``: the body writes ``files.stage(path)`` for each;
    committed on a normal exit, every temporary discarded on an exception (no final file
    created or replaced)."""
    files = FileSet(paths)
    try:
        yield files
        files.commit()
    finally:
        files.discard()
