"""A lab's output folder ``OUT/NAME/``: written whole, never through a link, one run at a time.

:meth:`LabResult.save <lavendersim.labs.common.LabResult.save>` and the ``lavendersim lab`` command write
through this module:

- **Whole or not at all.** The files are written into a new hidden sibling folder ``OUT/.NAME.lab-new-PID``
  that this run creates, with a marker file ``INCOMPLETE`` written first and removed last; the complete
  folder is then swapped in for ``OUT/NAME`` in one step (Linux ``renameat2(RENAME_EXCHANGE)``; elsewhere two
  renames, between which ``OUT/NAME`` is briefly absent) and the old one removed. A run killed at any point
  leaves ``OUT/NAME`` as it was (the previous results, or none) — never a ``results.json`` without its figures —
  and at most a sibling marked ``INCOMPLETE``, removed by the next run into ``OUT`` (an old folder left between
  the two renames is put back).
- **No link is followed below OUT.** ``OUT`` itself is the user's own path and resolved as typed (a link there
  is the user's choice, like any tool writing into a directory it is given). Nothing the lab writes inside it
  is opened through an existing entry: a link planted in ``OUT/NAME/`` is removed with the old folder (its
  target untouched); ``OUT/NAME`` that is itself a link, not a folder, or a folder that is not a lab's (it
  holds a sub-folder, or files but no ``results.json``) is refused before anything is written, so
  ``--out ~`` never replaces a folder of yours. The lock file is opened with ``O_NOFOLLOW``.
- **One run per folder.** A run holds ``OUT/.NAME.lock`` (``fcntl.flock``: released by the kernel when the
  process ends, killed or not) from before the lab computes until its folder is in place; another run into
  the same ``OUT/NAME`` is refused at once, naming the folder and the running one's pid. The lock file stays
  (removing it would race with the next run); it is empty of anything but that pid.

Every refusal is a :class:`lavendersim.validate.LavenderInputError` naming ``out`` (exit code 2, one line).
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from lavendersim import validate as V
from lavendersim.derive.atomic import _fsync_dir   # (light: derive/__init__ and atomic import no SymPy)

MARKER = "INCOMPLETE"
RESULTS = "results.json"
_SIBLING = re.compile(r"^\.(?P<name>.+)\.lab-(?P<kind>new|old)-(?P<pid>\d+)$")


if sys.platform == "win32":   # pragma: no cover - Windows: msvcrt.locking (both released when the process ends)
    import msvcrt
else:                         # POSIX: flock
    import fcntl

_held_lock = threading.Lock()
_held: dict[tuple[str, str], list] = {}   # (real OUT, NAME) -> [owning thread id, depth, fd]


def _forget_locks_in_child() -> None:   # a forked child holds none of its parent's locks
    global _held_lock
    _held_lock = threading.Lock()
    _held.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_locks_in_child)


def _fail(folder: Path, rule: str, exc: OSError | None = None) -> V.LavenderInputError:
    detail = "" if exc is None else f" ({exc.strerror or exc})"
    return V.LavenderInputError("out", f"{folder}: {rule}", detail)


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name or name in (".", "..") or "/" in name or os.sep in name \
            or name.startswith("."):
        raise V.LavenderInputError("lab", "must be a plain folder name", f", got {name!r}")
    return name


def lock_path(out_dir, name: str) -> Path:
    """``OUT/.NAME.lock``: the file a run into ``OUT/NAME`` holds locked.

    Parameters
    ----------
    out_dir : str or Path
        OUT.
    name : str
        The lab's folder name.

    Returns
    -------
    Path
    """
    return Path(out_dir) / f".{_check_name(name)}.lock"


def _holder(fd: int) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 64).decode("ascii", "replace").strip()
    except OSError:
        text = ""
    return f"pid {text}" if text.isdigit() else "pid unknown"


def _open_lock(path: Path, folder: Path) -> int:
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _fail(folder, f"its lock file {path.name} is a symbolic link: refusing to follow it") from None
        raise _fail(folder, f"cannot create its lock file {path}", exc) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise _fail(folder, f"its lock file {path} is not a regular file")
    return fd


def _try_lock(fd: int) -> bool:
    try:
        if sys.platform == "win32":   # pragma: no cover - Windows
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        else:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES, errno.EDEADLK):
            return False
        raise
    return True


@contextlib.contextmanager
def lab_lock(out_dir, name: str) -> Iterator[Path]:
    """Hold ``OUT/.NAME.lock`` for writing ``OUT/NAME/`` (re-entrant within one thread).

    Parameters
    ----------
    out_dir : str or Path
        OUT (created if missing).
    name : str
        The lab's folder name.

    Yields
    ------
    Path
        ``OUT/NAME``.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``out``: another run (its pid named) writes the same folder, or the lock file cannot be
        made (OUT unwritable, the lock file a link or not a regular file).
    """
    out = Path(out_dir)
    folder = out / _check_name(name)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _fail(out, "cannot create the output folder", exc) from None
    key = (os.path.realpath(out), name)
    me = threading.get_ident()
    with _held_lock:
        entry = _held.get(key)
        if entry is not None:
            if entry[0] != me:
                raise _fail(folder, f"another thread of this process (pid {os.getpid()}) is writing it; "
                                    "write to another --out")
            entry[1] += 1
    if entry is None:
        path = lock_path(out, name)
        fd = _open_lock(path, folder)
        try:
            if not _try_lock(fd):
                raise _fail(folder, f"another run ({_holder(fd)}) is writing it (lock {path}); wait for it to "
                                    "finish or write to another --out")
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, f"{os.getpid()}\n".encode())
        except BaseException:
            os.close(fd)
            raise
        with _held_lock:
            _held[key] = entry = [me, 1, fd]
    try:
        yield folder
    finally:
        with _held_lock:
            entry[1] -= 1
            done = entry[1] == 0
            if done:
                del _held[key]
        if done:
            os.close(entry[2])   # closing the only descriptor releases the lock


def leftovers(out_dir, name: str) -> list[Path]:
    """Hidden siblings ``OUT/.NAME.lab-new-PID`` / ``-old-PID`` left by interrupted runs.

    Parameters
    ----------
    out_dir : str or Path
        OUT.
    name : str
        The lab's folder name.

    Returns
    -------
    list of Path
    """
    out = Path(out_dir)
    if not out.is_dir():
        return []
    found = []
    for entry in sorted(os.listdir(out)):
        m = _SIBLING.match(entry)
        if m and m["name"] == name:
            found.append(out / entry)
    return found


def _remove(p: Path) -> None:
    """Remove p without following a link (a link is unlinked; a folder's links are unlinked, not followed)."""
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        return
    if stat.S_ISDIR(st.st_mode):
        shutil.rmtree(p)
    else:
        os.unlink(p)


def _recover(out: Path, name: str, folder: Path) -> None:
    """Under the lock: every sibling left is a dead run's. An old folder left between the two renames of
    the fallback, with OUT/NAME missing, is put back; the rest is removed."""
    left = leftovers(out, name)
    if not os.path.lexists(folder):
        olds = [p for p in left if p.name.rsplit("-", 2)[1] == "old" and p.is_dir() and not p.is_symlink()]
        if olds:
            os.rename(olds[-1], folder)
            left.remove(olds[-1])
    for p in left:
        _remove(p)


def _check_replaceable(folder: Path) -> None:
    """OUT/NAME may be replaced: missing, or a real folder that is empty or a lab's (results.json or the
    marker; files and links only)."""
    try:
        st = os.lstat(folder)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(st.st_mode):
        raise _fail(folder, "is a symbolic link; a lab writes its own folder and never follows a link there "
                            "(remove the link or write to another --out)")
    if not stat.S_ISDIR(st.st_mode):
        raise _fail(folder, "exists and is not a folder")
    entries = os.listdir(folder)
    subdirs = [e for e in entries if stat.S_ISDIR(os.lstat(folder / e).st_mode)]
    if subdirs or (entries and RESULTS not in entries and MARKER not in entries):
        what = f"the sub-folder {subdirs[0]}" if subdirs else f"{len(entries)} entries but no {RESULTS}"
        raise _fail(folder, f"holds {what}: it is not a lab's output folder, and a lab replaces its folder "
                            "as a whole (move them away or write to another --out)")


def check_folder(out_dir, name: str) -> Path:
    """Refuse at once what :func:`write_folder` would refuse at the end (``OUT/NAME`` a link, not a folder,
    or not a lab's folder), so a long lab never fails after its computation; the command line calls it
    while holding :func:`lab_lock`.

    Parameters
    ----------
    out_dir : str or Path
        OUT.
    name : str
        The lab's folder name.

    Returns
    -------
    Path
        ``OUT/NAME``.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``out``.
    """
    folder = Path(out_dir) / _check_name(name)
    try:
        _check_replaceable(folder)
    except OSError as exc:
        raise _fail(folder, "cannot be read", exc) from None
    return folder


def _write(path: Path, payload) -> None:
    """Create path (never an existing entry, never through a link) and write payload into it."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                 | getattr(os, "O_BINARY", 0), 0o644)
    with os.fdopen(fd, "wb") as f:
        if callable(payload):
            payload(f)
        else:
            f.write(payload.encode("utf-8") if isinstance(payload, str) else bytes(payload))
        f.flush()
        os.fsync(f.fileno())


def _swap_in(new: Path, folder: Path) -> None:
    """Put the complete folder `new` at `folder`; the old one (if any) is removed without following links."""
    from lavendersim.derive.atomic import exchange

    if os.path.lexists(folder):
        _check_replaceable(folder)
        if not exchange(new, folder):   # no RENAME_EXCHANGE here: two renames (recover() repairs the window)
            aside = folder.parent / f".{folder.name}.lab-old-{os.getpid()}"
            os.rename(folder, aside)
            os.rename(new, folder)
            new = aside
        _remove(new)          # the old content (a link swapped in by a racing writer: unlinked, not followed)
    else:
        os.rename(new, folder)
    _fsync_dir(folder.parent)


def write_folder(out_dir, name: str, files: Mapping[str, object]) -> list[Path]:
    """Make ``OUT/NAME/`` hold exactly ``files``, written whole (module docstring).

    Parameters
    ----------
    out_dir : str or Path
        OUT (created if missing).
    name : str
        The lab's folder name.
    files : mapping
        File name (no folders) -> ``bytes``, ``str`` (UTF-8) or ``callable(binary_file)`` writing the content,
        written in this order.

    Returns
    -------
    list of Path
        ``OUT/NAME/<file>`` for each of ``files``.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``out``: another run writes the folder, it is a link or not a lab's folder, or a file cannot
        be written (nothing of this run is left in ``OUT/NAME``).
    """
    for n in files:
        if not isinstance(n, str) or not n or n in (".", "..", MARKER) or "/" in n or os.sep in n:
            raise ValueError(f"write_folder: bad file name {n!r}")
    out = Path(out_dir)
    with lab_lock(out, name) as folder:
        try:
            _recover(out, name, folder)
            _check_replaceable(folder)
            new = out / f".{name}.lab-new-{os.getpid()}"
            _remove(new)
            os.mkdir(new, 0o755)
        except OSError as exc:
            raise _fail(folder, "cannot be written", exc) from None
        try:
            _write(new / MARKER, f"being written by pid {os.getpid()}; a folder holding this file is incomplete\n")
            for n, payload in files.items():
                _write(new / n, payload)
            os.unlink(new / MARKER)
            _fsync_dir(new)
            _swap_in(new, folder)
        except OSError as exc:
            _remove(new)
            raise _fail(folder, "cannot be written", exc) from None
        except BaseException:
            _remove(new)
            raise
    return [folder / n for n in files]
