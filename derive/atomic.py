"""Replace an output folder as a whole: readers see the old folder or the new one, never a mix.

``lavendersim derive`` (generated/) and ``lavendersim derive --user FILE`` (a user set's folder) write
through :func:`replace_folder`:

1. every file is written (and fsynced) into a temporary sibling folder ``.<name>.derive-new-<pid>``,
   unchanged files copied from the old folder with their timestamps, kept entries (a user set's
   ``build/``) copied over;
2. the two folders are swapped in one step: Linux's ``renameat2(RENAME_EXCHANGE)``; elsewhere, or on
   a file system without it, two renames (``<name>`` -> ``.<name>.derive-old-<pid>``, then the new
   folder -> ``<name>``), a window of two system calls that the next run repairs;
3. the old content, now in the sibling, is removed.

A process killed at any point leaves ``<name>`` old-and-intact or new-and-complete (with the exchange;
with the two-rename fallback, killed between the renames, ``<name>`` is missing until the next run
puts the old folder back). Leftover siblings of a dead process are removed (or, for that window,
restored) by the next :func:`replace_folder` or :func:`recover` on the same folder.

The folder is replaced as a whole, so it must hold only what the writer owns: anything else in it
raises :class:`OutputFolderError` before anything is written (``--out ~`` never deletes a home folder).
Standard library only; no SymPy.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import shutil
import sys
from collections.abc import Mapping
from pathlib import Path

IGNORED = ("__pycache__",)  # dropped with the old folder: Python rebuilds it
_LEFTOVER = re.compile(r"^\.(?P<name>.+)\.derive-(?P<kind>new|old)-(?P<pid>\d+)$")
_RENAME_EXCHANGE = 2      # linux/fs.h
_AT_FDCWD = -100


class OutputFolderError(ValueError):
    """The output folder holds entries the writer does not own, or is not a folder: nothing was written."""


def _sibling(outdir: Path, kind: str, pid: int | None = None) -> Path:
    return outdir.parent / f".{outdir.name}.derive-{kind}-{os.getpid() if pid is None else pid}"


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # exists, another user's
        return True
    except OSError:
        return False
    return True


def leftovers(outdir) -> list[Path]:
    """Siblings of outdir left by interrupted runs (of any process, alive or not)."""
    outdir = Path(outdir)
    if not outdir.parent.is_dir():
        return []
    out = []
    for p in sorted(outdir.parent.iterdir()):
        m = _LEFTOVER.match(p.name)
        if m and m["name"] == outdir.name:
            out.append(p)
    return out


def recover(outdir) -> list[str]:
    """Repair what an interrupted run left next to outdir; return what was done (one line each).

    outdir missing and an old folder left between the two renames of the fallback: the old folder
    is put back. Every other leftover of a process that is no longer running is removed."""
    outdir = Path(outdir)
    done = []
    dead = []
    for p in leftovers(outdir):
        m = _LEFTOVER.match(p.name)
        assert m is not None   # (leftovers() matched it)
        if not _alive(int(m["pid"])) or int(m["pid"]) == os.getpid():
            dead.append((m["kind"], p))
    if not outdir.exists():
        olds = [p for kind, p in dead if kind == "old"]
        if olds:
            os.rename(olds[-1], outdir)
            _fsync_dir(outdir.parent)
            done.append(f"restored {outdir} from {olds[-1].name} (an interrupted run had moved it away)")
            dead = [(k, p) for k, p in dead if p != olds[-1]]
    for _, p in dead:
        _remove(p)
        done.append(f"removed {p.name} (left by an interrupted run)")
    return done


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink(missing_ok=True)


def _fsync_dir(path: Path) -> None:
    if os.name == "nt":
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_file(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0), 0o644)
    try:
        view = memoryview(data)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)


def _exchange_fn():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):   # glibc < 2.28, musl without it
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_EXCHANGE = _exchange_fn()


def exchange(a: Path, b: Path) -> bool:
    """Swap two folders in one step (renameat2 RENAME_EXCHANGE); False if this system cannot."""
    if _EXCHANGE is None:
        return False
    r = _EXCHANGE(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if r == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):   # EINVAL, ENOSYS, EOPNOTSUPP: this file system or kernel cannot exchange
        return False
    raise OSError(err, f"renameat2(RENAME_EXCHANGE) {a} <-> {b}: {os.strerror(err)}")


def replace_folder(outdir, files: Mapping[str, str | bytes], owned=(), keep=()) -> list[str]:
    """Make outdir hold exactly `files` (name -> text or bytes) plus the `keep` entries it already had,
    swapping the whole folder in at once; return the names whose content changed (sorted).

    Parameters
    ----------
    outdir : path-like
        The folder (created if missing; its parent too).
    files : dict
        File name (no sub-folders) -> content; text is written as UTF-8 bytes, newlines untouched.
    owned : iterable of str
        Other names the writer owns in outdir (e.g. files an older run wrote): dropped silently.
    keep : iterable of str
        Entries of the old folder carried over unchanged (copied, timestamps kept), e.g. a build cache.

    Nothing is written when every file already has its content and nothing owned is to be dropped.
    An entry of outdir that is none of files, owned, keep or __pycache__ raises OutputFolderError
    before anything is written."""
    outdir = Path(outdir).resolve()   # a symlinked folder: its target is the one replaced
    data = {n: (t.encode("utf-8") if isinstance(t, str) else bytes(t)) for n, t in files.items()}
    for n in data:
        if not n or "/" in n or os.sep in n or n in (".", "..") or n in IGNORED:
            raise ValueError(f"replace_folder: bad file name {n!r}")
    outdir.parent.mkdir(parents=True, exist_ok=True)
    recover(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise OutputFolderError(f"{outdir} exists and is not a folder")
    allowed = set(data) | set(owned) | set(keep) | set(IGNORED)
    old = {p.name: p for p in outdir.iterdir()} if outdir.is_dir() else {}
    foreign = sorted(n for n in old if n not in allowed)
    if foreign:
        raise OutputFolderError(
            f"{outdir} holds {', '.join(foreign[:5])}{' …' if len(foreign) > 5 else ''}, which derive did not write; "
            "derive replaces the folder as a whole, so move them away or write into a new or empty folder")
    changed = sorted(n for n, b in data.items() if n not in old or not old[n].is_file() or old[n].read_bytes() != b)
    dropped = [n for n in old if n not in data and n not in keep and n not in IGNORED]
    if outdir.is_dir() and not changed and not dropped:
        return []
    new = _sibling(outdir, "new")
    if new.exists():
        _remove(new)
    new.mkdir()
    try:
        for n, b in sorted(data.items()):
            if n in changed:
                _write_file(new / n, b)
            else:
                shutil.copy2(old[n], new / n)
        for n in keep:
            if n in old:
                if old[n].is_dir() and not old[n].is_symlink():
                    shutil.copytree(old[n], new / n, symlinks=True)
                else:
                    shutil.copy2(old[n], new / n, follow_symlinks=False)
        _fsync_dir(new)
    except BaseException:
        _remove(new)
        raise
    if not outdir.exists():
        os.rename(new, outdir)
        _fsync_dir(outdir.parent)
        return changed
    if exchange(new, outdir):          # outdir: new content; `new`: the old content
        _fsync_dir(outdir.parent)
        _remove(new)
        return changed
    aside = _sibling(outdir, "old")
    if aside.exists():
        _remove(aside)
    os.rename(outdir, aside)           # from here to the next rename outdir is missing: recover() repairs
    os.rename(new, outdir)
    _fsync_dir(outdir.parent)
    _remove(aside)
    return changed
