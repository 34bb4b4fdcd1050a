"""What this installation of LavenderSim has: optional extras, and how to rebuild it.

The core (``pip install -e .`` from a clone; the distribution is ``lavender-rigid-body``) runs the simulator, the kernels, the chapter's labs and
``lavendersim derive``. Heavier features live in extras; a feature whose extra is missing raises
:class:`MissingExtraError` naming the extra and the command that installs it (the CLI prints that
one line and exits 2).
"""
from __future__ import annotations

import importlib
import json
from pathlib import Path
from types import ModuleType
from urllib.parse import unquote, urlparse

from ._version import DISTRIBUTION
from .errors import PicklableError

# extra -> the packages it installs (as imported)
EXTRAS = {
    "control": ("casadi", "control"),
    "viewer": ("viser",),
    "gym": ("gymnasium",),
    "bench": ("mujoco",),
    "distributed": ("dask", "distributed"),
}


def extra_command(extra: str) -> str:
    """The command that installs ``extra``: ``pip install 'lavender-rigid-body[<extra>]'``; for an
    editable install ``pip install -e '<its source folder>[<extra>]'``; run from a source tree
    that is not installed, ``pip install -e '.[<extra>]'``."""
    if extra not in EXTRAS and extra not in ("test", "all"):
        raise ValueError(f"extra_command: unknown extra {extra!r}; known: {sorted(EXTRAS)}")
    if _direct_url() is None:  # run from a source tree, not installed
        return f"pip install -e '.[{extra}]'  (from the repository root)"
    src = _editable_source()
    return f"pip install -e '{src}[{extra}]'" if src else f"pip install '{DISTRIBUTION}[{extra}]'"


class MissingExtraError(PicklableError, ImportError):
    """A feature needs an optional extra that is not installed.

    The message is one line: ``"<feature> needs the <extra> extra: <extra_command(extra)>"``
    (``pip install -e '<source folder>[<extra>]'`` for an editable install); the three are kept as
    attributes.

    Parameters
    ----------
    feature : str
        What was asked for (``"lavendersim lqr"``).
    extra : str
        The extra that provides it (``"control"``).
    module : str
        The module that failed to import.
    """

    _init_fields = ("feature", "extra", "module")   # pickles with them (lavendersim.errors.PicklableError)

    def __init__(self, feature: str, extra: str, module: str):
        self.feature, self.extra, self.module = feature, extra, module
        try:
            command = extra_command(extra)
        except ValueError:   # not one of ours (an extra named by a caller): the plain form
            command = f"pip install '{DISTRIBUTION}[{extra}]'"
        super().__init__(f"{feature} needs the {extra} extra: {command} "
                         f"(module {module!r} is not installed)", name=module)


def require(module: str, extra: str, feature: str) -> ModuleType:
    """Import ``module`` (a package of ``extra``) or raise MissingExtraError naming the extra.

    Parameters
    ----------
    module : str
        The module to import, e.g. ``"casadi"``.
    extra : str
        The extra that installs it (a key of :data:`EXTRAS`).
    feature : str
        What needs it, as the user asked for it, e.g. ``"lavendersim lqr"``.
    """
    if extra not in EXTRAS or module.split(".")[0] not in EXTRAS[extra]:
        raise ValueError(f"require: {module!r} is not a package of the {extra!r} extra")
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] != module.split(".")[0]:
            raise  # the extra is there but one of *its* dependencies is broken: show that as it is
        raise MissingExtraError(feature, extra, module) from None


def _direct_url() -> dict | None:
    from importlib import metadata

    try:
        text = metadata.distribution(DISTRIBUTION).read_text("direct_url.json")
    except metadata.PackageNotFoundError:
        return None
    try:
        return json.loads(text) if text else None
    except ValueError:
        return None


def _editable_source() -> str | None:
    """The source folder of an editable install, else None."""
    info = _direct_url()
    if not info or not info.get("dir_info", {}).get("editable"):
        return None
    parsed = urlparse(info.get("url", ""))
    return unquote(parsed.path) if parsed.scheme == "file" else None


def rebuild_command() -> str:
    """The command that rebuilds the compiled backend for the way this copy was installed.

    Editable install: ``pip install -e <its source folder>``; installed from a local folder:
    ``pip install --force-reinstall <that folder>``; from an index or a wheel: ``pip install
    --force-reinstall --no-deps lavender-rigid-body``; not installed (run from a source tree):
    ``pip install -e .`` from the repository root."""
    info = _direct_url()
    if info is None:
        return "pip install -e .  (from the repository root)"
    url = info.get("url", "")
    parsed = urlparse(url)
    local = parsed.scheme == "file" and Path(unquote(parsed.path)).is_dir()
    if local and info.get("dir_info", {}).get("editable"):
        return f"pip install -e {unquote(parsed.path)}"
    if local:
        return f"pip install --force-reinstall --no-deps {unquote(parsed.path)}"
    return f"pip install --force-reinstall --no-deps {DISTRIBUTION}"
