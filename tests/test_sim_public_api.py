"""Applications (envs, control, linearization, viewer, bench, spacecraft, …) use the public Sim API — ``sim.model``
(read-only, live), ``reinit_body``, ``fast_chunks``, ``check_written`` — never a Sim's private attributes
(issue 29: "rooms that do not import each other in circles")."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.generated import layout as LY

PKG = Path(lv.__file__).parent
APPLICATIONS = ["envs", "control.py", "wheel_control.py", "_linearize.py", "viewer.py", "_playback.py", "bench",
                "spacecraft.py", "lqr.py", "controller_c.py", "cli.py", "cli_lqr.py", "cli", "figures.py"]


def _application_files() -> list[Path]:
    out = []
    for a in APPLICATIONS:
        p = PKG / a
        out += sorted(p.rglob("*.py")) if p.is_dir() else ([p] if p.exists() else [])
    return out


def _sim_private_names() -> set[str]:
    """Every private name of class Sim: its _methods and the self._attributes it assigns."""
    tree = ast.parse((PKG / "sim.py").read_text(encoding="utf-8"))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Sim")
    names = set()
    for node in ast.walk(cls):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("_"):
            names.add(node.name)
        if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and isinstance(node.value, ast.Name)
                and node.value.id == "self" and node.attr.startswith("_")):
            names.add(node.attr)
    return {n for n in names if not (n.startswith("__") and n.endswith("__"))}


def _receiver(node: ast.AST) -> str:
    return node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""


def private_sim_accesses(path: Path, private: set[str]) -> list[str]:
    """`<x>._name` in path where x is not self/cls and either _name is one of Sim's private names or x is named
    like a Sim (sim, *_sim, sim_*)."""
    hits = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
            continue
        r = _receiver(node.value)
        simlike = r.lower() == "sim" or r.lower().endswith("_sim") or r.lower().startswith("sim_")
        if r not in ("self", "cls") and (simlike or node.attr in private):
            hits.append(f"{path.name}:{node.lineno}: {r}.{node.attr}")
    return hits


def test_the_scan_sees_sims_private_names():
    private = _sim_private_names()
    assert {"_models", "_x", "_fast", "_frames", "_effect_objs", "_wheel_n", "_ctr", "_fast_n"} <= private
    assert not {"reinit_body", "fast_chunks", "check_written", "model"} & private


def test_the_scan_finds_a_private_access(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("def f(sim, env, other):\n    return sim._anything, env.sim._x, other._models, other._private_of_its_own\n",
                     encoding="utf-8")
    hits = private_sim_accesses(probe, _sim_private_names())
    assert sorted(h.split(": ")[1] for h in hits) == ["other._models", "sim._anything", "sim._x"]


def test_applications_use_no_private_sim_attribute():
    files = _application_files()
    assert any(f.name == "_linearize.py" for f in files) and any(f.parent.name == "envs" for f in files)
    private = _sim_private_names()
    hits = [h for f in files for h in private_sim_accesses(f, private)]
    assert not hits, "applications reach into Sim's private attributes (use sim.model or a public method):\n" + "\n".join(hits)


def _wheeled_cube_sim() -> lv.Sim:
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15), p_w=[0.0, 0.0, 0.1]))
    s.add_body(lv.Body.box("free", 2.0, (1, 2, 3), omega_b=[0.1, 0.2, 0.3]))
    s.add_effect("spherical_joint", body="cube", anchor_w=[0.0, 0.0, 0.0])
    s.add_effect("reaction_wheels", body="cube", J=[1e-4, 1e-4, 1e-4], torque_limit=0.1, speed_limit=400.0)
    return lv.Sim(s, dt=1e-3, backend="numpy")


def test_sim_model_is_read_only_and_live():
    sim = _wheeled_cube_sim()
    m = sim.model
    assert m.kind(0) == (True, True) and m.kind(1) == (False, False)
    assert m.wheel_counts.tolist() == [3, 0] and m.rows.shape == (2, LY.MODEL_SIZE)
    assert [e.name for e in m.effects] == ["spherical_joint", "reaction_wheels"]
    for a in (m.rows, m.wheel_counts, m.state, m.Omega, m.applied):
        with pytest.raises(ValueError):
            a[...] = 0.0
        with pytest.raises(ValueError):
            a.flags.writeable = True
    m.command[0, :3] = [0.01, -0.02, 0.03]                  # the documented writable buffer: the held commands
    np.testing.assert_array_equal(sim.wheel_command("cube"), [0.01, -0.02, 0.03])
    sim.run(5)
    np.testing.assert_array_equal(m.state, sim.x)            # live: the stepped rows (frames principal here)
    np.testing.assert_array_equal(m.Omega[0, :3], sim.wheel_rates("cube"))
    assert m.counters.steps == sim.steps == 5


def test_reinit_body_is_public():
    sim = _wheeled_cube_sim()
    sim.set_wheel_command("cube", [0.01, 0.0, 0.0])
    sim.run(3)
    q = np.array([0.0, 0.0, np.sin(0.1), np.cos(0.1)])
    sim.reinit_body(0, np.zeros(3), q, np.array([0.0, 0.0, 0.5]), np.array([1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(sim.q[0], q)
    np.testing.assert_array_equal(sim.wheel_rates("cube"), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(sim.wheel_command("cube"), np.zeros(3))
    sim.check_written()
    sim.run(2)
    assert np.all(np.isfinite(sim.x))
