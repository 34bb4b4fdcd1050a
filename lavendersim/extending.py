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

A set is identified by its declaration file: a declaration of the same name from another folder is
refused naming both files (while the first exists), and so is an effect name another set declares.
Each set has a manifest.json with the sha256 of the declaration, of every printed file and of the
compiled library; loading a set checks the printed files before importing them and the library
before the dynamic loader opens it, so an edited kernels.c, a swapped or truncated library, or a
declaration edited since (run the derive command again) raises :class:`UserSetError` rather than
simulating other equations or crashing. derive writes atomically: it prints and compiles first (the
library into build/ under a new content-hashed name), checks the library's symbols, then swaps the
set's folder in whole (lavendersim.derive.atomic); a declaration that fails anywhere leaves the last
good set in place.

A declaration file may also declare explicit Runge–Kutta tableaux (``TABLEAUX = [tableau(...)]``,
lavendersim.derive.user): loading the set registers them in lavendersim.backends.USER_TABLEAUX, and
``Sim(..., integrator=NAME)`` finds one by name in the user directory (:func:`tableau`).

Layers: lavendersim.user_sets finds and verifies sets (it imports neither effects nor this module);
lavendersim.effects registers a set's effects (it finds a set by effect name through user_sets); this
module derives sets and registers everything a set declares.
"""
from __future__ import annotations

import json
from pathlib import Path

from . import backends
from . import effects as E
from . import user_sets as U
from . import validate as V
from .user_sets import (CFLAGS, ENV, MANIFEST, MANIFEST_FORMAT, PRINTED, SOURCES, UserBuildError,  # noqa: F401
                        UserSet, UserSetError, compiler, read_manifest, sets_dir, user_dir)
from .user_sets import _compile, _manifest_or_none, _manifest_text, _set_error

def _meta_names(meta_text: str) -> tuple[list[str], list[str], list[str]]:
    ns: dict = {}
    exec(compile(meta_text, "effects_meta.py", "exec"), ns)
    return [e["name"] for e in ns["EFFECTS"]], list(ns["KERNELS"]), [t["name"] for t in ns.get("TABLEAUX", ())]


def _check_folder(directory: Path) -> None:
    """The set's folder holds only what derive writes (it is replaced whole): else OutputFolderError,
    before anything (the library's build/ included) is written into it."""
    from .derive.atomic import IGNORED, OutputFolderError

    if directory.exists() and not directory.is_dir():
        raise OutputFolderError(f"{directory} exists and is not a folder")
    if directory.is_dir():
        allowed = set(PRINTED) | {MANIFEST, "build"} | set(IGNORED)
        foreign = sorted(p.name for p in directory.iterdir() if p.name not in allowed)
        if foreign:
            raise OutputFolderError(f"{directory} holds {', '.join(foreign[:5])}{' …' if len(foreign) > 5 else ''}, "
                                    "which derive did not write; derive replaces the set's folder as a whole, so move "
                                    "them away or derive into another folder (--out)")


def _check_identity(directory: Path, declaration: Path, set_name: str) -> Path | None:
    """Refuse a set folder derived from another declaration file that still exists (naming both); return
    that other file when it no longer exists (the set is replaced, and the caller says so)."""
    m = _manifest_or_none(directory)
    if m is None:
        return None
    prev = Path(m["declaration"])
    if prev == declaration:
        return None
    if prev.is_file():
        raise _set_error(f"{declaration} and {prev} both name the set {set_name!r} (a set is named by its file): "
                         f"{directory} holds the set derived from {prev}",
                         "; rename one of the files, or derive this one elsewhere with --out DIR")
    return prev


def _check_names(root: Path, directory: Path, declaration: Path, names: dict[str, list[str]]) -> None:
    """Refuse an effect or tableau name (names: {"effects": [...], "tableaux": [...]}) that another set under `root`
    declares, naming both declaration files."""
    if not root.is_dir() or not any(names.values()):
        return
    for d in sorted(root.iterdir()):
        if not d.is_dir() or d.resolve() == directory:
            continue
        m = _manifest_or_none(d)
        if m is None:
            continue
        for what, mine in names.items():
            clash = sorted(set(mine) & set(m.get(what, ())))
            kind = "effect" if what == "effects" else "tableau"
            if clash:
                raise _set_error(f"{kind} {clash[0]!r} of {declaration} is also declared by {m['declaration']} (set "
                                 f"{d})", f"; a{'n' * (kind == 'effect')} {kind} name belongs to one set: rename it in "
                                 f"one of the files, or remove the folder {d}")


def derive(declaration, out=None, compile: bool = True) -> UserSet:
    """Derive a declaration file: print its set, compile its C (cached), check the library, then swap the
    set's folder `out` (default sets_dir()) / <stem>/ in whole and load it. Imports SymPy (this is the
    derive step, not the simulation path). Anything that fails leaves the set that was there as it was.

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
        With ``replaced_declaration``: the other declaration file (no longer there) whose set of the same
        name this one replaced, else None.

    Raises
    ------
    lavendersim.derive.user.DeclarationError
        The declaration cannot be run or printed (one line naming the effect or kernel).
    UserSetError
        Another existing file of the same name owns the set's folder, or another set declares one of
        its effect or tableau names.
    UserBuildError
        No compiler, a refused ``$CC``, or the C does not compile.
    """
    from .derive.atomic import recover, replace_folder
    from .derive.user import render_user

    decl = Path(declaration).expanduser().resolve()
    set_name, printed = render_user(decl)
    files: dict[str, str | bytes] = dict(printed)
    root = (Path(out).expanduser() if out is not None else sets_dir()).resolve()
    directory = root / set_name
    if directory.parent.is_dir():
        recover(directory)   # an interrupted swap is repaired before the folder is judged
    _check_folder(directory)
    replaced = _check_identity(directory, decl, set_name)
    effects, kernels, tableaux = _meta_names(printed["effects_meta.py"])
    _check_names(root, directory, decl, {"effects": effects, "tableaux": tableaux})
    library, built = None, None
    if compile:
        library, built = _compile(directory, set_name, files, compiler(), (effects, set_name, kernels, str(decl)))
    files[MANIFEST] = _manifest_text(set_name, decl, files, effects, kernels, library, tableaux)
    replace_folder(directory, files, keep=("build",))
    s = load(directory, reload=True)
    s.replaced_declaration = replaced
    if compile:
        s.library()
        s.library_built_now = built
    return s




def build(directory) -> Path:
    """Compile a derived set's C (its printed files checked against its manifest) into build/ and record
    the library in the manifest; reuse it when the printed C and the compiler command are unchanged.

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
    UserSetError
        The set's files do not match its manifest.
    UserBuildError
        With the command and the compiler's full output.
    """
    s = UserSet(directory)
    if s.manifest.get("library") is None or compiler() != s.manifest["library"].get("compiler"):
        s.manifest, s.library_built_now = U._add_library(s)
    s.library()
    assert s.library_path is not None   # (the manifest names the library now)
    return s.library_path



def _check_tableaux(s: UserSet) -> None:
    """Raise if one of the set's tableaux is named as a built-in integrator or as another loaded set's tableau."""
    from .generated import tableaux as TB

    for t in s.tableaux:
        if t["name"] in TB.INTEGRATOR_CODES:
            raise V.LavenderInputError("user tableaux", f"{t['name']!r} in {s.declaration} is the name of a built-in "
                                       "integrator; rename it")
        prev = backends.USER_TABLEAUX.get(t["name"])
        if prev is not None and prev.source != str(s.directory):
            raise _set_error(f"tableau {t['name']!r} is declared by {s.declaration} (set {s.directory}) and by the set "
                             f"{prev.source}, loaded first", "; a tableau name belongs to one set: rename it in one of "
                             "the files")


def _register_tableaux(s: UserSet) -> None:
    """Register the set's tableaux in backends.USER_TABLEAUX (replacing the ones an earlier load of the same set
    registered, dropping those it no longer declares)."""
    for name in [n for n, t in backends.USER_TABLEAUX.items() if t.source == str(s.directory)]:
        del backends.USER_TABLEAUX[name]
    for t in s.tableaux:
        backends.USER_TABLEAUX[t["name"]] = backends.Tableau(t["name"], t["c"], t["A"], t["b"], t["order"],
                                                             str(s.directory), real_axis=t["real_axis"],
                                                             wdt_max=t["wdt_max"])


def load(path, reload: bool = False) -> UserSet:
    """Load and register a derived set: `path` is its directory, or its declaration file (then the set of
    that name in sets_dir(), which must have been derived from that very file). Registers its effects
    (lavendersim.effects) and its tableaux (lavendersim.backends.USER_TABLEAUX). Already loaded sets are
    returned as they are unless reload=True.

    Parameters
    ----------
    path : str or os.PathLike
        A set's directory or its declaration file.
    reload : bool, optional
        Load again even if loaded.

    Returns
    -------
    UserSet

    Raises
    ------
    UserSetError
        The set's files do not match its manifest; the set of that name was derived from another file;
        one of its effect or tableau names belongs to another loaded set.
    """
    s = U.open_set(U.directory_of(path), reload=reload)
    _check_tableaux(s)   # before the effects are registered: a clash leaves nothing half-registered
    E.register_set(s)
    _register_tableaux(s)
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

    Raises
    ------
    UserSetError
        Two sets declare it (naming both declaration files), or the set's files do not match its manifest.
    """
    d = U.find(name, "effects")
    return load(d) if d is not None else None


def tableau(name: str) -> backends.Tableau:
    """The user tableau `name`: registered already, or found in the user directory (its set is loaded).

    Parameters
    ----------
    name : str
        A tableau's name, as declared in ``TABLEAUX`` of a declaration file.

    Returns
    -------
    lavendersim.backends.Tableau

    Raises
    ------
    lavendersim.validate.LavenderInputError
        No loaded or derived set declares it (naming the built-in integrators and the known tableaux).
    UserSetError
        Two sets declare it, or its set's files do not match its manifest.
    """
    if isinstance(name, str) and name not in backends.USER_TABLEAUX and name not in backends.INTEGRATORS:
        opened = [o.directory for o in U.opened() if name in o.tableau_names]   # e.g. by effects.load_user(DIR)
        d = opened[0] if opened else U.find(name, "tableaux")
        if d is not None:
            load(d)
    tab = backends.USER_TABLEAUX.get(name) if isinstance(name, str) else None
    if tab is None:
        V.choice("integrator", name, list(backends.INTEGRATORS) + list(backends.USER_TABLEAUX))
        raise V.LavenderInputError("integrator", f"{name!r} is a built-in integrator, not a user tableau")
    return tab


def loaded() -> list[UserSet]:
    """The user sets loaded in this process."""
    return U.opened()
