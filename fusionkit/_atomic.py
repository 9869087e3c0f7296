"""Crash-safe writes of one file or of a set of files that belong together.

A merged map is a *set*: ``merged.yaml``, the image it names, the report, maybe group maps. A
reader must never find files of two different writes together, and a crash (``kill -9``, a
power cut) or a signal at any instant must leave either the old set or the new one.
:func:`write_set` gives that promise with an undo journal and one commit point:

1. Lock every directory of the set (``flock``): a second writer to the same output waits, so
   two writers end with the whole set of one of them.
2. Recover: a journal left by a killed write is rolled back (or forward, if that write had
   reached its commit point); temporary and backup files a killed write left are removed.
3. Stage every new file under a temporary name beside its target, ``fsync`` each.
4. Write and ``fsync`` the journal (each target, its backup, whether it existed).
5. Hide the commit file and the files named in ``hide_first`` (a map YAML, so that its old
   text never stands beside a new image); hard-link a backup of every other existing target.
6. Rename the staged files into place in the order given; the commit file last: that rename
   is the commit point. Then drop the journal and the backups.

SIGINT and SIGTERM are held back from step 4 on; one that arrives before the commit point
rolls the write back (the old set stays whole), one after it lets the write finish. An error
(disk full, permission) rolls back too and is raised as one :class:`InputError` line.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import secrets
import shutil
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from . import _signals
from ._guards import (_check_target, _parent, _short, _write_error, check_distinct,  # noqa: F401
                      check_not_input, check_out_dir, check_writable, describe_os_error,
                      dead_export, make_out_dir, made_out_dir, show)
from .errors import InputError

__all__ = ["atomic_path", "write_bytes_atomic", "write_text_atomic", "write_set", "recover_set", "recover_folder",
           "hidden_copies",
           "check_not_input", "check_distinct", "check_writable", "check_out_dir", "make_out_dir", "made_out_dir",
           "describe_os_error", "show"]

_TMP, _BAK, _JOURNAL = ".tmp", ".bak", ".journal"


# ---------------------------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------------------------
def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot sync a directory; the renames are still atomic
    finally:
        os.close(fd)


def _write_durable(path: Path, payload: bytes) -> None:
    """Create ``path`` (which must not exist) holding ``payload``, flushed to disk."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        view = memoryview(payload)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)



@contextlib.contextmanager
def _locked(directories: Iterable[Path], wait: bool = True) -> Iterator[None]:
    """Exclusive ``flock`` on each directory (sorted, so that two writers cannot deadlock);
    without ``wait``, :class:`BlockingIOError` when another process holds one."""
    try:
        import fcntl
    except ImportError:  # no flock on this platform: writes are still atomic one by one
        yield
        return
    fds = []
    try:
        for d in sorted({os.path.realpath(d) for d in directories}):
            fd = os.open(d, os.O_RDONLY)
            fds.append(fd)
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        yield
    finally:
        for fd in reversed(fds):
            os.close(fd)  # closing the descriptor releases its lock


def _is_leftover(name: str, target: str) -> bool:
    return (name.startswith(f".{target}.") and name != f".{target}{_JOURNAL}"
            and (name.endswith(_TMP) or name.endswith(_BAK)))


def _sweep(targets: Iterable[Path]) -> None:
    """Remove temporary and backup files that a killed write of these targets left behind."""
    by_dir: dict[Path, set[str]] = {}
    for t in targets:
        by_dir.setdefault(_parent(t), set()).add(t.name)
    for d, names in by_dir.items():
        try:
            entries = os.listdir(d)
        except OSError:
            continue
        for entry in entries:
            if entry.startswith(".") and any(_is_leftover(entry, n) for n in names):
                with contextlib.suppress(OSError):
                    if not os.path.isdir(d / entry):
                        os.unlink(d / entry)


def recover_set(commit: os.PathLike | str, leftovers, targets: Iterable[os.PathLike | str] = ()) -> None:
    """Before a folder is judged by what it holds: finish or undo a write of the set whose
    commit file is ``commit`` that a kill cut short, and remove the temporary and backup files
    of killed writes whose names match ``leftovers`` (a compiled pattern of file names) in the
    folders of ``commit`` and of ``targets`` (the set's other files, which may stand in other
    folders). Waits for a write in progress in those folders."""
    commit = Path(commit)
    targets = [Path(t) for t in targets]
    folders = [d for d in dict.fromkeys([_parent(commit)] + [_parent(t) for t in targets]) if d.is_dir()]
    if not folders:
        return
    with _locked(folders):
        _recover(commit, targets)
        for folder in folders:
            for entry in os.listdir(folder):
                if leftovers.fullmatch(entry) and not os.path.isdir(folder / entry):
                    with contextlib.suppress(OSError):
                        os.unlink(folder / entry)


#: A temporary file of a write (``.NAME.TOKEN.tmp``, ``.NAME.TOKEN.journal.tmp``)
_STAGED = re.compile(r"\..+\.[0-9a-f]{12}(?:\.journal)?\.tmp")


def _here(jpath: Path, folder: str) -> bool:
    """Whether every file a journal names is in ``folder`` (a journal cut short is: it names
    none, and :func:`_recover` drops it)."""
    try:
        doc = json.loads(jpath.read_text(encoding="utf-8"))
        return all(os.path.realpath(_parent(Path(e["target"]))) == folder for e in doc["entries"])
    except (OSError, ValueError, KeyError, TypeError):
        return True


def _recover_folder(folder: Path) -> bool:
    """With ``folder`` locked: finish or undo every write of a set of files all in ``folder``
    that a kill cut short (whatever its names), then remove the temporary files killed writes
    left there (no write holds the folder, so none is needed). A set with files in other
    folders too is left, its backups with it, to the next write of that set, which names them.
    True when it changed what the folder holds."""
    try:
        names = os.listdir(folder)
    except OSError:
        return False
    real = os.path.realpath(folder)
    changed = False
    for name in names:
        if (name.startswith(".") and name.endswith(_JOURNAL) and len(name) > len(_JOURNAL) + 1
                and _here(folder / name, real)):
            _recover(folder / name[1:-len(_JOURNAL)])
            changed = True
    for name in os.listdir(folder) if changed else names:
        if _STAGED.fullmatch(name) and not os.path.isdir(folder / name):
            with contextlib.suppress(OSError):
                os.unlink(folder / name)
                changed = True
        elif dead_export(folder, name):   # a killed export rosbag's folder, of any output name
            shutil.rmtree(folder / name, ignore_errors=True)
            changed = True
    return changed


def recover_folder(folder: os.PathLike | str, *, wait: bool = True) -> bool:
    """Finish or undo the writes a kill cut short in ``folder`` and remove their temporary
    files (what every write does first in its folders). Without ``wait``, nothing is done while
    another write holds the folder (a reader must not wait on, or deadlock with, a writer).
    True when it changed what the folder holds."""
    folder = Path(folder)
    try:
        with _locked([folder], wait=wait):
            return _recover_folder(folder)
    except OSError:   # busy, read-only, missing: the reader reads what is there
        return False


def hidden_copies(names: str):
    """The pattern of the temporary and backup files a killed write left of the files whose
    names match the regular expression ``names`` (for :func:`recover_set`)."""
    import re
    return re.compile(r"\.(?:" + names + r")\.[0-9a-f]{12}\.(?:tmp|bak)")


#: The commit file of every set this process wrote whole, in order (a command interrupted
#: after its last write says so)
COMMITTED: list[Path] = []


def _journal_path(commit: Path) -> Path:
    return _parent(commit) / f".{commit.name}{_JOURNAL}"


def _digest(path: Path) -> str | None:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()


def _recover(commit: Path, targets: Iterable[Path] = ()) -> None:
    """Finish or undo the write a killed process left half done (its journal tells which).

    Only entries that a write of this output can have made are acted on: a target beside the
    journal or among ``targets`` (this write's files), with its backup beside it under the
    journal's token; anything else in the journal is ignored.
    """
    jpath = _journal_path(commit)
    if not jpath.is_file():
        return
    allowed_dirs = {os.path.realpath(_parent(jpath))} | {os.path.realpath(_parent(Path(t))) for t in targets}
    try:
        doc = json.loads(jpath.read_text(encoding="utf-8"))
        token, digest = str(doc["token"]), doc["digest"]
        entries = []
        for e in doc["entries"]:
            target = Path(e["target"])
            backup = Path(e["backup"]) if e["backup"] else None
            if os.path.realpath(_parent(target)) not in allowed_dirs:
                continue
            if backup is not None and backup != _parent(target) / f".{target.name}.{token}{_BAK}":
                continue
            entries.append((target, backup, bool(e["existed"])))
    except (OSError, ValueError, KeyError, TypeError):
        jpath.unlink(missing_ok=True)  # a journal cut short: its write never began
        return
    committed = _digest(commit) == digest
    for target, backup, existed in reversed(entries):
        if committed:
            if backup is not None:
                backup.unlink(missing_ok=True)
        elif backup is not None and os.path.lexists(backup):
            _restore(backup, target)
        elif not existed:
            target.unlink(missing_ok=True)
    for d in {_parent(t) for t, _, _ in entries}:
        _fsync_dir(d)
    jpath.unlink(missing_ok=True)
    _fsync_dir(_parent(jpath))


# ---------------------------------------------------------------------------------------------
# Writers
# ---------------------------------------------------------------------------------------------
def write_set(files: Sequence[tuple[os.PathLike | str, bytes | None]],
              commit: tuple[os.PathLike | str, bytes], *,
              hide_first: Iterable[os.PathLike | str] = ()) -> None:
    """Replace a set of files as one: afterwards all are new, or (on any failure) all are old.

    Parameters
    ----------
    files : sequence of (path, bytes or None)
        The files of the set, renamed into place in this order; ``None`` removes a file of the
        previous set that the new set does not have.
    commit : (path, bytes)
        The file written last: while it is absent the set is incomplete, once it is in place
        the write is done (a report, a ``truth.json``).
    hide_first : paths, keyword-only
        Targets among ``files`` to take away before any file is replaced (a map YAML whose
        image keeps its name, so that the old YAML never names the new image).

    Raises
    ------
    InputError
        A folder is missing or read-only, a target is a folder, the disk is full, ...: one line
        naming the file. Nothing is changed.
    KeyboardInterrupt
        (or :class:`fusionkit._signals.Terminated`) when interrupted before the commit point:
        the old set is left whole.
    """
    _signals.check()   # a Ctrl-C a library swallowed: the old set stays
    items = [(Path(p), b) for p, b in files]
    commit_path, commit_payload = Path(commit[0]), commit[1]
    targets = [p for p, _ in items] + [commit_path]
    resolved = [os.path.realpath(p) for p in targets]
    if len(set(resolved)) != len(resolved):
        dup = next(p for p, r in zip(targets, resolved) if resolved.count(r) > 1)
        raise InputError(f"{_short(dup)}: is given as two outputs of one write; choose distinct paths")
    for p in targets:
        _check_target(p)
    hide = {os.path.realpath(p) for p in hide_first}
    token = secrets.token_hex(6)
    staged: list[Path] = []
    writing = commit_path   # the file being staged, named when the disk fills mid-write
    try:
        with _locked(_parent(p) for p in targets):
            _recover(commit_path, targets)
            _sweep(targets)
            for folder in dict.fromkeys(_parent(p) for p in targets):
                _recover_folder(folder)   # other sets a kill cut short there, whatever their names
            try:
                for p, payload in items + [(commit_path, commit_payload)]:
                    if payload is None:
                        staged.append(None)
                        continue
                    tmp = _parent(p) / f".{p.name}.{token}{_TMP}"
                    staged.append(tmp)
                    writing = p
                    _write_durable(tmp, payload)
                with _signals.deferred():
                    try:
                        if _commit(items, commit_path, commit_payload, staged, hide, token):
                            COMMITTED.append(commit_path)   # before a held-back signal comes
                    finally:
                        # before a held-back signal is sent again: raised in the loop below,
                        # it would cut it short and leave temporary files behind
                        _unlink_all(staged)
            finally:
                _unlink_all(staged)
    except OSError as exc:
        failed = Path(exc.filename) if getattr(exc, "filename", None) else writing
        for t in targets:  # name the target, not its temporary file
            if failed.name.startswith(f".{t.name}."):
                failed = t
        raise _write_error(failed, exc) from None


def _unlink_all(paths) -> None:
    for tmp in paths:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()


def _commit(items, commit_path: Path, commit_payload: bytes, staged, hide, token) -> bool:
    """Put the staged set in place; True once committed, False when a held-back signal
    rolled it back."""
    entries = []
    for p, _ in items + [(commit_path, None)]:
        existed = os.path.lexists(p)
        backup = _parent(p) / f".{p.name}.{token}{_BAK}" if existed else None
        entries.append((p, backup, existed))
    journal = _journal_path(commit_path)
    jtmp = _parent(journal) / f".{commit_path.name}.{token}.journal{_TMP}"
    try:
        _write_durable(jtmp, json.dumps({
            "token": token, "digest": hashlib.sha256(commit_payload).hexdigest(),
            "entries": [{"target": os.path.abspath(p), "backup": os.path.abspath(b) if b else None,
                         "existed": e} for p, b, e in entries]}).encode())
        os.replace(jtmp, journal)
    finally:
        with contextlib.suppress(OSError):
            jtmp.unlink()
    dirs = {_parent(p) for p, _, _ in entries}
    try:
        last = len(entries) - 1  # the commit file goes away first, then the hidden files
        for i in [last] + list(range(last)):
            p, backup, existed = entries[i]
            if existed and (i == last or os.path.realpath(p) in hide or staged[i] is None):
                os.replace(p, backup)
        for p, backup, existed in entries:  # every other old file keeps a backup
            if existed and not os.path.lexists(backup):
                _backup_copy(p, backup)
        for d in dirs:
            _fsync_dir(d)
        for (p, _, _), tmp in zip(entries[:-1], staged[:-1]):
            if tmp is not None:
                os.replace(tmp, p)
        for d in dirs:
            _fsync_dir(d)
        if _signals.pending():
            raise _Cancelled()
        os.replace(staged[-1], commit_path)  # the commit point
    except BaseException as exc:
        if _rollback(entries):
            journal.unlink(missing_ok=True)
        for d in dirs:
            _fsync_dir(d)
        if isinstance(exc, _Cancelled):
            return False  # the held-back signal is delivered when the deferred block ends
        raise
    # Committed: the new set is in place whatever happens now. A failure to tidy up is no
    # failure of the write: the next write to this output finds the journal, sees the commit
    # file is the new one and finishes the tidying. So the backups go before the journal: a
    # kill between the two leaves the journal, which names them.
    _fsync_dir(_parent(commit_path))
    for _, backup, _ in entries:
        if backup is not None:
            with contextlib.suppress(OSError):
                backup.unlink()
    for d in dirs:
        _fsync_dir(d)
    with contextlib.suppress(OSError):
        journal.unlink(missing_ok=True)
    _fsync_dir(_parent(journal))
    return True


class _Cancelled(Exception):
    """A signal arrived before the commit point (raised and handled inside :func:`_commit`)."""


def _backup_copy(target: Path, backup: Path) -> None:
    try:
        os.link(target, backup, follow_symlinks=False)   # a symbolic link is kept as itself
    except OSError:
        shutil.copy2(target, backup, follow_symlinks=False)


def _same_entry(a: Path, b: Path) -> bool:
    """Whether two names are links to one file (a symbolic link, even dangling, as itself)."""
    sa, sb = os.lstat(a), os.lstat(b)
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def _restore(backup: Path, target: Path) -> None:
    """Put ``backup`` back as ``target`` (a hard-link backup of an untouched target is simply
    dropped: renaming a link onto the same file does nothing)."""
    if os.path.lexists(target) and _same_entry(backup, target):
        backup.unlink()
    else:
        os.replace(backup, target)


def _rollback(entries) -> bool:
    """Put every old file back; False when some step failed (the journal must then stay, so
    that the next write to this output finishes the undo)."""
    ok = True
    for p, backup, existed in reversed(entries):
        try:
            if backup is not None and os.path.lexists(backup):
                _restore(backup, p)
            elif not existed:
                p.unlink(missing_ok=True)
        except OSError:
            ok = False
    return ok


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success flush it and rename it onto ``target``.

    On any exception the temporary file is removed and ``target`` is left as it was; a
    temporary file that a killed process left for the same target is removed first.
    """
    _signals.check()
    target = Path(target)
    _check_target(target)
    tmp = _parent(target) / f".{target.name}.{secrets.token_hex(6)}{_TMP}"
    try:
        with _locked([_parent(target)]):
            _recover(target)
            _sweep([target])
            _recover_folder(_parent(target))
            try:
                yield tmp
                with open(tmp, "rb+") as fh:
                    os.fsync(fh.fileno())
                os.chmod(tmp, 0o644)
                with _signals.deferred():
                    try:
                        os.replace(tmp, target)
                        _fsync_dir(_parent(target))
                    finally:
                        _unlink_all([tmp])
            finally:
                _unlink_all([tmp])
    except OSError as exc:
        raise _write_error(target, exc) from None



def write_bytes_atomic(target: str | os.PathLike, payload: bytes) -> None:
    """Write ``payload`` to ``target`` atomically and durably (temporary file, fsync, rename)."""
    write_set([], (target, payload))


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``target`` atomically."""
    write_bytes_atomic(target, text.encode("utf-8"))
