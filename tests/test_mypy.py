"""Types that reach users (issue 31): `mypy` in its default mode is clean on the package, in CI.

What is checked: ``mypy -p lavendersim`` — every module of the installed package. That is the public modules
(every module whose dotted name has no component with a leading underscore: lavendersim.bodies, .scene, .sim,
.effects, ..., lavendersim.envs, .cli, .bench, .backends, and lavendersim.labs, lavendersim.derive,
lavendersim.generated, which the wheel maps in from labs/, derive/, generated/) together with the private
modules they import (mypy reports errors in those too). The configuration is pyproject.toml's [tool.mypy]:
the default mode, and ``ignore_missing_imports`` only for packages that ship no type information (SymPy, SciPy,
python-control, mpmath, MuJoCo, cloudpickle, tqdm) and for the compiled extension lavendersim._lavender_c.

mypy follows the package as an installed wheel lays it out: a folder of links (lavendersim/ with derive/,
generated/ and labs/ linked in) on MYPYPATH, run from an empty folder, so the checkout's own top-level derive/
and labs/ folders are not mistaken for top-level packages. The same by hand:

    mkdir -p /tmp/lt/lavendersim /tmp/empty && cd /tmp/lt/lavendersim && ln -s "$REPO"/lavendersim/* . \\
      && ln -s "$REPO"/derive "$REPO"/generated "$REPO"/labs . && cd /tmp/empty \\
      && MYPYPATH=/tmp/lt mypy --config-file "$REPO"/pyproject.toml -p lavendersim

The fast tests below pin what mypy found on the way that was more than a missing annotation."""
from __future__ import annotations

import ast
import collections
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from conftest import require
from lavendersim import effects as E
from lavendersim.validate import LavenderInputError

ROOT = Path(__file__).resolve().parents[1]
MAPPED = {"derive": "derive", "generated": "generated", "labs": "labs"}   # pyproject's package-dir remap


def _link_tree(dst: Path) -> Path:
    """dst/lavendersim: a link to every entry of lavendersim/ (but caches), plus the remapped folders."""
    pkg = dst / "lavendersim"
    pkg.mkdir(parents=True)
    for entry in (ROOT / "lavendersim").iterdir():
        if entry.name not in ("__pycache__", ".mypy_cache") and entry.name not in MAPPED:
            (pkg / entry.name).symlink_to(entry)
    for name, folder in MAPPED.items():
        (pkg / name).symlink_to(ROOT / folder)
    return dst


@pytest.mark.slow
def test_mypy_default_mode_is_clean_on_the_package(tmp_path):
    require("mypy")
    tree, empty = _link_tree(tmp_path / "tree"), tmp_path / "empty"
    empty.mkdir()
    env = {**os.environ, "MYPYPATH": str(tree)}
    env.pop("MYPY_CACHE_DIR", None)
    run = subprocess.run([sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
                          "--cache-dir", str(tmp_path / "cache"), "--no-color-output", "--no-error-summary",
                          "-p", "lavendersim"], cwd=empty, env=env, capture_output=True, text=True, timeout=3600)
    errors = [line for line in run.stdout.splitlines() if re.search(r":\d+: error:", line)]
    per_file = collections.Counter(line.split(":", 1)[0].replace(str(tree) + os.sep, "") for line in errors)
    report = "\n".join(errors) + "\n\nper file: " + ", ".join(f"{f} {n}" for f, n in per_file.most_common())
    assert not errors, f"mypy found {len(errors)} errors in {len(per_file)} files:\n{report}"
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]


# ---- what mypy found on the way ---------------------------------------------------------------------------------

def test_a_dask_executor_without_an_address_is_refused_not_a_silent_local_cluster():
    """Executor(kind="dask") built by hand had address None, which distributed.Client(None) takes as "start a
    local cluster": the user's sweep would silently run on this machine instead of the scheduler."""
    from lavendersim.executor import DASK, Executor

    with pytest.raises(LavenderInputError) as err:
        Executor(DASK).map(abs, [1, -2])
    assert err.value.field == "address" and "scheduler" in str(err.value)


def test_the_env_before_reset_says_so():
    """angle_error_deg() and tilt_deg() before the first reset raised AttributeError on None; now the env's own
    message, as step() gives."""
    require("gym")
    from lavendersim.envs.reaction_wheel_cube import ReactionWheelCubeEnv

    env = ReactionWheelCubeEnv(task="corner")
    for call in (env.angle_error_deg, env.tilt_deg):
        with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
            call()
    env.reset(seed=0)
    assert 0 <= env.angle_error_deg() <= 180 and 0 <= env.tilt_deg() <= 180


def test_the_effect_classes_type_checkers_see_are_the_registered_ones():
    """lavendersim.effects declares the built-in classes for type checkers (they are built at import from the
    printed declarations): the declared names are exactly the built-in effects' classes, with the same bases."""
    tree = ast.parse(inspect.getsource(E))
    block = next(n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING"
                 and any(isinstance(b, ast.ClassDef) for b in n.body))
    declared = {c.name: [ast.unparse(b) for b in c.bases] for c in block.body if isinstance(c, ast.ClassDef)}
    built_in = {cls.__name__: cls for name, cls in E.EFFECTS.items() if E.REGISTRY[name].source == "built-in"}
    assert set(declared) == set(built_in)
    for name, cls in built_in.items():
        assert [b.__name__ for b in cls.__bases__] == declared[name], name
        assert getattr(E, name) is cls and issubclass(cls, E.Effect)


def test_scene_add_bodies_is_a_method_with_the_documented_signature():
    """Scene.add_bodies was assigned onto the class after it (invisible to a type checker); it is a method now,
    documented as the function, and adds the same bodies."""
    from lavendersim import scene

    assert "add_bodies" in vars(lv.Scene) and lv.Scene.add_bodies.__doc__ == scene.add_bodies.__doc__
    params = list(inspect.signature(lv.Scene.add_bodies).parameters)
    assert params == ["self", "names", "masses", "I_b", "p_w", "q", "v_w", "omega_b", "omega_w"]
    sc = lv.Scene()
    added = sc.add_bodies(["a", "b"], [1.0, 2.0], np.full((2, 3), 0.1), omega_b=[[0, 0, 1], [1, 0, 0]])
    assert [b.name for b in added] == ["a", "b"] and added[1].mass == 2.0
    np.testing.assert_array_equal(sc.bodies["a"].x0[10:13], [0, 0, 1])


def test_body_positions_are_a_mapping_of_indices():
    """The name -> index view was a subclass of the name -> Body table whose __getitem__ returned an int."""
    sc = lv.Scene()
    sc.add_bodies(["a", "b", "c"], [1.0] * 3, np.full((3, 3), 0.1))
    pos = sc._bodies.positions
    assert dict(pos) == {"a": 0, "b": 1, "c": 2} and len(pos) == 3 and "b" in pos and "z" not in pos
    sc.add_bodies(["d"], [1.0], np.full((1, 3), 0.1))
    assert "d" not in pos and len(pos) == 3          # a view of the bodies at the time it was taken
    with pytest.raises(KeyError):
        pos["d"]


def test_a_declaration_file_not_ending_in_py_is_named_not_an_attribute_error(tmp_path):
    """importlib finds no loader for a name without .py: `derive --user decl.txt` said "AttributeError: 'NoneType'
    object has no attribute 'loader'"."""
    from lavendersim.derive.user import DeclarationError, load_declarations

    decl = tmp_path / "decl.txt"
    decl.write_text("EFFECTS = []\n")
    with pytest.raises(DeclarationError, match=r"decl\.txt: a declaration file is Python source: its name must end in \.py"):
        load_declarations(decl)
