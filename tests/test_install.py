"""A light install as a new user meets it: lazy imports, missing extras named in one line (exit 2),
backend="auto" falling back to NumPy with one warning, --version, python -m lavendersim."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import warnings

import pytest

import lavendersim
from lavendersim import _install, backends


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), *args], capture_output=True, text=True,
                          timeout=600)


# A child process in which the named top-level packages cannot be imported (as if their extra were
# not installed), then runs the lavendersim command line with the given arguments.
_WITHOUT = """
import sys
blocked = set(sys.argv[1].split(","))

class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in blocked:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, Block())
from lavendersim.cli import main
sys.exit(main(sys.argv[2:]))
"""


def run_without(blocked: str, *args: str) -> subprocess.CompletedProcess:
    return _python(_WITHOUT, blocked, *args)


def test_import_lavendersim_is_light():
    r = _python("""
        import sys, lavendersim
        heavy = [m for m in ("gymnasium", "sympy", "scipy.integrate", "casadi", "control", "viser", "numpy")
                 if m in sys.modules]
        print(",".join(heavy))
        lavendersim.Sim  # the public names load on first use
        print(",".join(m for m in ("gymnasium", "sympy", "scipy.integrate") if m in sys.modules))
    """)
    assert r.returncode == 0, r.stderr
    first, second = r.stdout.splitlines()
    assert first == "" and second == ""


def test_every_public_name_loads():
    for name in lavendersim.__all__:
        assert getattr(lavendersim, name) is not None, name
    with pytest.raises(AttributeError):
        lavendersim.NoSuchThing  # noqa: B018


@pytest.mark.needs("gym")   # tests/conftest.py: skipped without gymnasium, failed under CI=true
def test_gym_id_works_whichever_is_imported_first():
    for order in ("import lavendersim, gymnasium as gym", "import gymnasium as gym, lavendersim", "import gymnasium as gym"):
        r = _python(f"""
            {order}
            env = gym.make("lavendersim:ReactionWheelCube-v0")
            obs, _ = env.reset(seed=0)
            print(obs.shape)
        """)
        assert r.returncode == 0, (order, r.stderr)
        assert r.stdout.strip() == "(10,)", (order, r.stdout)


def test_version_and_python_m():
    r = subprocess.run([sys.executable, "-m", "lavendersim", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == f"lavendersim {lavendersim.__version__}"


@pytest.mark.parametrize("blocked, args, extra", [
    ("casadi,control", ["lqr"], "control"),
    ("viser", ["view", "tumble", "--duration", "0.1", "--port", "0"], "viewer"),
    ("viser", ["lab", "03", "--view", "--out", "OUT"], "viewer"),
])
def test_a_missing_extra_is_one_line_and_exit_2(blocked, args, extra, tmp_path):
    args = [str(tmp_path) if a == "OUT" else a for a in args]
    r = run_without(blocked, *args)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    # the editable install names its own source folder; never the index's `lavendersim` (another project)
    assert f"needs the {extra} extra: pip install -e '" in lines[0] and f"[{extra}]'" in lines[0], lines[0]
    assert "'lavendersim[" not in lines[0]
    assert "Traceback" not in r.stderr


def test_the_env_without_gymnasium_names_the_gym_extra():
    r = _python("""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] == "gymnasium":
                    raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        sys.meta_path.insert(0, Block())
        import lavendersim
        try:
            from lavendersim.envs import ReactionWheelCubeEnv
        except lavendersim.MissingExtraError as exc:
            print(exc.extra)
    """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "gym"


def test_require_rejects_a_module_of_another_extra():
    with pytest.raises(ValueError):
        _install.require("numpy", "control", "x")


def test_a_bad_option_value_is_one_line_and_exit_2(tmp_path):
    r = subprocess.run([sys.executable, "-m", "lavendersim", "lab", "01", "--dt", "-1", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_auto_falls_back_to_numpy_with_one_warning(monkeypatch):
    monkeypatch.setattr(backends, "_c_problem", "the C extension is not built (test)")
    monkeypatch.setattr(backends, "_fallback_warned", False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert backends.resolve("auto") == "numpy"
        assert backends.resolve("auto") == "numpy"
        sc = lavendersim.Scene()
        sc.add_body(lavendersim.Body.box("b", 1.0, (0.1, 0.2, 0.3), omega_b=(0, 0, 1)))
        sim = lavendersim.Sim(sc)
    assert sim.backend.name == "numpy"
    fallbacks = [w for w in caught if issubclass(w.category, backends.BackendFallbackWarning)]
    assert len(fallbacks) == 1 and "not built (test)" in str(fallbacks[0].message)
    assert backends.resolve("numpy") == "numpy"


def test_auto_is_c_when_the_extension_is_current():
    # the C backend is part of `pip install -e .` (test_c_backend.py requires it too)
    assert backends.c_unavailable() is None, backends.c_unavailable()
    assert backends.resolve("auto") == "c"


def test_rebuild_command_fits_an_editable_install(monkeypatch, tmp_path):
    monkeypatch.setattr(_install, "_direct_url", lambda: {"url": tmp_path.as_uri(), "dir_info": {"editable": True}})
    assert _install.rebuild_command() == f"pip install -e {tmp_path}"
    monkeypatch.setattr(_install, "_direct_url", lambda: {"url": tmp_path.as_uri(), "dir_info": {}})
    assert _install.rebuild_command() == f"pip install --force-reinstall --no-deps {tmp_path}"
    monkeypatch.setattr(_install, "_direct_url", lambda: {"url": "https://files.example/lavendersim.whl", "archive_info": {}})
    assert _install.rebuild_command() == "pip install --force-reinstall --no-deps lavender-rigid-body"
    monkeypatch.setattr(_install, "_direct_url", lambda: None)
    assert _install.rebuild_command().startswith("pip install -e .")


def test_every_package_folder_is_in_the_wheel():
    """pyproject lists the packages a wheel (a non-editable install) carries. An editable install finds any
    folder with an __init__.py, so a package missing from the list works here and is absent from a wheel: the
    CLI package went missing that way once (lavendersim/cli/, session 14)."""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    tool = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed, remap = set(tool["packages"]), tool["package-dir"]
    found = set()
    for name, folder in remap.items():
        for init in (root / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(root / folder).parts
            if "__pycache__" not in rel and not any(p.startswith(".") for p in rel):
                found.add(".".join((name, *rel)))
    assert found <= listed, f"packages missing from pyproject's [tool.setuptools] packages: {sorted(found - listed)}"


def _tracked_files(root) -> set[str] | None:
    try:
        r = subprocess.run(["git", "ls-files"], cwd=root, capture_output=True, text=True, timeout=120)
    except OSError:
        return None
    return set(r.stdout.split()) if r.returncode == 0 and r.stdout else None


def test_the_sdist_holds_every_tracked_file(monkeypatch):
    """The sdist is the whole project: its tests, notebooks and docs site need the files they read (the
    sdist of session 13 lacked notebooks/, docs/conf.py, docs/api* and .ci/sanitize, and its test run failed).
    MANIFEST.in is applied as setuptools' sdist applies it (its FileList) to this checkout; every file git
    tracks must be matched, except the three below. A built sdist agreed (session 15: `python -m build
    --sdist`, then its listing against `git ls-files`)."""
    from pathlib import Path

    from setuptools.command.egg_info import FileList

    root = Path(__file__).resolve().parents[1]
    tracked = _tracked_files(root)
    if tracked is None:
        pytest.skip("not a git checkout (an unpacked sdist): nothing to compare the manifest with")
    monkeypatch.chdir(root)
    files = FileList()
    files.findall(".")
    for line in (root / "MANIFEST.in").read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            files.process_template_line(line.strip())
    shipped = {str(Path(f)) for f in files.files}
    # not needed by anything in the sdist: the two ignore files; docs/nb is a link whose target
    # (notebooks/*.ipynb) the sdist stores as copies under docs/nb/
    left_out = {".gitignore", "docs/.gitignore", "docs/nb"}
    missing = sorted(tracked - shipped - left_out)
    assert not missing, f"tracked files MANIFEST.in does not put in the sdist: {missing}"
    assert {"docs/nb/force.ipynb", "notebooks/force.ipynb", "docs/conf.py", ".ci/sanitize"} <= shipped


def test_the_classifiers_claim_only_what_ci_tests():
    """CI runs CPython 3.11 on Linux (.ci/run); the classifiers name no other version or system."""
    import tomllib
    from pathlib import Path

    classifiers = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]["classifiers"]
    versions = [c for c in classifiers if c.startswith("Programming Language :: Python :: 3.")]
    systems = [c for c in classifiers if c.startswith("Operating System ::")]
    assert versions == ["Programming Language :: Python :: 3.11"], versions
    assert systems == ["Operating System :: POSIX :: Linux"], systems
