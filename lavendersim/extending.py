"""Your own equations: effects (and plain kernels) declared in one file outside the package.

    lavendersim derive --user my_effects.py     # derive, print C/NumPy/CasADi/EQUATIONS.md, compile

writes the set ``my_effects`` (the file's stem) into ``user_dir()/sets/my_effects/`` and compiles its C
into a shared library there (cached by the hash of the printed C and the compiler command: an
unchanged declaration is not recompiled; a compiler error is raised with its full output). Then, in
any process, ``scene.add_effect("gravity_gradient", body=..., mu=...)`` finds the effect by name in
the user directory and loads the set: the NumPy backend calls its printed NumPy dispatch, the C
backend calls its compiled functions through a table of function pointers (codes from
USER_CODE_BASE, assigned in load order), and ``lavendersim.effects.casadi_expr`` /
``casadi_function`` give its CasADi expression. See docs/extending.md.

The user directory is ``$LAVENDERSIM_USER_DIR`` when set, else the platform's user data directory:
``$XDG_DATA_HOME/lavendersim`` (default ``~/.local/share/lavendersim``) on Linux,
``~/Library/Application Support/lavendersim`` on macOS, ``%LOCALAPPDATA%\\lavendersim`` on Windows.
A set kept elsewhere (``--out DIR``) is loaded with ``lavendersim.effects.load_user(DIR/NAME)``.

A set records the sha256 of the declaration it was derived from: loading it while that file exists
with other contents raises (run the derive command again) rather than simulating stale equations.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

from . import validate as V

ENV = "LAVENDERSIM_USER_DIR"
CFLAGS = ["-O3", "-std=c99", "-fno-math-errno", "-fPIC", "-shared", "-fvisibility=hidden"]  # never -ffast-math
SOURCES = ("kernels.c", "kernels.h")

_SETS: dict[Path, "UserSet"] = {}  # loaded sets by directory


class UserBuildError(RuntimeError):
    """Compiling a user set's C failed; the message holds the command and the compiler's full output."""


def user_dir() -> Path:
    """Where user sets live: $LAVENDERSIM_USER_DIR, else the platform's user data directory."""
    env = os.environ.get(ENV, "").strip()
    if env:
        return Path(env).expanduser()
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Application Support" / "lavendersim"
    if os.name == "nt":
        return Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local")) / "lavendersim"
    return Path(os.environ.get("XDG_DATA_HOME", "") or Path.home() / ".local" / "share") / "lavendersim"


def sets_dir() -> Path:
    """The directory holding one sub-directory per derived user set."""
    return user_dir() / "sets"


def compiler() -> list[str]:
    """The C compiler: $CC, else cc, else gcc (UserBuildError if none is found)."""
    for c in (os.environ.get("CC"), "cc", "gcc"):
        if c and shutil.which(c.split()[0]):
            return c.split()
    raise UserBuildError("no C compiler found to build user effects for the C backend: set CC or install cc/gcc "
                         "(the NumPy backend needs none)")


def _import_file(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class UserSet:
    """A derived user set: its metadata, NumPy module, CasADi module (on demand) and compiled library
    (on demand, built when missing).

    Parameters
    ----------
    directory : str or os.PathLike
        The folder ``lavendersim derive --user`` wrote for the set.
    """

    def __init__(self, directory: Path):
        self.directory = Path(directory).resolve()
        meta_path = self.directory / "effects_meta.py"
        if not meta_path.is_file():
            raise V.LavenderInputError("user effects", f"{self.directory} is not a derived set (no effects_meta.py); "
                                       "run `lavendersim derive --user FILE`")
        self.meta = _import_file(f"lavendersim_user_meta_{abs(hash(self.directory))}", meta_path)
        self.name = self.meta.SET_NAME
        self.effect_names = [e["name"] for e in self.meta.EFFECTS]
        self.kernel_names = list(self.meta.KERNELS)
        self.numpy = _import_file(f"lavendersim_user_{self.name}_numpy", self.directory / "kernels_numpy.py")
        self._casadi = None
        self._lib = None
        self.library_path: Path | None = None
        self.library_built_now: bool | None = None  # True: compiled by this process; False: reused from the cache

    def check_current(self) -> None:
        """Raise if the declaration this set was derived from exists and has changed since."""
        decl = Path(self.meta.DECLARATION)
        if decl.is_file() and hashlib.sha256(decl.read_bytes()).hexdigest() != self.meta.DECLARATION_SHA256:
            raise V.LavenderInputError("user effects", f"{decl} changed since the set {self.name!r} was derived "
                                       f"into {self.directory}: run `lavendersim derive --user {decl}`")

    @property
    def casadi(self):
        """The set's printed CasADi module (needs the control extra)."""
        if self._casadi is None:
            from ._install import require

            require("casadi", "control", "the CasADi expressions of user effects")
            self._casadi = _import_file(f"lavendersim_user_{self.name}_casadi", self.directory / "kernels_casadi.py")
        return self._casadi

    def library(self) -> ctypes.CDLL:
        """The compiled library (built now if missing or out of date with the printed C)."""
        if self._lib is None:
            self.library_path, self.library_built_now = _build(self.directory)
            lib = ctypes.CDLL(str(self.library_path))
            abi = ctypes.c_int.in_dll(lib, "lvu_abi_version").value
            from .generated import effects_meta

            if abi != effects_meta.ABI_VERSION:
                raise UserBuildError(f"{self.library_path}: built for effect ABI {abi}, this lavendersim uses "
                                     f"{effects_meta.ABI_VERSION}; run `lavendersim derive --user {self.meta.DECLARATION}`")
            self._lib = lib
        return self._lib

    def c_function(self, effect: str) -> int:
        """Address of the compiled accumulating function of one of the set's effects.

        Parameters
        ----------
        effect : str
            An effect of this set.

        Returns
        -------
        int
            The C function's address (the C backend calls it per body).
        """
        fn = getattr(self.library(), f"lvu_effect_{effect}")
        return int(ctypes.cast(fn, ctypes.c_void_p).value)


def _library_name(directory: Path, cmd: list[str]) -> str:
    h = hashlib.sha256()
    for name in SOURCES:
        h.update(f"{name} {hashlib.sha256((directory / name).read_bytes()).hexdigest()}\n".encode())
    h.update(" ".join(cmd).encode())
    suffix = ".dll" if os.name == "nt" else ".so"
    return f"lib{directory.name}-{h.hexdigest()[:16]}{suffix}"


def build(directory) -> Path:
    """Compile a set's kernels.c into build/lib<set>-<hash>.so; reuse it when the printed C and the
    compiler command are unchanged. A failing compile raises UserBuildError with its full output.

    Parameters
    ----------
    directory : str or os.PathLike
        The set's folder.

    Returns
    -------
    pathlib.Path
        The shared library.

    Raises
    ------
    UserBuildError
        With the command and the compiler's full output.
    """
    return _build(directory)[0]


def _build(directory) -> tuple[Path, bool]:
    directory = Path(directory).resolve()
    cmd = compiler() + CFLAGS
    out = directory / "build" / _library_name(directory, cmd)
    if out.is_file():
        return out, False
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + f".tmp{os.getpid()}")
    full = cmd + [str(directory / "kernels.c"), "-o", str(tmp), "-lm"]
    try:
        r = subprocess.run(full, capture_output=True, text=True, cwd=directory)
    except OSError as exc:
        raise UserBuildError(f"compiling user effects failed to start: {' '.join(full)}: {exc}") from exc
    if r.returncode != 0:
        tmp.unlink(missing_ok=True)
        raise UserBuildError(f"compiling the user set {directory.name!r} failed (exit {r.returncode}):\n"
                             f"$ {' '.join(full)}\n{r.stdout}{r.stderr}".rstrip())
    os.replace(tmp, out)
    return out, True


def derive(declaration, out=None, compile: bool = True) -> UserSet:
    """Derive a declaration file: print its set into `out` (default sets_dir()) / <stem>/, compile its
    C (cached) and load it. Imports SymPy (this is the derive step, not the simulation path).

    Parameters
    ----------
    declaration : str or os.PathLike
        The declaration file (docs/extending.md).
    out : str or os.PathLike, optional
        Parent folder of the set (default :func:`sets_dir`).
    compile : bool, optional
        Compile its C now (else on first use by the C backend).

    Returns
    -------
    UserSet
    """
    from .derive.user import render_user

    from .derive.atomic import replace_folder

    set_name, files = render_user(declaration)
    directory = (Path(out) if out is not None else sets_dir()) / set_name
    # the set's folder is swapped in whole (a killed run leaves the old set or the new one), its
    # compiled-library cache build/ carried over; anything else in it raises before anything is written
    replace_folder(directory, files, keep=("build",))
    s = load(directory, reload=True)
    if compile:
        s.library()
    return s


def load(path, reload: bool = False) -> UserSet:
    """Load and register a derived set: `path` is its directory, or its declaration file (then the set of
    that name in sets_dir()). Already loaded sets are returned as they are unless reload=True.

    Parameters
    ----------
    path : str or os.PathLike
        A set's directory or its declaration file.
    reload : bool, optional
        Load again even if loaded.

    Returns
    -------
    UserSet
    """
    from . import effects as E

    path = Path(path).expanduser().resolve()
    directory = sets_dir() / path.stem if path.suffix == ".py" else path
    directory = directory.resolve()
    if directory in _SETS and not reload:
        return _SETS[directory]
    s = UserSet(directory)
    s.check_current()
    old = _SETS.get(directory)
    for entry in s.meta.EFFECTS:
        prev = E.REGISTRY.get(entry["name"])
        if prev is not None and prev.source == "built-in":
            raise V.LavenderInputError("user effects", f"{entry['name']!r} in {s.meta.DECLARATION} is the name of a "
                                       "built-in effect; rename it")
        code = prev.code if (prev is not None and old is not None and prev.user_set is old) else None
        if code is None:
            user_codes = [c for c in E.BY_CODE if c >= E.USER_CODE_BASE]
            code = max(user_codes, default=E.USER_CODE_BASE - 1) + 1
        E.register(E.EffectSpec.from_meta(entry, code=code, source=str(directory), user_set=s))
    _SETS[directory] = s
    return s


def discover(name: str) -> UserSet | None:
    """Load the set in sets_dir() that declares effect `name`, if any (None otherwise).

    Parameters
    ----------
    name : str
        An effect name.

    Returns
    -------
    UserSet or None
    """
    root = sets_dir()
    if not root.is_dir():
        return None
    for d in sorted(p for p in root.iterdir() if (p / "effects_meta.py").is_file()):
        text = (d / "effects_meta.py").read_text(encoding="utf-8")
        if f"'name': {name!r}" in text or f'"name": {name!r}' in text:
            s = UserSet(d)
            if name in s.effect_names:
                return load(d)
    return None


def loaded() -> list[UserSet]:
    """The user sets loaded in this process."""
    return list(_SETS.values())
