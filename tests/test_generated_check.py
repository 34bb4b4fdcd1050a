"""generated/kernels_numpy.py is checked against generated/manifest.json when it is first imported, like
the C build is checked against the generated C sources: a hand edit (a box's inertia doubled) or a
truncated file raises GeneratedFileError naming the file and `lavendersim derive`, never runs silently,
never surfaces as an AttributeError. Every test works on a copy of generated/ (the real tree is never
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
    """Import a copy of kernels_numpy.py as a fresh module (its own check runs on its own folder)."""
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


def test_a_hand_edit_raises_naming_the_file_and_derive(gen_copy):
    p = gen_copy / "kernels_numpy.py"
    p.write_text(doubled_box_inertia(p.read_text(encoding="utf-8")), encoding="utf-8")
    with pytest.raises(GeneratedFileError) as e:
        import_copy(p)
    msg = str(e.value)
    assert str(p) in msg and "`lavendersim derive`" in msg and "manifest.json" in msg
    assert isinstance(e.value, ImportError)      # the CLI reports an ImportError as one line, exit 2


@pytest.mark.parametrize("keep", [0.5, 0.05])
def test_a_truncated_file_raises_not_attribute_error(gen_copy, keep):
    p = gen_copy / "kernels_numpy.py"
    data = p.read_bytes()
    cut = int(len(data) * keep)
    if keep == 0.5:          # cut at a kernel's start, so the rest still compiles and the module's own check runs
        cut = data.rindex(b"\ndef ", 0, cut) + 1
    p.write_bytes(data[:cut])
    with pytest.raises(GeneratedFileError, match="lavendersim derive"):
        _integrity.check_generated(p)
    if keep == 0.5:          # cut after the module's own check: importing it raises the same error
        with pytest.raises(GeneratedFileError, match="kernels_numpy.py"):
            import_copy(p)


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
    """Through lavendersim.kernels (the path every backend takes), in a fresh process whose package
    folder is redirected to the damaged copy; an empty file is caught here too (it has no check of
    its own left)."""
    p = gen_copy / "kernels_numpy.py"
    if damage == "empty":
        p.write_bytes(b"")
    else:
        p.write_text(doubled_box_inertia(p.read_text(encoding="utf-8")), encoding="utf-8")
    code = textwrap.dedent(f"""
        from pathlib import Path
        import lavendersim._integrity as I
        I.generated_dir = lambda: Path({str(gen_copy)!r})
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
    code = ("import sys, lavendersim\n"
            "loaded = [m for m in ('lavendersim._integrity', 'lavendersim.kernels', "
            "'lavendersim.generated.kernels_numpy') if m in sys.modules]\n"
            "assert not loaded, loaded\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr


def test_the_package_file_is_checked_and_the_check_is_printed_by_derive():
    _integrity.check_generated(GEN / "kernels_numpy.py")          # the committed tree is consistent
    head = (GEN / "kernels_numpy.py").read_text(encoding="utf-8").split("import numpy", 1)[0]
    assert "_check_generated(__file__)" in head                    # before any kernel is defined


@pytest.mark.parametrize("name", ["tableaux.py", "layout.py", "effects_meta.py", "kernels_casadi.py", "kernels_numpy.py"])
def test_every_generated_python_module_is_checked_when_the_package_is_imported(gen_copy, name):
    """generated/__init__.py checks every Python module of the package: a hand edit of, e.g., an RK4
    weight in tableaux.py raises before any module of the package is used (and a kernels_numpy.py cut
    mid-statement raises GeneratedFileError, not the SyntaxError its own first-line check cannot pre-empt)."""
    _integrity.check_generated(gen_copy / name)                          # the intact copy passes
    p = gen_copy / name
    p.write_text(p.read_text(encoding="utf-8") + "\n# hand edit\n", encoding="utf-8")
    spec = importlib.util.spec_from_file_location(f"lavendersim_test_generated_pkg_{name[:-3]}", gen_copy / "__init__.py",
                                                  submodule_search_locations=[str(gen_copy)])
    module = importlib.util.module_from_spec(spec)
    with pytest.raises(GeneratedFileError, match=name.replace(".", r"\.")):
        spec.loader.exec_module(module)
    assert "`lavendersim derive`" in str(pytest.raises(GeneratedFileError, spec.loader.exec_module, module).value)
