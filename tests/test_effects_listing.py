"""The effects and their parameters are listed by a documented call (lavendersim.effects.describe / list_effects)
and a CLI command (``lavendersim effects [NAME] [--json]``), built from the registered declarations (issue 31).
A user set's effects listed by the command: test_extending::test_cli_lists_the_guides_effects (on the set its module
fixture derives with the guide's command, not derived again here)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from lavendersim import effects as E
from lavendersim.validate import LavenderInputError

CLI = [sys.executable, "-m", "lavendersim.cli"]


def _run(*args: str) -> subprocess.CompletedProcess:
    """`lavendersim effects ARGS` with an empty user directory (only the built-ins)."""
    import os
    import tempfile

    from lavendersim import extending

    with tempfile.TemporaryDirectory() as user:
        env = {**os.environ, extending.ENV: user}
        return subprocess.run([*CLI, "effects", *args], capture_output=True, text=True, timeout=300, env=env)


def test_list_effects_holds_every_registered_effect_and_its_declared_parameters():
    listed = {e["name"]: e for e in E.list_effects()}
    assert set(listed) == set(E.REGISTRY)
    for name, spec in E.REGISTRY.items():
        e = listed[name]
        assert [p["name"] for p in e["params"]] == [p.name for p in spec.params]
        for p, ps in zip(e["params"], spec.params):
            assert (p["unit"], p["rule"], p["frame"], p["required"]) == (ps.unit, ps.rule, ps.frame, ps.default is None)
        assert e["reads"] == list(spec.state_inputs) and e["decay"] == spec.is_decay
    g = listed["gravity"]["params"][0]
    assert (g["name"], g["shape"], g["unit"], g["default"], g["frame"]) == ("g_w", [3], "m/s²", [0.0, 0.0, -9.81], "world")
    assert listed["angular_damping"]["decay"] and "1/s" in listed["angular_damping"]["decay_rate"]
    assert not listed["applied_torque"]["decay"] and listed["applied_torque"]["decay_rate"] is None
    axes = {p["name"]: p for p in listed["reaction_wheels"]["params"]}["axes_b"]
    assert axes["upto"] and axes["shape_text"] == "(1 … 4, 3)" and listed["reaction_wheels"]["per_body"]


def test_describe_names_each_parameter_with_unit_rule_and_default():
    text = E.describe()
    built_in = [spec for spec in E.REGISTRY.values() if spec.source == "built-in"]   # (other tests may load user sets)
    assert {s.name for s in built_in} >= {"gravity", "linear_damping", "angular_damping", "reaction_wheels"}
    for spec in built_in:
        assert f"{spec.name} ({spec.kind}, built-in)" in text
        for p in spec.params:
            line = next(ln for ln in text.splitlines() if ln.strip().startswith(p.name + " ") and
                        text.rfind(spec.name + " (", 0, text.find(ln)) >= 0)
            assert (p.unit or "dimensionless") in line and p.rule in line
    one = E.describe("gravity")
    assert one.startswith("gravity (force, built-in)") and "default [0.0, 0.0, -9.81]" in one
    assert "applied_torque" not in one
    assert "torque_w" in E.describe("applied_torque") and "required" in E.describe("applied_torque")


def test_unknown_effect_is_refused_naming_the_known_ones():
    with pytest.raises(LavenderInputError, match="effect.*known: .*gravity"):
        E.describe("gravty")


def test_cli_lists_every_builtin_effect_with_units():
    r = _run()
    assert r.returncode == 0, r.stderr
    for spec in E.REGISTRY.values():
        if spec.source != "built-in":
            continue
        assert spec.name in r.stdout
        for p in spec.params:
            assert p.name in r.stdout
            if p.unit:
                assert p.unit in r.stdout
    assert "N·m·s/rad" in r.stdout and "m/s²" in r.stdout


def test_cli_json_parses_and_matches_the_call():
    r = _run("--json")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert data == [e for e in E.list_effects() if e["source"] == "built-in"]
    one = _run("reaction_wheels", "--json")
    assert one.returncode == 0
    (rw,) = json.loads(one.stdout)
    assert {p["name"]: p["unit"] for p in rw["params"]}["speed_limit"] == "rad/s"


def test_cli_unknown_name_is_one_line_exit_2():
    r = _run("no_such_effect")
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and "no_such_effect" in r.stderr and "gravity" in r.stderr
