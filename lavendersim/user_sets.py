"""Finding and verifying derived user sets (the layer under lavendersim.extending; it registers nothing).

A user set is the folder ``lavendersim derive --user FILE`` writes (docs/extending.md): printed files, a
manifest.json with their sha256, and a compiled library. This module finds a set by the effect or tableau it
declares (:func:`find`), opens it with every file checked against the manifest (:func:`open_set`,
:class:`UserSet`), and compiles its C (cached by content). Registering what a set declares is done by its
users: lavendersim.effects registers the set's effects (effects.register_set), lavendersim.extending its
tableaux as well (extending.load). Neither is imported here, so the three form no import circle (issue 29).
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import types
from collections.abc import Sequence
from pathlib import Path

from . import validate as V
from .errors import PicklableError

ENV = "LAVENDERSIM_USER_DIR"
# never -ffast-math; -fno-semantic-interposition: the exported effects inline into their tile forms (vectorized)
CFLAGS = ["-O3", "-std=c99", "-fno-math-errno", "-ffp-contract=off", "-fno-semantic-interposition", "-fPIC", "-shared",
          "-fvisibility=hidden"]
SOURCES = ("kernels.c", "kernels.h")
PRINTED = ("kernels.h", "kernels.c", "kernels_numpy.py", "kernels_casadi.py", "effects_meta.py", "EQUATIONS.md")
MANIFEST = "manifest.json"
MANIFEST_FORMAT = 1

_SETS: dict[Path, "UserSet"] = {}  # loaded sets by directory


class UserBuildError(PicklableError, RuntimeError):
    """Compiling a user set's C failed, no compiler was found, or ``$CC`` names none.

    Parameters
    ----------
    summary : str
        One line: what failed, the compiler's first error line and where its full output is.
    output : str, optional
        The command line and the compiler's full output (also in ``str(exc)``).
    log : str or None, optional
        The file holding the full output.
    """

    _init_fields = ("summary", "output", "log")   # crosses process boundaries with them (errors.PicklableError)

    def __init__(self, summary: str, output: str = "", log: str | None = None):
        self.summary, self.output, self.log = summary, output, log
        super().__init__(summary + (f"\n{output}" if output else ""))


class UserSetError(V.LavenderInputError):
    """A user set that cannot be used as it is: two declaration files of one name, an effect name two
    sets declare, or files that do not match the set's manifest.json (edited, swapped, truncated).
    The message names the files and the command that repairs it.

    Parameters
    ----------
    field : str
        Always ``"user set"``.
    rule : str
        What is wrong, naming the files.
    detail : str, optional
        The command that repairs it.
    """


def _set_error(rule: str, detail: str = "") -> UserSetError:
    return UserSetError("user set", rule, detail)


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
    """The C compiler command: ``$CC`` (split like a shell word list) when set, else cc, else gcc.

    Raises
    ------
    UserBuildError
        ``$CC`` is set but names no executable (it is never silently replaced by another compiler),
        or it is unset and neither cc nor gcc is found.
    """
    cc = os.environ.get("CC", "")
    if cc.strip():
        try:
            cmd = shlex.split(cc)
        except ValueError as exc:
            raise UserBuildError(f"CC={cc!r} cannot be split into a command ({exc}); set CC to a C compiler, "
                                 "e.g. CC=gcc, or unset it to use cc/gcc") from None
        if not shutil.which(cmd[0]):
            raise UserBuildError(f"CC={cc!r}: {cmd[0]!r} is not an executable compiler (not found on PATH); set CC to a C "
                                 "compiler, e.g. CC=gcc, or unset it to use cc/gcc")
        return cmd
    for c in ("cc", "gcc"):
        if shutil.which(c):
            return [c]
    raise UserBuildError("no C compiler found to build user effects for the C backend: set CC or install cc/gcc "
                         "(the NumPy backend needs none)")


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _module(name: str, path: Path, source: bytes) -> types.ModuleType:
    """A module run from `source` (the bytes just checked against the manifest, not a second read)."""
    module = types.ModuleType(name)
    module.__file__ = str(path)
    exec(compile(source, str(path), "exec"), module.__dict__)
    return module


def read_manifest(directory) -> dict:
    """A set's manifest.json (format, set name, declaration and its sha256, effects, kernels, the sha256 of
    every printed file, the library's file, sha256 and compiler command).

    Parameters
    ----------
    directory : str or os.PathLike
        The set's folder.

    Returns
    -------
    dict
        The manifest, as derive wrote it.

    Raises
    ------
    UserSetError
        No manifest (not a set, or one derived by an older lavendersim), or not a manifest.
    """
    directory = Path(directory)
    path = directory / MANIFEST
    try:
        m = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        what = "an older lavendersim's set" if (directory / "effects_meta.py").is_file() else "not a derived set"
        raise _set_error(f"{directory} has no {MANIFEST} ({what}); run `lavendersim derive --user FILE`") from None
    except (OSError, ValueError) as exc:
        raise _set_error(f"{path} cannot be read as a set manifest ({exc}); run `lavendersim derive --user FILE` "
                         "again") from None
    ok = (isinstance(m, dict) and m.get("format") == MANIFEST_FORMAT and isinstance(m.get("files"), dict)
          and set(PRINTED) <= set(m["files"]) and isinstance(m.get("declaration"), str)
          and isinstance(m.get("effects"), list) and (m.get("library") is None or _library_entry_ok(m["library"])))
    if not ok:
        raise _set_error(f"{path} is not a set manifest of this lavendersim; run `lavendersim derive --user "
                         f"{m.get('declaration', 'FILE') if isinstance(m, dict) else 'FILE'}` again")
    return m


def _library_entry_ok(e) -> bool:
    return (isinstance(e, dict) and isinstance(e.get("file"), str) and isinstance(e.get("sha256"), str)
            and re.fullmatch(r"build/[A-Za-z0-9_][A-Za-z0-9_.-]*", e["file"]) is not None)   # no "..", no dot files


def _manifest_or_none(directory: Path) -> dict | None:
    try:
        return read_manifest(directory)
    except UserSetError:
        return None


def _verified(directory: Path, name: str, want: str, declaration: str) -> bytes:
    """The bytes of a set's file, if they have the sha256 the manifest records (else UserSetError)."""
    path = directory / name
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise _set_error(f"{path} cannot be read ({exc.strerror or exc})",
                         f"; run `lavendersim derive --user {declaration}` again") from None
    return _check_bytes(path, data, want, declaration)


def _check_bytes(path: Path, data: bytes, want: str, declaration: str) -> bytes:
    got = _sha(data)
    if got != want:
        raise _set_error(f"{path} does not match the set's {MANIFEST} (sha256 {got[:12]}…, manifest {want[:12]}…; "
                         f"{len(data)} bytes): it was edited, replaced or cut after derive wrote it",
                         f"; run `lavendersim derive --user {declaration}` again")
    return data


class UserSet:
    """A derived user set: its metadata, NumPy module, CasADi module (on demand) and compiled library
    (on demand, built when the set was derived without it). Every file is checked against the set's
    manifest.json before it is imported or loaded.

    Parameters
    ----------
    directory : str or os.PathLike
        The folder ``lavendersim derive --user`` wrote for the set.

    Raises
    ------
    UserSetError
        No manifest, or a printed file that does not match it.
    """

    def __init__(self, directory: Path):
        self.directory = Path(directory).resolve()
        if not self.directory.is_dir():
            raise _set_error(f"{self.directory} is not a derived set (no such folder); run `lavendersim derive --user FILE`")
        self.manifest = read_manifest(self.directory)
        self.declaration = Path(self.manifest["declaration"])
        src = {n: self._file(n) for n in PRINTED}   # every printed file checked before any is run
        tag = _sha(str(self.directory).encode())[:12]
        self.meta = _module(f"lavendersim_user_meta_{tag}", self.directory / "effects_meta.py", src["effects_meta.py"])
        self.name = self.meta.SET_NAME
        self.effect_names = [e["name"] for e in self.meta.EFFECTS]
        self.kernel_names = list(self.meta.KERNELS)
        self.tableaux = tuple(getattr(self.meta, "TABLEAUX", ()))   # printed by derive/user.py (none before)
        self.tableau_names = [t["name"] for t in self.tableaux]
        self.numpy = _module(f"lavendersim_user_{self.name}_numpy_{tag}", self.directory / "kernels_numpy.py",
                             src["kernels_numpy.py"])
        self._casadi: types.ModuleType | None = None
        self._lib: ctypes.CDLL | None = None
        self.replaced_declaration: Path | None = None   # set by extending.derive_user when it replaced another set
        lib = self.manifest.get("library")
        self.library_path: Path | None = self.directory / lib["file"] if lib else None
        self.library_built_now: bool | None = None  # True: compiled by this process; False: reused from the cache

    def _file(self, name: str) -> bytes:
        return _verified(self.directory, name, self.manifest["files"][name], str(self.declaration))

    def check_current(self) -> None:
        """Raise if the declaration this set was derived from exists and has changed since."""
        decl = self.declaration
        if decl.is_file() and _sha(decl.read_bytes()) != self.manifest.get("declaration_sha256"):
            raise V.LavenderInputError("user effects", f"{decl} changed since the set {self.name!r} was derived "
                                       f"into {self.directory}: run `lavendersim derive --user {decl}`")

    @property
    def casadi(self):
        """The set's printed CasADi module (needs the control extra)."""
        if self._casadi is None:
            from ._install import require

            require("casadi", "control", "the CasADi expressions of user effects")
            path = self.directory / "kernels_casadi.py"
            self._casadi = _module(f"lavendersim_user_{self.name}_casadi", path, self._file("kernels_casadi.py"))
        return self._casadi

    def library(self) -> ctypes.CDLL:
        """The compiled library, its sha256 checked against the manifest before the dynamic loader maps it
        (compiled now, atomically, when the set was derived without it)."""
        if self._lib is None:
            if self.manifest.get("library") is None:
                self.manifest, self.library_built_now = _add_library(self)
            entry = self.manifest["library"]
            self.library_path = path = self.directory / entry["file"]
            try:
                fd = os.open(path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
            except OSError as exc:
                raise _set_error(f"{path} cannot be read ({exc.strerror or exc})",
                                 f"; run `lavendersim derive --user {self.declaration}` again") from None
            try:   # the file checked is the file loaded: the same inode before and after the loader opens the path
                with os.fdopen(os.dup(fd), "rb") as f:
                    _check_bytes(path, f.read(), entry["sha256"], str(self.declaration))
                ident = _file_id(os.fstat(fd))
                same = _file_id(os.stat(path)) == ident
                lib = _open_library(path, self.effect_names, self.name, self.kernel_names, str(self.declaration))
                self._check_tableaux(lib, path)
                if not (same and _file_id(os.stat(path)) == ident):
                    raise _set_error(f"{path} was replaced while it was being checked and loaded",
                                     "; load the set again")
                self._lib = lib
            finally:
                os.close(fd)
        return self._lib

    def _check_tableaux(self, lib: ctypes.CDLL, path: Path) -> None:
        """The library's lvu_tableau_<name> arrays hold the very doubles of effects_meta.TABLEAUX (c, A, b)."""
        for t in self.tableaux:
            want = list(t["c"]) + [v for row in t["A"] for v in row] + list(t["b"])
            try:
                got = list((ctypes.c_double * len(want)).in_dll(lib, f"lvu_tableau_{t['name']}"))
            except ValueError:
                got = None
            if got != want:
                raise _set_error(f"{path}: tableau {t['name']!r} is {'missing' if got is None else 'not the same doubles'}"
                                 " in the library and in effects_meta.py", f"; run `lavendersim derive --user "
                                 f"{self.declaration}` again")

    def c_function(self, effect: str, body: bool = False) -> int:
        """Address of the compiled accumulating function of one of the set's effects.

        Parameters
        ----------
        effect : str
            An effect of this set.
        body : bool, optional
            Its body-frame form instead (``lvu_effect_<name>_b``: the torque added in the body frame), which an
            effect declaring ``torque_b`` alone has (FLAG_TORQUE_B in its flags).

        Returns
        -------
        int
            The C function's address (the C backend calls it per body).

        Raises
        ------
        UserSetError
            body, and the library does not export the body-frame form.
        """
        symbol = f"lvu_effect_{effect}_b" if body else f"lvu_effect_{effect}"
        fn = getattr(self.library(), symbol, None)
        if fn is None:
            raise _set_error(f"{self.library_path} does not export {symbol}",
                             f"; run `lavendersim derive --user {self.declaration}` again")
        address = ctypes.cast(fn, ctypes.c_void_p).value
        assert address is not None, effect   # (a symbol dlsym found is never NULL)
        return address

    def c_fused_tiles(self, effect: str) -> tuple[int, ...]:
        """Addresses of an effect's fused tiles (derive/effect_fuse_user.py), q raw then normalized, each per
        instruction set (base, avx2, avx512); zeros when the library has none, or was compiled against other engine
        sources than this lavendersim's (its lvu_engine_hash: the engine then steps the effect in stage passes)."""
        from .generated import effects_meta
        lib = self.library()
        try:
            built = ctypes.c_char.in_dll(lib, "lvu_engine_hash")
            got = ctypes.string_at(ctypes.addressof(built)).decode("ascii", "replace")
        except ValueError:
            got = None
        out, current = [], got is not None and got == engine_hash()
        for norm in ("raw", "norm"):
            for isa in effects_meta.TILE_ISAS:
                fn = getattr(lib, f"lvu_fused_tile{effects_meta.TILE_LANES}_{effect}_{norm}_{isa}", None)
                out.append(0 if fn is None or not current else ctypes.cast(fn, ctypes.c_void_p).value or 0)
        return tuple(out)

    def c_tile_functions(self, effect: str, body: bool = False) -> tuple[int, int, int]:
        """Addresses of an effect's tile form (body: its body-frame form's) for the C SIMD tiles, per instruction set
        (base, avx2, avx512); 0 where the library has none (a library built before tile forms, or a copy this
        platform lacks)."""
        from .generated import effects_meta
        lib = self.library()
        out = []
        for isa in effects_meta.TILE_ISAS:
            fn = getattr(lib, f"lvu_effect_tile{effects_meta.TILE_LANES}_{effect}{'_b' if body else ''}_{isa}", None)
            out.append(0 if fn is None else ctypes.cast(fn, ctypes.c_void_p).value or 0)
        return out[0], out[1], out[2]


def engine_hash() -> str | None:
    """The hash of the C engine's generated sources (the extension's GENERATED_HASH, which lavendersim's C backend
    checks against the files it runs), or None when the extension is not built."""
    try:   # loaded by name, as backends.c_backend does (an import statement would read as a circle to the scans)
        ext = importlib.import_module("lavendersim._lavender_c")
    except ImportError:
        return None
    return str(ext.GENERATED_HASH)


def engine_flags() -> list[str]:
    """The compiler flags that give a user set's library the engine's generated C sources (its fused tiles, see
    lavendersim/derive/effect_fuse_user.py): their folder on the include path and their hash (engine_hash) as
    LVU_ENGINE; [] without the C extension or its generated sources (then the library has no fused tiles, and the
    engine steps the user's effects in stage passes)."""
    from . import generated

    gen = Path(generated.__file__).resolve().parent
    want = engine_hash()
    if want is None or not all((gen / n).is_file() for n in ("kernels.c", "kernels.h", "layout.h", "tableaux.h")):
        return []
    return ["-I", str(gen), f'-DLVU_ENGINE="{want}"']


def _file_id(st: os.stat_result) -> tuple[int, int, int, int]:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _open_library(path: Path, effects, set_name: str, kernels, declaration: str) -> ctypes.CDLL:
    """Load a library and check its ABI version and that it exports every effect and kernel of the set."""
    from .generated import effects_meta

    shown = path
    try:
        lib = ctypes.CDLL(str(path))
        abi = ctypes.c_int.in_dll(lib, "lvu_abi_version").value
    except (OSError, ValueError) as exc:
        raise _set_error(f"{shown} is not a loadable library of the set ({exc})",
                         f"; run `lavendersim derive --user {declaration}` again") from None
    if abi != effects_meta.ABI_VERSION:
        raise _set_error(f"{shown}: built for effect ABI {abi}, this lavendersim uses {effects_meta.ABI_VERSION}",
                         f"; run `lavendersim derive --user {declaration}`")
    want = [f"lvu_effect_{e}" for e in effects] + [f"lvu_{set_name}_{k}" for k in kernels]
    missing = [s for s in want if not hasattr(lib, s)]
    if missing:
        raise _set_error(f"{shown} does not export {', '.join(missing)}",
                         f"; run `lavendersim derive --user {declaration}` again")
    return lib


def _library_name(set_name: str, sources: dict, cmd: list[str]) -> str:
    h = hashlib.sha256()
    for name in SOURCES:
        data = sources[name]
        h.update(f"{name} {_sha(data.encode() if isinstance(data, str) else data)}\n".encode())
    h.update(" ".join(cmd).encode())
    suffix = ".dll" if os.name == "nt" else ".so"
    return f"lib{set_name}-{h.hexdigest()[:16]}{suffix}"


def _first_error(output: str) -> str:
    lines = [ln.strip() for ln in output.splitlines() if ln.strip()]
    for ln in lines:
        if re.search(r"\berror\b", ln, re.I):
            return ln
    return lines[-1] if lines else "no output"


def _remove_dead_compiles(root: Path, set_name: str) -> None:
    """Temporary compile folders of this set left by processes that no longer run (killed mid-compile)."""
    from .derive.atomic import _alive

    for p in root.glob(f".{set_name}.compile-*"):
        m = re.fullmatch(re.escape(f".{set_name}.compile-") + r"(\d+)-\w+", p.name)
        if m and p.is_dir() and not p.is_symlink() and not _alive(int(m[1])):
            shutil.rmtree(p, ignore_errors=True)


def _compile(directory: Path, set_name: str, sources: dict, cmd: list[str], symbols: tuple) -> tuple[dict, bool]:
    """The library entry of the manifest for these printed sources: reused when the set's current manifest
    names a library of this name whose bytes still match it, else compiled in a temporary folder, loaded
    and checked (ABI and every symbol), then moved into directory/build/ under its content-hashed name
    (never over a library the current manifest uses unless it no longer matches it).
    Returns (entry, compiled now)."""
    engine = engine_flags()
    name = _library_name(set_name, sources, cmd + engine)
    rel = f"build/{name}"
    entry = {"file": rel, "compiler": cmd}
    old = _manifest_or_none(directory)
    path = directory / rel
    if old and old.get("library") and old["library"]["file"] == rel and path.is_file():
        digest = _sha(path.read_bytes())
        if digest == old["library"]["sha256"]:
            return {**entry, "sha256": digest}, False
    root = directory.parent
    log = root / f"{set_name}.compile.log"
    root.mkdir(parents=True, exist_ok=True)
    _remove_dead_compiles(root, set_name)
    with tempfile.TemporaryDirectory(prefix=f".{set_name}.compile-{os.getpid()}-", dir=root) as tmp_dir:
        tmp = Path(tmp_dir)
        for n in SOURCES:
            (tmp / n).write_text(sources[n], encoding="utf-8")
        full = cmd + CFLAGS + engine + [str(tmp / "kernels.c"), "-o", str(tmp / name), "-lm"]
        try:
            r = subprocess.run(full, capture_output=True, text=True, cwd=tmp)
        except OSError as exc:
            raise UserBuildError(f"compiling the user set {set_name!r} failed to start ({' '.join(cmd)}: "
                                 f"{exc.strerror or exc}); the last good set is unchanged") from None
        if r.returncode != 0:
            output = f"$ {' '.join(full)}\n{r.stdout}{r.stderr}".rstrip()
            log.write_text(output + "\n", encoding="utf-8")
            raise UserBuildError(f"compiling the user set {set_name!r} failed (exit {r.returncode}): "
                                 f"{_first_error(r.stdout + r.stderr)} — full output in {log}; the last good set "
                                 "is unchanged", output, str(log))
        _open_library(tmp / name, *symbols)
        data = (tmp / name).read_bytes()
        path.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp / name, path)
    log.unlink(missing_ok=True)
    return {**entry, "sha256": _sha(data)}, True


def _manifest_text(set_name: str, declaration: Path, files: dict, effects: list, kernels: list,
                   library: dict | None, tableaux: Sequence = ()) -> str:
    m = {"format": MANIFEST_FORMAT, "set_name": set_name, "declaration": str(declaration),
         "declaration_sha256": _sha(declaration.read_bytes()), "effects": list(effects), "kernels": list(kernels),
         "tableaux": list(tableaux),
         "files": {n: _sha(files[n].encode() if isinstance(files[n], str) else files[n]) for n in PRINTED},
         "library": library}
    return json.dumps(m, indent=1, sort_keys=True) + "\n"


def _add_library(s: UserSet) -> tuple[dict, bool]:
    """Compile the library of a set derived without it and record it in its manifest (folder swapped whole)."""
    from .derive.atomic import replace_folder

    files = {n: s._file(n) for n in PRINTED}
    sources = {n: files[n].decode("utf-8") for n in SOURCES}
    library, built = _compile(s.directory, s.name, sources, compiler(),
                              (s.effect_names, s.name, s.kernel_names, str(s.declaration)))
    text = _manifest_text(s.name, s.declaration, files, s.manifest["effects"], s.manifest.get("kernels", []), library,
                          s.manifest.get("tableaux", []))
    m = json.loads(text)
    m["declaration_sha256"] = s.manifest.get("declaration_sha256")   # the set's declaration, not today's file
    replace_folder(s.directory, {**files, MANIFEST: json.dumps(m, indent=1, sort_keys=True) + "\n"}, keep=("build",))
    return m, built


def open_set(directory, reload: bool = False) -> UserSet:
    """The verified set in `directory`: the one already opened in this process when its manifest is unchanged
    (and reload is False), else opened and checked afresh (its files against its manifest, its declaration
    unchanged since it was derived).

    Parameters
    ----------
    directory : str or os.PathLike
        The set's folder.
    reload : bool, optional
        Open it again even if it is open.

    Returns
    -------
    UserSet

    Raises
    ------
    UserSetError
        The set's files do not match its manifest.
    lavendersim.validate.LavenderInputError
        Its declaration changed since it was derived.
    """
    directory = Path(directory).expanduser().resolve()
    s = _SETS.get(directory)
    if s is not None and not reload and _manifest_or_none(directory) == s.manifest:
        return s   # (a folder derived again since, from this file or another, is opened again)
    s = UserSet(directory)
    s.check_current()
    _SETS[directory] = s
    return s


def directory_of(path) -> Path:
    """The set folder of `path`: a set's directory as given, or for a declaration file (``.py``) the set of that
    name in sets_dir(), which must have been derived from that very file.

    Raises
    ------
    UserSetError
        No set derived from that file there, or that set was derived from another file.
    """
    path = Path(path).expanduser().resolve()
    if path.suffix != ".py":
        return path
    directory = (sets_dir() / path.stem).resolve()
    m = read_manifest(directory) if directory.is_dir() else None
    if m is None:
        raise _set_error(f"no set derived from {path} in {sets_dir()}", f"; run `lavendersim derive --user {path}`")
    if Path(m["declaration"]) != path:
        raise _set_error(f"{directory} holds the set derived from {m['declaration']}, not from {path} (a set is "
                         "named by its file)", "; rename one of the files and derive it")
    return directory


def find(name: str, what: str = "effects") -> Path | None:
    """The folder of the set in sets_dir() that declares effect (what="effects") or tableau (what="tableaux")
    `name`, or None.

    Raises
    ------
    UserSetError
        Two sets declare it (naming both declaration files).
    """
    root = sets_dir()
    if not root.is_dir():
        return None
    found = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        m = _manifest_or_none(d)
        if m is not None:
            if name in m.get(what, ()):
                found.append((d, m["declaration"]))
        elif (d / "effects_meta.py").is_file():   # no (valid) manifest: loading it says what to do
            text = (d / "effects_meta.py").read_text(encoding="utf-8", errors="replace")
            if f"'name': {name!r}" in text or f'"name": {name!r}' in text:
                found.append((d, "an unknown file"))
    if len(found) > 1:
        (d1, f1), (d2, f2) = found[:2]
        kind = what[:-1] if what == "effects" else "tableau"
        raise _set_error(f"{kind} {name!r} is declared by {f1} (set {d1}) and by {f2} (set {d2})",
                         f"; a{'n' * (kind == 'effect')} {kind} name belongs to one set: rename it in one of the files "
                         "and derive it again")
    return found[0][0] if found else None


def opened() -> list[UserSet]:
    """The user sets opened in this process."""
    return list(_SETS.values())
