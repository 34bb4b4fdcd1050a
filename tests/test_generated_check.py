"""Every Python module of generated/ is checked against generated/manifest.json when lavendersim imports it (the
import hook lavendersim._integrity.GeneratedChecker), like the C build is checked against the generated C sources:
a hand edit (a box's inertia doubled) or a truncated file raises GeneratedFileError naming the file and
`lavendersim derive`, never runs silently, never surfaces as an AttributeError or a SyntaxError. The generated
code itself imports nothing of the runtime. Every test works on a copy of generated/ (the real tree is never
modified)."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lavendersim import _integrity
from lavendersim.cli import generated_dir
from lavendersim.errors import GeneratedFileError

GEN = generated_dir()
_count = [0]


@pytest.fixture
def gen_copy(tmp_path):
    out = tmp_path / "generated"
    shutil.copytree(GEN, out, ignore=shutil.ignore_patterns("__pycache__"))
    return out


def import_copy(path: Path):
    """Import a copy of kernels_numpy.py as a fresh module, bypassing lavendersim's import hook."""
    _count[0] += 1
    name = f"lavendersim_test_kernels_copy_{_count[0]}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def doubled_box_inertia(text: str) -> str:
    """kernels_numpy.py with inertia_box's mass factor doubled (a plausible hand edit)."""
    start = text.index("def inertia_box(")
    end = text.index("\ndef ", start + 1)
    body = text[start:end]
    edited = body.replace("t2 = ((1.0/12.0))*m", "t2 = ((2.0/12.0))*m")
    assert edited != body, "inertia_box's printed form changed: update this test's edit"
    return text[:start] + edited + text[end:]


def test_the_intact_copy_imports_and_computes(gen_copy):
    K = import_copy(gen_copy / "kernels_numpy.py")
    np.testing.assert_allclose(K.inertia_box(12.0, 1.0, 1.0, 1.0), [2.0, 2.0, 2.0], rtol=1e-15)


def import_through_hook(gen_copy: Path, name: str):
    """What lavendersim's import hook does for lavendersim.generated.<name> found in the folder gen_copy."""
    return _integrity.GeneratedChecker().find_spec(f"lavendersim.generated.{name}", [str(gen_copy)])


def test_a_hand_edit_raises_naming_the_file_and_derive(gen_copy):
    p = gen_copy / "kernels_numpy.py"
    assert import_through_hook(gen_copy, "kernels_numpy").origin == str(p)    # intact: found, checked
    p.write_text(doubled_box_inertia(p.read_text(encoding="utf-8")), encoding="utf-8")
    with pytest.raises(GeneratedFileError) as e:
        import_through_hook(gen_copy, "kernels_numpy")
    msg = str(e.value)
    assert str(p) in msg and "`lavendersim derive`" in msg and "manifest.json" in msg
    assert isinstance(e.value, ImportError)      # the CLI reports an ImportError as one line, exit 2


@pytest.mark.parametrize("keep", [0.5, 0.05])
def test_a_truncated_file_raises_not_attribute_error(gen_copy, keep):
    p = gen_copy / "kernels_numpy.py"
    data = p.read_bytes()
    cut = int(len(data) * keep)
    if keep == 0.5:          # cut at a kernel's start, so the rest still compiles
        cut = data.rindex(b"\ndef ", 0, cut) + 1
    p.write_bytes(data[:cut])
    with pytest.raises(GeneratedFileError, match="lavendersim derive"):
        _integrity.check_generated(p)
    with pytest.raises(GeneratedFileError, match="kernels_numpy.py"):    # before Python compiles it
        import_through_hook(gen_copy, "kernels_numpy")


def test_a_missing_or_foreign_manifest_raises(gen_copy):
    p = gen_copy / "kernels_numpy.py"
    (gen_copy / "manifest.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(GeneratedFileError, match="manifest.json"):
        _integrity.check_generated(p)
    (gen_copy / "manifest.json").unlink()
    with pytest.raises(GeneratedFileError, match="lavendersim derive"):
        _integrity.check_generated(p)


def test_an_edit_after_a_successful_check_is_caught(gen_copy):
    """The per-process cache is keyed by size and modification time, so a later edit is seen."""
    p = gen_copy / "kernels_numpy.py"
    _integrity.check_generated(p)
    p.write_text(p.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    with pytest.raises(GeneratedFileError):
        _integrity.check_generated(p)


@pytest.mark.parametrize("damage", ["empty", "edited"])
def test_the_runtime_refuses_a_damaged_file_before_simulating(gen_copy, damage):
    """Through lavendersim.kernels (the path every backend takes), in a fresh process whose generated package
    is redirected to the damaged copy (its __path__); an empty file is caught too."""
    p = gen_copy / "kernels_numpy.py"
    if damage == "empty":
        p.write_bytes(b"")
    else:
        p.write_text(doubled_box_inertia(p.read_text(encoding="utf-8")), encoding="utf-8")
    code = textwrap.dedent(f"""
        import lavendersim.generated as G
        G.__path__[:] = [{str(gen_copy)!r}]
        import lavendersim as lv
        s = lv.Scene(); s.add_body(lv.Body.box("b", 1.0, (1, 2, 3), omega_b=[1, 2, 3]))
        lv.Sim(s, backend="numpy").run(10)
        print("ran")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "ran" not in r.stdout
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("lavendersim.errors.GeneratedFileError:"), r.stderr
    assert "kernels_numpy.py" in last and "`lavendersim derive`" in last


def test_import_lavendersim_stays_lazy():
    """import lavendersim installs the hook only: no generated module is imported, no file hashed."""
    code = ("import sys, lavendersim\n"
            "loaded = [m for m in ('lavendersim.kernels', 'lavendersim.generated.kernels_numpy') if m in sys.modules]\n"
            "assert not loaded, loaded\n"
            "from lavendersim import _integrity\n"
            "assert not _integrity._OK, _integrity._OK\n"
            "assert any(isinstance(f, _integrity.GeneratedChecker) for f in sys.meta_path)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr


def test_the_package_files_are_consistent_and_import_nothing_of_the_runtime():
    """Generated code does not import the runtime (issue 29): no generated module imports lavendersim."""
    import ast

    for p in sorted(GEN.glob("*.py")):
        _integrity.check_generated(p)                                  # the committed tree is consistent
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                assert node.level == 0 and not (node.module or "").startswith("lavendersim"), (p.name, node.module)
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("lavendersim") for a in node.names), p.name


@pytest.mark.parametrize("name", ["tableaux.py", "layout.py", "effects_meta.py", "kernels_casadi.py", "kernels_numpy.py",
                                  "kernels_numpy_f32.py"])
def test_every_generated_python_module_is_checked_when_imported(gen_copy, name):
    """The hook checks every Python module of the package: a hand edit of, e.g., an RK4 weight in tableaux.py raises
    before the module runs."""
    assert import_through_hook(gen_copy, name[:-3]) is not None              # the intact copy passes
    p = gen_copy / name
    p.write_text(p.read_text(encoding="utf-8") + "\n# hand edit\n", encoding="utf-8")
    with pytest.raises(GeneratedFileError, match=name.replace(".", r"\.")) as e:
        import_through_hook(gen_copy, name[:-3])
    assert "`lavendersim derive`" in str(e.value)


def test_a_python_in_the_checkout_imports_the_remapped_subpackages():
    """`python -m pytest` or a REPL started in the checkout puts the checkout first on sys.path, so `import lavendersim`
    finds its lavendersim/ folder, which holds no generated/, derive/ or labs/ (pyproject.toml's package-dir puts them
    beside it): the import hook finds them there. The strict editable install failed this (ModuleNotFoundError: No module
    named 'lavendersim.generated' for every test module under `python -m pytest` in a clean clone)."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    remap = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["package-dir"]
    beside = sorted(k.split(".", 1)[1] for k, v in remap.items() if "." in k)
    assert beside == sorted(_integrity.GeneratedChecker.BESIDE)
    code = ("import lavendersim, lavendersim.generated.layout, lavendersim.derive, lavendersim.labs, pathlib\n"
            "print(pathlib.Path(lavendersim.generated.layout.__file__).resolve().parent.name)\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["generated"]
