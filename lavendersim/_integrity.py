"""The check of generated Python modules against generated/manifest.json, done by the importer (generated code
imports nothing of the runtime).

The C backend embeds the hash of the generated C sources it was built from (StaleBuildError on a
mismatch). The Python modules of generated/ are checked the same way when first imported: ``import
lavendersim`` installs :class:`GeneratedChecker`, an import hook (a ``sys.meta_path`` finder) that, before any
``lavendersim.generated.<module>`` is executed, verifies that its file has the sha256 manifest.json records
for it, else raises :class:`GeneratedFileError` naming the file and the command that regenerates it — a hand
edit (a box's inertia doubled) or a truncated file never runs silently, never surfaces as an AttributeError
or a SyntaxError. One file is hashed once per process (cached by size and modification time); ``import
lavendersim`` installs the hook only and hashes nothing. Standard library only.
"""
from __future__ import annotations

import hashlib
import importlib.abc
import importlib.machinery
import json
import os
import sys
from pathlib import Path

from .errors import GeneratedFileError

_OK: dict[str, tuple[int, int]] = {}   # path -> (size, mtime_ns) of a file found consistent


def generated_dir() -> Path:
    """The package's generated/ folder (found without importing any generated module)."""
    import importlib.util

    spec = importlib.util.find_spec("lavendersim.generated")
    if spec is None or not spec.submodule_search_locations:
        raise GeneratedFileError("lavendersim.generated is missing: the package's generated/ folder is not there; "
                                 "run `lavendersim derive` from a source checkout (or reinstall lavendersim)")
    folder = Path(list(spec.submodule_search_locations)[0])
    # a strict editable install (docs/install.md) maps the package as a folder of links into the clone: the
    # clone's generated/ is where __init__.py points (`lavendersim derive` must write there, not into the links)
    init = folder / "__init__.py"
    return init.resolve().parent if init.is_symlink() else folder


def _fail(path: Path, why: str) -> GeneratedFileError:
    return GeneratedFileError(
        f"{path} {why}. Files in generated/ are written only by `lavendersim derive`; it was edited by hand "
        "or half-written. Regenerate it with `lavendersim derive` (then rebuild the C backend, "
        "`pip install -e .` in a checkout), or restore the file from your installation.")


def check_generated(path) -> None:
    """Raise GeneratedFileError unless the file at `path` has the sha256 that the manifest.json beside it
    records for its name.

    Parameters
    ----------
    path : path-like
        A generated file (e.g. ``generated/kernels_numpy.py``, or a module's ``__file__``).
    """
    path = Path(path)
    key = os.fspath(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror or exc})") from exc
    sig = (st.st_size, st.st_mtime_ns)
    if _OK.get(key) == sig:
        return
    man_path = path.parent / "manifest.json"
    try:
        want = json.loads(man_path.read_text(encoding="utf-8"))["outputs_sha256"][path.name]
    except OSError as exc:
        raise _fail(path, f"cannot be checked: {man_path} cannot be read ({exc.strerror or exc})") from exc
    except (ValueError, KeyError, TypeError) as exc:
        raise _fail(path, f"cannot be checked: {man_path} is not a derive manifest listing {path.name}") from exc
    try:
        got = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror or exc})") from exc
    if got != want:
        raise _fail(path, f"does not match generated/manifest.json (sha256 {got[:12]}…, manifest {want[:12]}…; "
                          f"{st.st_size} bytes)")
    _OK[key] = sig


class GeneratedChecker(importlib.abc.MetaPathFinder):
    """Import hook: find ``lavendersim.generated.<module>`` as usual, then check its file (:func:`check_generated`)
    before it is executed.

    It also finds any ``lavendersim.*`` module that a strict editable install (pyproject.toml's default,
    docs/install.md) does not link yet: that install is a folder of links to the files the install saw, so a file
    added to the clone since (a new module, a file a new derive/ step prints) is looked for in the folder the
    package's ``__init__.py`` links to."""

    PACKAGE = "lavendersim.generated."
    BESIDE = ("derive", "generated", "labs")   # pyproject.toml's package-dir (tests/test_generated_check.py checks it)

    def find_spec(self, fullname, path, target=None):
        if not fullname.startswith("lavendersim.") or path is None:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is None:
            linked = [Path(p, "__init__.py") for p in path]
            clone = [str(i.resolve().parent) for i in linked if i.is_symlink()]
            spec = importlib.machinery.PathFinder.find_spec(fullname, clone, target) if clone else None
        if spec is None and fullname.count(".") == 1 and fullname.split(".")[1] in self.BESIDE:
            # `import lavendersim` found a checkout's own lavendersim/ folder (the current directory on sys.path:
            # `python -m pytest` or a REPL in the clone) rather than the install: pyproject.toml's package-dir puts
            # these subpackages in the checkout's top-level folders, beside it
            beside = [str(Path(p).resolve().parent) for p in path if Path(p).resolve().parent.joinpath("pyproject.toml").is_file()]
            spec = importlib.machinery.PathFinder.find_spec(fullname, beside, target) if beside else None
        if fullname.startswith(self.PACKAGE) and spec is not None and spec.origin and spec.origin.endswith(".py"):
            check_generated(spec.origin)
        return spec


def install() -> None:
    """Put :class:`GeneratedChecker` first on ``sys.meta_path`` (once per process)."""
    if not any(isinstance(f, GeneratedChecker) for f in sys.meta_path):
        sys.meta_path.insert(0, GeneratedChecker())
