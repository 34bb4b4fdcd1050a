"""The command line's conventions (issues 29 and 31): every parser lives in lavendersim/cli/; ``--json`` is the
results as one JSON document on stdout on every command that has results; ``--quiet`` prints nothing on success;
progress goes to stderr, as a bar on a terminal only, and never floods a pipe.

Commands run in-process through ``cli.main(argv)`` (capsys holds stdout and stderr, which are not terminals);
a terminal is simulated by patching ``_common.is_terminal``. No duration is asserted.
"""
from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from lavendersim import cli
from lavendersim.cli import _common

ROOT = Path(__file__).resolve().parents[1]


# ---- one room for the command line ---------------------------------------------------------------------------

def _argparse_users() -> list[str]:
    out = []
    for folder in ("lavendersim", "labs", "derive"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if (ROOT / "lavendersim" / "cli") in path.parents:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module or ""] if isinstance(node, ast.ImportFrom) else []
                if any(n == "argparse" or n.startswith("argparse.") for n in names):
                    out.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return out


def test_no_argparse_outside_the_cli_package():
    assert _argparse_users() == []


def _leaf_parsers():
    """(command line, parser) of every command and every lab."""
    import argparse

    def sub(p):
        (a,) = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        return a.choices

    for name in cli.COMMANDS:
        p = sub(cli._top_parser(name))[name]
        if name == "lab":
            yield from ((f"lab {n}", q) for n, q in sub(p).items())
        else:
            yield name, p


RESULTS = {"lab", "lqr", "bench", "effects", "derive"}   # the commands with results: --json


def test_every_command_takes_quiet_and_the_ones_with_results_take_json():
    seen = set()
    for line, p in _leaf_parsers():
        seen.add(line.split()[0])
        assert "--quiet" in p._option_string_actions, line
        assert ("--json" in p._option_string_actions) == (line.split()[0] in RESULTS), line
        assert p._option_string_actions.get("--json") is None or p._option_string_actions["--json"].nargs == 0, line
    assert seen == set(cli.COMMANDS)


# ---- lab ---------------------------------------------------------------------------------------------------

def _lab(tmp_path, *argv):
    return cli.main(["lab", "force", "--out", str(tmp_path), "--backend", "numpy", *argv])


def test_lab_json_is_its_results_json_on_stdout(tmp_path, capsys):
    assert _lab(tmp_path, "--json") == 0
    cap = capsys.readouterr()
    data = json.loads(cap.out)           # stdout holds the document and nothing else
    assert data == json.loads((tmp_path / "force" / "results.json").read_text())
    assert data["torque"] == [0.0, 0.0, 1.5] and data["passed"] is True
    assert cap.err == ""


def test_lab_quiet_prints_nothing_on_success_and_the_failure_on_stderr(tmp_path, capsys, monkeypatch):
    assert _lab(tmp_path, "--quiet") == 0
    assert capsys.readouterr() == ("", "")
    from lavendersim import labs

    monkeypatch.setattr(labs.lab_module("force"), "TAU_EXPECTED", (0.0, 0.0, 1.6))
    assert _lab(tmp_path, "--quiet") == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "torque" in cap.err and "FAILED" in cap.err


def test_lab_options_reach_compute(tmp_path, capsys):
    """The labs' options are a table in cli/lab.py: a given option reaches the lab's compute keyword."""
    assert _lab(tmp_path, "--json", "--offset", "0.6") == 0
    data = json.loads(capsys.readouterr().out)
    assert data["r_w"] == [0.6, 0.0, 0.0] and data["torque"] == [0.0, 0.0, 3.0]


def test_lab_all_json_has_an_object_per_lab(tmp_path, capsys, monkeypatch):
    from lavendersim import labs

    monkeypatch.setattr(labs, "LABS", {"force": "force", "momentum": "momentum"})
    assert cli.main(["lab", "all", "--out", str(tmp_path), "--backend", "numpy", "--json"]) == 0
    cap = capsys.readouterr()
    data = json.loads(cap.out)
    assert data["passed"] is True and data["failed"] == [] and sorted(data["labs"]) == ["force", "momentum"]
    assert data["labs"]["force"]["torque"] == [0.0, 0.0, 1.5]
    assert data["labs"]["momentum"] == json.loads((tmp_path / "momentum" / "results.json").read_text())
    assert cap.err == ""


def test_a_single_labs_default_report_is_short(capsys):
    """The default: the figures and one line; --verbose adds the parameters, each check and the files (issue 31)."""
    from argparse import Namespace

    from lavendersim.cli import lab as L
    from lavendersim.labs import common as C

    res = C.make_result("t", {"x": 1.5, "y": [0.0, 2.0]}, {"p": 2, "q": "long " * 40},
                        [C.holds("ok", True), C.holds("also", True)])
    args = dict(quiet=False, json=False, verbose=False)
    assert L._report(res, Namespace(**args)) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1:] == ["  x = 1.5", "  y = [0, 2]", "lab t: all 2 checks pass (every parameter and check: --verbose)"]
    assert L._report(res, Namespace(**{**args, "verbose": True})) == 0
    verbose = capsys.readouterr().out
    assert "PASS  also" in verbose and "p=2" in verbose and len(verbose.splitlines()) > len(out)
    assert L._report(res, Namespace(**{**args, "quiet": True})) == 0
    assert capsys.readouterr() == ("", "")
    bad = C.make_result("t", {"x": 1.5}, {}, [C.holds("ok", False, "it broke")])
    assert L._report(bad, Namespace(**args)) == 1
    cap = capsys.readouterr()
    assert "x = 1.5" in cap.out and "ok" in cap.err and "FAILED" in cap.err


# ---- effects -----------------------------------------------------------------------------------------------

def test_effects_quiet_prints_nothing_and_an_unknown_name_is_still_one_line(capsys):
    assert cli.main(["effects", "gravity", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert cli.main(["effects", "no_such_effect", "--quiet"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and len(cap.err.strip().splitlines()) == 1 and "no_such_effect" in cap.err


def test_effects_json_holds_the_numbers(capsys):
    assert cli.main(["effects", "gravity", "--json"]) == 0
    (g,) = json.loads(capsys.readouterr().out)
    assert g["name"] == "gravity"


# ---- derive: a line per phase on a pipe, a bar on a terminal, nothing when quiet -----------------------------

PHASES = ["deriving the equations", "simplifying 3 kernels", "printing C, NumPy and CasADi"]


@pytest.fixture
def fake_codegen(monkeypatch):
    """codegen.write/check that report PHASES through the progress callback and change/find nothing stale."""
    from lavendersim.derive import codegen

    calls = []

    def write(out, progress=None):
        for ph in PHASES:
            progress(ph)
        calls.append(out)
        return ["kernels.c"]

    def check(out, full=False, progress=None):
        for ph in PHASES[:1]:
            progress(ph)
        return list(stale)

    stale: list = []
    monkeypatch.setattr(codegen, "write", write)
    monkeypatch.setattr(codegen, "check", check)
    return calls, stale


def test_derive_says_each_phase_on_stderr_one_line_each(tmp_path, capsys, fake_codegen):
    assert cli.main(["derive", "--out", str(tmp_path / "g")]) == 0
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == len(PHASES) and all(line.startswith(f"derive: {ph} (") for line, ph in zip(lines, PHASES))
    assert cap.out.startswith("derived into ") and "changed: kernels.c" in cap.out


def test_derive_quiet_prints_nothing_and_json_is_the_summary(tmp_path, capsys, fake_codegen):
    assert cli.main(["derive", "--out", str(tmp_path / "g"), "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert cli.main(["derive", "--out", str(tmp_path / "g"), "--json", "--quiet"]) == 0
    cap = capsys.readouterr()
    data = json.loads(cap.out)
    assert data["changed"] == ["kernels.c"] and data["directory"] == str(tmp_path / "g") and data["seconds"] >= 0
    assert data["rebuild"] is None and cap.err == ""    # the package's C is built from its own generated/ only
    assert len(fake_codegen[0]) == 2


def test_derive_asks_for_a_rebuild_only_for_the_packages_kernels(tmp_path, capsys, fake_codegen, monkeypatch):
    """`derive --out DIR` told the user to rebuild the compiled backend although the package's kernels, which it is
    built from, did not change (issue 31). Now only a C kernel changed in the package's own generated/ does."""
    assert cli.main(["derive", "--out", str(tmp_path / "g")]) == 0
    assert "rebuild the compiled backend" not in capsys.readouterr().out
    monkeypatch.setattr(cli, "generated_dir", lambda: (tmp_path / "g").resolve())
    assert cli.main(["derive", "--out", str(tmp_path / "g")]) == 0
    assert "C kernels changed: rebuild the compiled backend with `" in capsys.readouterr().out
    assert cli.main(["derive", "--json", "--quiet"]) == 0          # no --out: the package's folder
    assert json.loads(capsys.readouterr().out)["rebuild"]


def test_derive_on_a_terminal_draws_a_bar_not_lines(tmp_path, capsys, fake_codegen, monkeypatch):
    monkeypatch.setattr(_common, "is_terminal", lambda stream=None: True)
    assert cli.main(["derive", "--out", str(tmp_path / "g")]) == 0
    err = capsys.readouterr().err
    assert "derive: printing C, NumPy and CasADi" in err and "\r" in err     # a bar redrawn in place
    assert not any(line.startswith("derive: deriving the equations (") for line in err.split("\n"))


def test_derive_check_json_and_quiet(tmp_path, capsys, fake_codegen):
    _, stale = fake_codegen
    assert cli.main(["derive", "--check", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["current"] is True
    assert cli.main(["derive", "--check", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    stale.append("kernels.c")
    assert cli.main(["derive", "--check", "--quiet"]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and len(cap.err.strip().splitlines()) == 1 and "kernels.c" in cap.err
    assert cli.main(["derive", "--check", "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["current"] is False and data["stale"] == ["kernels.c"]


# ---- lqr: JSON, quiet, Monte Carlo progress ------------------------------------------------------------------

# C backend: these tests check the CLI's output conventions, not the backend (the Monte Carlo on NumPy
# took 35-50 s per test on a loaded machine, on C 6-13 s; the closed loop on NumPy: tests/test_control.py)
LQR = ["lqr", "--scenario", "center", "--backend", "c"]


def test_lqr_monte_carlo_json_and_its_progress_bar_on_a_terminal(capsys, monkeypatch):
    monkeypatch.setattr(_common, "is_terminal", lambda stream=None: True)
    assert cli.main([*LQR, "--monte-carlo", "2", "--workers", "1", "--json"]) == 0
    cap = capsys.readouterr()
    data = json.loads(cap.out)
    assert data["monte_carlo"]["n"] == 2 and "samples" not in data["monte_carlo"]
    assert math.isfinite(data["figures"]["settling_time"]) and data["figures"]["settling_time"] > 0
    assert data["design"]["controllability_rank"] == 6
    assert "lqr: Monte Carlo" in cap.err and "/2" in cap.err


def test_lqr_quiet_prints_nothing_and_no_progress_off_a_terminal(capsys):
    assert cli.main([*LQR, "--monte-carlo", "1", "--workers", "1", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")


def test_lqr_text_output_and_monte_carlo_off_a_terminal_has_no_progress(capsys):
    assert cli.main([*LQR, "--monte-carlo", "1", "--workers", "1"]) == 0
    cap = capsys.readouterr()
    assert "settling time" in cap.out and "Monte Carlo, 1 runs" in cap.out and cap.err == ""


def test_map_tasks_reports_progress_and_keeps_the_order():
    from lavendersim import executor as X

    done = []
    assert X.map_tasks(abs, range(-9, 0), progress=done.append) == list(range(9, 0, -1))
    assert sum(done) == 9 and len(done) == 3       # chunks of 4 tasks per worker, serial: 4 + 4 + 1
    assert X.map_tasks(abs, [-1, -2]) == [1, 2]


# ---- the two spellings of the command ------------------------------------------------------------------------

@pytest.mark.parametrize("module", ["lavendersim", "lavendersim.cli"])
def test_python_dash_m_runs_the_command_line(module):
    r = subprocess.run([sys.executable, "-m", module, "effects", "gravity", "--quiet"], capture_output=True,
                       text=True, timeout=300)
    assert (r.returncode, r.stdout, r.stderr) == (0, "", "")
    r = subprocess.run([sys.executable, "-m", module, "effects", "--quiet", "--bogus"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_lab_accuracy_integrators_reach_compute(monkeypatch, tmp_path):
    """lab accuracy --integrators A,B is the compute keyword integrators=[A, B] (H3's user tableaux use it)."""
    from lavendersim import labs
    from lavendersim.labs import common as C

    seen = {}

    def compute(backend="auto", **options):
        seen.update(options)
        return C.make_result("accuracy", {"x": 1.0}, {}, [C.holds("ok", True)])

    monkeypatch.setattr(labs.lab_module("accuracy"), "compute", compute)
    assert cli.main(["lab", "accuracy", "--integrators", "rk4, euler", "--quick", "--workers", "1",
                     "--out", str(tmp_path), "--quiet"]) == 0
    assert seen["integrators"] == ["rk4", "euler"] and seen["quick"] is True and seen["workers"] == 1
