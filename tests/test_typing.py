"""Types reach users (issue 31): type checkers see LavenderSim through the README's editable install, and the public
signatures survive the validation decorator (`validate.keywords` is typed with ParamSpec).

Setuptools' default editable install puts an import hook in site-packages, which neither mypy nor pyright runs
(they never execute code), and LavenderSim's package-dir remap (lavendersim.generated -> generated/, ...) rules
out a plain path entry. pyproject.toml therefore makes `pip install -e .` setuptools' strict editable mode, a tree
of links that both follow; a file added to the clone after the install is found by lavendersim's own import hook.
The slow tests install a copy of the tree with the README's plain command into a venv (once for the module) and
run mypy and pyright (basedpyright, the test extra's pip-installable build of pyright with its own Node.js) on a
user's snippet against it; one more install checks the documented opt-out to the import hook."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]

SNIPPET = '''\
import lavendersim as lv

reveal_type(lv.Body.box)
reveal_type(lv.Sim)
cube = lv.Body.box(name="cube", mass="heavy", size=(0.1, 0.1, 0.1))
reveal_type(lv.Sim.__init__)
'''


def _env() -> dict[str, str]:
    """This environment without PYTHONPATH: the venv must find lavendersim through its install, not a source tree."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def _copy_tree(dst: Path) -> None:
    shutil.copytree(ROOT, dst, ignore=shutil.ignore_patterns(".git", "build", "*.so", "__pycache__", "*.egg-info",
                                                               ".pytest_cache", ".mypy_cache", "_build", ".hypothesis"))


def _outer_site_dirs() -> list[str]:
    """This environment's site-packages folders (where the dependencies are)."""
    import site

    return [d for d in [*site.getsitepackages(), site.getusersitepackages()] if Path(d).is_dir()]


def _install(tmp: Path, *options: str) -> Path:
    """A venv with a copy of the tree installed editable by pip: the README's `pip install -e .` (with `--no-deps`:
    the dependencies are this environment's) plus `options`. Returns the venv's python.

    The venv sees this environment's site-packages as plain path entries (a .pth listing the folders), not as site
    folders (`--system-site-packages`): their .pth files are not run, so this environment's own editable install of
    LavenderSim (CI's strict one puts its link tree on sys.path, and a path entry wins over a lenient install's
    import hook) cannot shadow the venv's."""
    src, venv = tmp / "src", tmp / "venv"
    _copy_tree(src)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    (site_packages,) = venv.glob("lib/python*/site-packages")
    (site_packages / "zz_outer_environment.pth").write_text("".join(d + "\n" for d in _outer_site_dirs()))
    run = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--no-deps", "-q", "-e", str(src),
                          *options], env=_env(), capture_output=True, text=True, timeout=3600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    return venv / "bin" / "python"


def _pth(python: Path) -> str:
    """What the install put in site-packages' __editable__ .pth file."""
    (pth,) = python.parents[1].glob("lib/python*/site-packages/__editable__*.pth")
    return pth.read_text()


@pytest.fixture(scope="module")
def readme_install(tmp_path_factory) -> Path:
    """The README's plain `pip install -e .`, which pyproject.toml makes setuptools' strict editable mode (a tree of
    links type checkers follow). Returns the venv's python."""
    python = _install(tmp_path_factory.mktemp("readme_install"))
    assert "__editable__" in _pth(python) and "import" not in _pth(python), _pth(python)  # a path: the link tree
    return python


@pytest.mark.slow
@pytest.mark.needs("mypy")
def test_mypy_sees_an_editable_install_and_the_real_signatures(readme_install, tmp_path, monkeypatch):
    from mypy import api

    monkeypatch.delenv("PYTHONPATH", raising=False)     # mypy asks the venv's python for its sys.path

    snippet = tmp_path / "user_code.py"
    snippet.write_text(SNIPPET)
    out, err, status = api.run(["--python-executable", str(readme_install), "--follow-imports=silent",
                                "--cache-dir", str(tmp_path / "mypy_cache"), str(snippet)])
    assert "import-not-found" not in out and "import-untyped" not in out, out
    lines = out.splitlines()
    # mypy spells builtins "builtins.float" up to 1.13 and "float" after: either is the real signature
    box = next(l for l in lines if ":3: note: Revealed type is" in l)
    assert re.search(r"mass: (builtins\.)?float\b", box) and "-> lavendersim.bodies.Body" in box, box
    sim = next(l for l in lines if ":4: note: Revealed type is" in l)
    assert "scene: lavendersim.scene.Scene" in sim and re.search(r"integrator: (builtins\.)?str\b", sim), sim
    assert any(':5: error: Argument "mass" to "box" of "Body" has incompatible type "str"' in l for l in lines), out
    assert status == 1, (out, err)


@pytest.mark.slow
@pytest.mark.needs("pyright")
def test_pyright_sees_an_editable_install_and_the_real_signatures(readme_install, tmp_path):
    """basedpyright in pyright's own `standard` mode (its default adds checks of its own) on the same snippet."""
    (tmp_path / "user_code.py").write_text(SNIPPET)
    (tmp_path / "pyrightconfig.json").write_text(json.dumps({"typeCheckingMode": "standard"}))
    run = subprocess.run([sys.executable, "-m", "basedpyright", "--outputjson", "--pythonpath", str(readme_install),
                          "user_code.py"], cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=600)
    report = json.loads(run.stdout)
    diagnostics = report["generalDiagnostics"]
    assert not any("could not be resolved" in d["message"] for d in diagnostics), diagnostics
    said = {d["range"]["start"]["line"] + 1: d for d in diagnostics}
    box, sim, wrong = said[3]["message"], said[6]["message"], said.get(5, {"severity": "nothing said"})
    assert re.search(r'is "\(name: str, mass: float, size: .+, \*\*state: Any\) -> Body"$', box), box
    assert re.search(r"\(self: Sim, scene: Scene, dt: float = .+, integrator: str = .+\) -> None", sim), sim
    assert "*args" not in box + sim and "..." not in box + sim
    assert (wrong["severity"], wrong.get("rule")) == ("error", "reportArgumentType"), wrong
    assert '"mass"' in wrong["message"] and '"float"' in wrong["message"], wrong
    assert report["summary"]["errorCount"] == 1 and run.returncode == 1, run.stdout[-3000:]


@pytest.mark.slow
def test_derive_in_a_strict_install_writes_the_clones_generated_folder(readme_install):
    """The strict install's package is a folder of links; `lavendersim derive` (and its integrity check) must find
    the clone's generated/, not the link folder (derive's folder swap would replace the links with files that the
    next install throws away)."""
    src = readme_install.parents[2] / "src"
    code = ("from lavendersim._integrity import generated_dir; from lavendersim import cli, generated; "
            "print(generated.__file__); print(generated_dir()); print(cli.generated_dir())")
    run = subprocess.run([str(readme_install), "-c", code], capture_output=True, text=True, timeout=600,
                         cwd=readme_install.parents[2], env=_env())
    assert run.returncode == 0, run.stderr[-2000:]
    package_file, found, for_cli = run.stdout.split()
    assert "__editable__" in package_file                       # the import goes through the link tree
    assert Path(found) == Path(for_cli) == (src / "generated").resolve()


def test_keywords_keeps_the_signature_for_type_checkers():
    """Without a type checker: the decorator's annotations carry the wrapped function's ParamSpec."""
    import typing

    from lavendersim import validate

    hints = typing.get_type_hints(validate.keywords)
    assert "ParamSpec" in repr(typing.get_args(hints["fn"])[0]) or "_P" in repr(hints["fn"])
    assert hints["return"] == hints["fn"]


@pytest.mark.slow
def test_files_added_after_a_strict_install_are_imported_from_the_clone(readme_install):
    """The link tree holds the files the install saw; lavendersim's import hook finds newer ones in the clone
    (a new module, a new lab, a file a new derive/ step prints, which is still checked against the manifest)."""
    src = readme_install.parents[2] / "src"
    added = [src / "lavendersim" / "typing_probe.py", src / "labs" / "typing_probe.py", src / "generated" / "probe.py"]
    for i, f in enumerate(added):
        f.write_text(f"X = {i}\n")
    code = ("import importlib, lavendersim\n"
            "for m in ('lavendersim.typing_probe', 'lavendersim.labs.typing_probe'):\n"
            "    print(importlib.import_module(m).__file__)\n"
            "try:\n    import lavendersim.generated.probe\nexcept Exception as exc:\n    print(type(exc).__name__)\n")
    try:
        run = subprocess.run([str(readme_install), "-c", code], capture_output=True, text=True, timeout=600,
                             cwd=readme_install.parents[2], env=_env())
    finally:
        for f in added:
            f.unlink()
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == [str(added[0]), str(added[1]), "GeneratedFileError"], run.stdout


@pytest.mark.slow
def test_the_import_hook_install_stays_available(tmp_path):
    """docs/install.md's opt-out: `--config-settings editable_mode=lenient` installs setuptools' import hook (what
    `pip install -e .` gave before pyproject chose strict); the package and its remapped parts import."""
    python = _install(tmp_path, "--config-settings", "editable_mode=lenient")
    assert "__editable___lavender_rigid_body" in _pth(python) and "install()" in _pth(python), _pth(python)
    code = "import lavendersim.generated.layout as g, lavendersim.labs as l; print(g.__file__); print(l.__file__)"
    run = subprocess.run([str(python), "-c", code], capture_output=True, text=True, timeout=600, cwd=tmp_path,
                         env=_env())
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == [str(tmp_path / "src" / "generated" / "layout.py"),
                                  str(tmp_path / "src" / "labs" / "__init__.py")], run.stdout
