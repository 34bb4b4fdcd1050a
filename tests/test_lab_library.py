"""Labs as a library: compute() writes nothing and returns figures; `lab all` prints one line per lab;
no nan printed as a figure; every lab figure fits its canvas and explains its colours."""
from __future__ import annotations

import io
import re

import numpy as np
import pytest
from lavendersim.labs import common as C
from matplotlib.colors import to_rgba, to_rgba_array
from matplotlib.figure import Figure

from lavendersim import labs

# the slow labs are the session's (conftest's quick_accuracy, quick_atlas and hard_lab, computed once from an empty
# working directory for their own test modules too)
SHARED = ("accuracy", "atlas", "hard")


@pytest.fixture(scope="module")
def results(tmp_path_factory, quick_accuracy, quick_atlas, hard_lab):
    """Every lab computed once, from an empty working directory that must stay empty."""
    mp = pytest.MonkeyPatch()
    cwd = tmp_path_factory.mktemp("cwd")
    mp.chdir(cwd)
    try:
        out = {name: labs.compute(name, backend="auto") for name in labs.LABS if name not in SHARED}
        written = sorted(p.name for p in cwd.rglob("*"))
    finally:
        mp.undo()
    for name, shared in zip(SHARED, (quick_accuracy, quick_atlas, hard_lab)):
        out[name] = shared.result
        written += shared.written
    assert set(out) == set(labs.LABS)
    return out, written


@pytest.fixture(scope="module")
def figures(results, quick_accuracy, quick_atlas, hard_lab):
    """{(lab, PNG name): Figure} of every lab, each drawn once: the shared labs' (SHARED) as their session copy's
    save drew them into its PNGs (conftest: `.figures()`, laid out and rendered by savefig), the others here."""
    out = {}
    for name, shared in zip(SHARED, (quick_accuracy, quick_atlas, hard_lab)):
        drawn = shared.figures()
        assert sorted(drawn) == sorted(results[0][name].plot_names), name
        out.update(((name, fname), fig) for fname, fig in drawn.items())
    for name, r in results[0].items():
        if name in SHARED:
            continue
        for fname in r.plot_names:
            fig = r.figure(fname)
            fig.canvas.draw()
            out[(name, fname)] = fig
    return out


def test_compute_writes_nothing_and_returns_figures(results, figures):
    out, written = results
    assert written == []                                   # no lab-output/, no PNG, no JSON
    for name, r in out.items():
        assert isinstance(r, C.LabResult) and r.lab == name
        assert r.files == [] and r.out_dir is None
        assert r.checks and isinstance(r.passed, bool)
        assert r.plot_names, name
        assert all(isinstance(fig, Figure) for (lab, _), fig in figures.items() if lab == name)
        line = r.summary_line(1.25)
        assert "\n" not in line and line.startswith(name) and ("PASS" in line or "FAIL" in line)
        assert "1.2 s" in line
        assert not NAN_FIGURE.search(line)


def test_figure_rejects_an_unknown_name(results):
    from lavendersim.validate import LavenderInputError

    r = results[0]["force"]
    fig = r.figure("force")                                # with or without .png
    assert isinstance(fig, Figure) and r.figure("force.png") is not fig   # a new Figure each call
    with pytest.raises(LavenderInputError, match="force.png"):
        r.figure("nope.png")


def test_save_writes_what_run_writes(results, tmp_path):
    r = results[0]["momentum"]
    r.save(tmp_path)
    assert sorted(p.name for p in (tmp_path / "momentum").iterdir()) == ["momentum.png", "results.json"]
    assert r.out_dir == tmp_path / "momentum" and len(r.files) == 2


def test_hard_survival_table_is_an_extra_file(hard_lab):
    r = hard_lab.saved()                                   # the session's lab hard, saved once (LabResult.save)
    assert r.out_dir.name == "hard" and "survival.md" in [p.name for p in r.files]
    assert (r.out_dir / "survival.md").read_text().startswith("# Which integrators survive")


# ---------------------------------------------------------------------------------- nothing printed as nan


# a figure printed as nan: "name = nan", "off by nan", a nan inside a printed vector (prose such as
# "never a silent NaN" in a check's note is fine)
NAN_FIGURE = re.compile(r"(=|by|\[|,)\s*[-+]?nan\b", re.I)


def _report_text(r, verbosity=1):
    s = io.StringIO()
    C.report(r, s, verbosity=verbosity)
    return s.getvalue()


def test_no_nan_printed_as_a_figure():
    r = labs.compute("01", damping=0.01)
    text = _report_text(r) + _report_text(r, verbosity=2)
    assert not NAN_FIGURE.search(text), text
    assert "integration_error = not computed with damping" in text
    assert r["integration_error"].startswith("not computed")


def test_hard_dt_range_diverged_points_say_why(results):
    r = results[0]["hard"]
    text = _report_text(r)
    assert not NAN_FIGURE.search(text)
    assert "dt_range_fast_dt1e-01_error = not computed: the run raised DivergenceError" in text


def test_non_finite_check_says_not_computed():
    c = C.close("order_rk4", float("nan"), 4.0, 0.35, "too few points")
    assert not c.passed
    assert c.describe() == "order_rk4: not computed, expected 4 ± 0.35 — too few points"
    assert "infinite" in C.at_most("x", float("inf"), 1.0).describe()


def test_parameters_are_wrapped_and_long_ones_named(results):
    r = results[0]["hard"]
    lines = C.parameters_text(r)
    assert all(len(line) <= C.PARAM_WIDTH for line in lines)
    assert "in results.json only (long)" in " ".join(lines) and "dt_range_setup" in " ".join(lines)
    assert sum(len(line) for line in lines) < 1000


# ---------------------------------------------------------------------------------- lab all, progress


def test_lab_all_prints_one_line_per_lab(tmp_path, monkeypatch, capsys):
    from lavendersim import cli

    monkeypatch.setattr(labs, "LABS", {"force": "force", "momentum": "momentum"})
    assert cli.main(["lab", "all", "--out", str(tmp_path), "--backend", "numpy"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("lab all: 2 labs") and "quick mode for accuracy" in out[0]
    assert [line.split()[0] for line in out[1:3]] == ["force", "momentum"]
    assert all("PASS" in line and " s" in line for line in out[1:3])
    assert out[3] == "all 2 labs pass" and len(out) == 4
    assert cli.main(["lab", "all", "--out", str(tmp_path), "--backend", "numpy", "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert cli.main(["lab", "all", "--out", str(tmp_path), "--backend", "numpy", "--verbose"]) == 0
    verbose = capsys.readouterr().out
    assert "== lab force" in verbose and "PASS  torque" in verbose


def test_lab_all_quiet_prints_failures(tmp_path, monkeypatch, capsys):
    from lavendersim import cli

    monkeypatch.setattr(labs, "LABS", {"force": "force"})
    monkeypatch.setattr(labs.lab_module("force"), "TAU_EXPECTED", (0.0, 0.0, 1.6))
    assert cli.main(["lab", "all", "--out", str(tmp_path), "--backend", "numpy", "--quiet"]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "force" in cap.err and "FAIL" in cap.err and "1 of 1 labs failed" in cap.err


def test_progress_is_silent_off_a_terminal(capsys):
    bar = C.progress(range(3), desc="x")          # pytest captures stderr: not a terminal
    assert bar.disable and list(bar) == [0, 1, 2]
    assert C.progress(range(3), enabled=False).disable
    assert capsys.readouterr().err == ""


# ---------------------------------------------------------------------------------- layout of every figure


GREYS = {to_rgba(c)[:3] for c in ("k", "white", "tab:gray", "gray", "0.35", "grey", "lightgray")}


def _grey(rgba) -> bool:
    r, g, b = rgba[:3]
    return rgba[:3] in GREYS or (abs(r - g) < 0.02 and abs(g - b) < 0.02)


def _rgb_set(value) -> set:
    try:
        arr = to_rgba_array(value)
    except (ValueError, TypeError):
        return set()
    return {tuple(np.round(c[:3], 3)) for c in arr}


def _legend_colours(fig) -> set:
    out = set()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    for lg in legends:
        for h in lg.legend_handles:
            for get in ("get_color", "get_facecolor", "get_edgecolor", "get_markerfacecolor", "get_markeredgecolor"):
                if hasattr(h, get):
                    out |= _rgb_set(getattr(h, get)())
    return out


def test_every_figure_fits_its_canvas(figures):
    bad = []
    for (name, fname), fig in figures.items():
        renderer = fig.canvas.get_renderer()
        bb = fig.get_tightbbox(renderer)           # inches
        w, h = fig.get_size_inches()
        tol = 0.02
        if bb.x0 < -tol or bb.y0 < -tol or bb.x1 > w + tol or bb.y1 > h + tol:
            bad.append(f"{name}/{fname}: content {bb.bounds} outside the {w:g} x {h:g} in canvas")
    assert not bad, "\n".join(bad)


def test_every_line_colour_is_explained(figures):
    """Every coloured line is in a legend (same colour) unless its axes has a colour bar."""
    bad = []
    for (name, fname), fig in figures.items():
        keys = _legend_colours(fig)
        for ax in fig.axes:
            if ax.get_label() == "<colorbar>" or not ax.get_visible():
                continue
            for line in ax.get_lines():
                if len(line.get_xdata()) < 2:
                    continue
                rgba = to_rgba(line.get_color())
                if _grey(rgba) or _rgb_set(line.get_color()) <= keys:
                    continue
                bad.append(f"{name}/{fname}: axes {ax.get_title()!r}: line colour {rgba[:3]} in no legend")
    assert not bad, "\n".join(bad)
