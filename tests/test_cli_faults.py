"""The command line's faults, round two (issue 28): one line and exit 2 (or a failed figure, exit 1), never a
traceback; lab output folders written whole, never through a link, one run at a time.

Commands run through the command line's `main()` in this process (_main: its parser, its guard, its messages;
exit code, stdout and stderr captured, warnings shown as a fresh interpreter shows them). A few run in a real
`python -m lavendersim.cli` subprocess (_run: what a user sees), and
test_the_command_line_process_says_what_main_says checks that both give the same exit code and output. The lab
runs are the cheap ones: a failure mode diverges at once and writes results.json only. Folder mechanics are checked on a synthetic
LabResult (labs.common.make_result) so they run in milliseconds. Waits have generous deadlines that are
only reached when the behaviour is broken; no duration is asserted.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

from conftest import run_main
from lavendersim import cli
from lavendersim.errors import DivergenceError
from lavendersim.labs import common as C
from lavendersim.labs import output as O
from lavendersim.validate import LavenderInputError

DEADLINE = 300.0   # s: a subprocess or an awaited event; reached only when something hangs


def _run(*args, env=None, timeout=DEADLINE):
    return subprocess.run([sys.executable, "-m", "lavendersim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env)


_main = run_main   # `lavendersim ARGS` through cli.main in this process (tests/conftest.py)


def _one_line(r, code=2):
    assert r.returncode == code, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    return lines[0]


# ---- lab failure modes: a divergence is a failed figure -----------------------------------------------------

FAILURE_MODES = [
    ("01", ["--damping", "100"], {"damping": 100.0}),
    ("03", ["--dt", "0.1", "--integrator", "euler"], {"dt": 0.1, "integrator": "euler"}),
    ("force", ["--offset", "1e100"], {"offset": 1e100}),
]


@pytest.mark.parametrize("lab, argv, options", FAILURE_MODES, ids=[m[0] for m in FAILURE_MODES])
def test_a_failure_mode_that_diverges_is_a_failed_figure_with_results(tmp_path, lab, argv, options):
    r = _main("lab", lab, *argv, "--out", tmp_path, "--quiet")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr and "no_divergence" in r.stderr
    res = json.loads((tmp_path / lab / "results.json").read_text())
    assert res["passed"] is False and res["check_no_divergence"] is False and res["diverged"] is True
    assert "diverged" in res["divergence"] or "beyond" in res["divergence"]   # the Sim's own words
    for k, v in options.items():        # the options it ran with are recorded
        assert res[k] == v
    assert res["backend"] in ("c", "numpy")
    assert sorted(os.listdir(tmp_path / lab)) == ["results.json"]   # complete: no plot was promised


def test_a_stepping_divergence_records_where_it_happened(tmp_path):
    r = _run("lab", "03", "--dt", "0.1", "--integrator", "euler", "--out", tmp_path, "--quiet")
    assert r.returncode == 1
    res = json.loads((tmp_path / "03" / "results.json").read_text())
    assert res["divergence_body"] == "principal" and res["divergence_step"] == 0 and res["divergence_t"] == 0.1


def test_labs_compute_returns_the_divergence_as_a_failed_result():
    from lavendersim import labs

    res = labs.compute("03", dt=0.1, integrator="euler")
    assert not res.passed and [c.name for c in res.failures] == ["no_divergence"]
    assert res["diverged"] is True and res.plot_names == []


def test_a_bad_option_is_still_exit_2_not_a_failed_figure(tmp_path):
    line = _one_line(_main("lab", "01", "--damping", "-1", "--out", tmp_path))
    assert "damping" in line
    assert not (tmp_path / "01").exists()


# ---- bad output paths: one line, exit 2, before anything runs ----------------------------------------------

def _paths(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    return a_file


@pytest.mark.parametrize("out", ["FILE", "FILE/sub", "/proc/lavendersim-no-such-dir/out", ""])
def test_lab_out_that_cannot_be_a_folder_is_one_line(tmp_path, out):
    a_file = _paths(tmp_path)
    line = _one_line(_main("lab", "01", "--damping", "100", "--out", out.replace("FILE", str(a_file))))
    assert "out" in line
    assert a_file.read_text() == "x"


def test_lab_all_out_that_is_a_file_is_one_line(tmp_path):
    a_file = _paths(tmp_path)
    assert "out" in _one_line(_run("lab", "all", "--out", a_file))


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into a read-only folder")
def test_lab_out_in_a_read_only_folder_is_one_line(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert "out" in _one_line(_main("lab", "01", "--damping", "100", "--out", ro / "x"))
    finally:
        ro.chmod(0o755)


@pytest.mark.needs("control")
@pytest.mark.parametrize("plot", ["out.xyz", "out.PNGX", "plot.docx"])
def test_lqr_plot_with_an_unknown_suffix_is_one_line_naming_the_allowed_ones(tmp_path, plot):
    line = _one_line(_main("lqr", "--plot", tmp_path / plot))
    assert "--plot" in line and ".png" in line and ".pdf" in line and ".svg" in line
    assert not (tmp_path / plot).exists()


@pytest.mark.needs("control")
@pytest.mark.parametrize("argv, field", [(["--plot", ""], "--plot"), (["--export-c", ""], "--export-c"),
                                         (["--plot", "FILE/p.png"], "--plot"), (["--export-c", "FILE"], "--export-c"),
                                         (["--monte-carlo", "2", "--dask", "nonsense"], "dask")])
def test_lqr_bad_paths_are_one_line(tmp_path, argv, field):
    a_file = _paths(tmp_path)
    line = _one_line(_main("lqr", *[a.replace("FILE", str(a_file)) for a in argv]))
    assert field in line


@pytest.mark.parametrize("argv, field", [(["--out", ""], "out"), (["--out", "DIR"], "out"),
                                         (["--out", "FILE/x.json"], "out")])
def test_bench_bad_out_paths_are_one_line(tmp_path, argv, field):   # bench --out FILE was --json FILE (issue 31)
    a_file = _paths(tmp_path)
    args = [a.replace("FILE", str(a_file)).replace("DIR", str(tmp_path)) for a in argv]
    assert field in _one_line(_main("bench", "--quick", *args))


@pytest.mark.parametrize("lab", ["atlas", "accuracy"])
def test_a_dask_address_without_a_port_is_one_line(tmp_path, lab):
    assert "dask" in _one_line(_main("lab", lab, "--quick", "--dask", "nonsense", "--out", tmp_path), 2)


def test_a_bad_view_host_of_a_lab_is_refused_before_the_lab_runs(tmp_path):
    line = _one_line(_main("lab", "03", "--view", "--view-host", "0", "--out", tmp_path))
    assert "host" in line and "every interface" in line
    assert not (tmp_path / "03").exists()      # refused before the lab computed or wrote anything


# ---- the guard in cli.main: whatever escapes a command is one line ----------------------------------------

def _boom(exc):
    def fn(args):
        raise exc
    return fn


@pytest.mark.parametrize("exc, code, words", [
    (RuntimeError("something\nbroke"), 2, "unexpected error"),
    (DivergenceError(3, 0, "it grew", "b", 0.5), 1, "diverged"),
    (PermissionError(13, "Permission denied", "/x/y"), 2, "/x/y"),
    (LavenderInputError("field", "a rule"), 2, "field"),
])
def test_cli_main_turns_whatever_escapes_into_one_line(monkeypatch, capsys, exc, code, words):
    monkeypatch.setitem(cli.BUILDERS, "bench", lambda sub: sub.add_parser("bench").set_defaults(fn=_boom(exc)))
    monkeypatch.delenv(cli.TRACEBACK_ENV, raising=False)
    assert cli.main(["bench"]) == code
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and words in err


def test_the_traceback_of_an_unexpected_error_is_there_on_request(monkeypatch):
    monkeypatch.setitem(cli.BUILDERS, "bench", lambda sub: sub.add_parser("bench").set_defaults(
        fn=_boom(RuntimeError("x"))))
    monkeypatch.setenv(cli.TRACEBACK_ENV, "1")
    with pytest.raises(RuntimeError):
        cli.main(["bench"])


# ---- lab output folders: no link followed, whole or marked, one run at a time ------------------------------

def _result(lab="t", plot=None, value=1.0):
    """A synthetic LabResult: results.json, one PNG drawn by `plot` (default: a real figure), one extra file."""
    def draw(_data):
        fig, ax = C.new_figure(1, 1)
        ax[0, 0].plot([0, 1], [0, value])
        return fig

    res = C.make_result(lab, {"x": value}, {"p": 2}, [C.holds("ok", True)], {"plot.png": plot or draw})
    res.extra_files["notes.md"] = f"value {value}\n"
    return res


def _secret(tmp_path):
    target = tmp_path / "elsewhere" / "precious.txt"
    target.parent.mkdir()
    target.write_text("keep me")
    return target


@pytest.mark.parametrize("name", ["results.json", "plot.png", "notes.md"])
def test_a_link_planted_in_the_lab_folder_does_not_have_its_target_written(tmp_path, name):
    target = _secret(tmp_path)
    out = tmp_path / "out"
    _result().save(out)
    (out / "t" / name).unlink()
    (out / "t" / name).symlink_to(target)
    res = _result(value=2.0).save(out)
    assert target.read_text() == "keep me"
    assert not (out / "t" / name).is_symlink() and (out / "t" / name).is_file()
    assert json.loads((out / "t" / "results.json").read_text())["x"] == 2.0
    assert [p.name for p in res.files] == ["results.json", "plot.png", "notes.md"]


def test_a_link_planted_by_hand_before_a_real_lab_run_keeps_its_target(tmp_path):
    target = _secret(tmp_path)
    (tmp_path / "out" / "01").mkdir(parents=True)
    (tmp_path / "out" / "01" / "results.json").symlink_to(target)
    r = _main("lab", "01", "--damping", "100", "--out", tmp_path / "out", "--quiet")
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert target.read_text() == "keep me"
    res = tmp_path / "out" / "01" / "results.json"
    assert not res.is_symlink() and json.loads(res.read_text())["damping"] == 100.0


def test_a_lab_folder_that_is_itself_a_link_is_refused_and_its_target_untouched(tmp_path):
    target = _secret(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "t").symlink_to(target.parent, target_is_directory=True)
    with pytest.raises(LavenderInputError, match="symbolic link"):
        _result().save(out)
    assert os.listdir(target.parent) == ["precious.txt"] and target.read_text() == "keep me"
    assert (out / "t").is_symlink()


def test_the_command_line_refuses_a_linked_lab_folder_in_one_line_before_computing(tmp_path):
    target = _secret(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "01").symlink_to(target.parent, target_is_directory=True)
    line = _one_line(_main("lab", "01", "--damping", "100", "--out", tmp_path / "out"))
    assert "symbolic link" in line and "01" in line
    assert os.listdir(target.parent) == ["precious.txt"]


def test_a_linked_lock_file_is_refused_and_its_target_untouched(tmp_path):
    target = _secret(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    O.lock_path(out, "t").symlink_to(target)
    with pytest.raises(LavenderInputError, match="lock file"):
        _result().save(out)
    assert target.read_text() == "keep me" and not (out / "t").exists()


def test_a_folder_that_is_not_a_labs_is_never_replaced(tmp_path):
    out = tmp_path / "out"
    (out / "t").mkdir(parents=True)
    (out / "t" / "thesis.tex").write_text("mine")
    with pytest.raises(LavenderInputError, match="not a lab's output folder"):
        _result().save(out)
    (out / "t" / "thesis.tex").unlink()
    (out / "t" / "data").mkdir()
    with pytest.raises(LavenderInputError, match="sub-folder"):
        _result().save(out)
    assert os.listdir(out / "t") == ["data"]


def test_out_itself_may_be_a_link_the_user_chose(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real, target_is_directory=True)
    _result().save(tmp_path / "link")
    assert (real / "t" / "results.json").is_file()


def test_a_save_that_fails_mid_write_leaves_the_previous_folder_whole(tmp_path):
    out = tmp_path / "out"
    _result(value=1.0).save(out)
    before = {p.name: p.read_bytes() for p in (out / "t").iterdir()}

    def broken(_data):
        raise RuntimeError("the figure could not be drawn")

    with pytest.raises(RuntimeError):
        _result(value=2.0, plot=broken).save(out)
    assert {p.name: p.read_bytes() for p in (out / "t").iterdir()} == before
    assert O.leftovers(out, "t") == []


KILL_MID_WRITE = textwrap.dedent("""
    import os, signal, sys
    from lavendersim.labs import common as C

    def die(_data):     # results.json is already written when the plot is drawn
        os.kill(os.getpid(), signal.SIGKILL)

    res = C.make_result("t", {"x": 3.0}, {}, [C.holds("ok", True)], {"plot.png": die})
    res.save(sys.argv[1])
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
@pytest.mark.parametrize("first", [True, False], ids=["no_previous_run", "over_a_previous_run"])
def test_a_lab_killed_mid_write_leaves_a_marked_or_absent_folder(tmp_path, first):
    out = tmp_path / "out"
    if not first:
        _result(value=1.0).save(out)
    before = None if first else {p.name: p.read_bytes() for p in (out / "t").iterdir()}
    r = subprocess.run([sys.executable, "-c", KILL_MID_WRITE, str(out)], capture_output=True, timeout=DEADLINE)
    assert r.returncode == -signal.SIGKILL
    if first:
        assert not (out / "t").exists()
    else:   # the previous results, whole: never the new results.json without its figure
        assert {p.name: p.read_bytes() for p in (out / "t").iterdir()} == before
    left = O.leftovers(out, "t")
    assert len(left) == 1 and (left[0] / O.MARKER).is_file() and (left[0] / "results.json").is_file()
    _result(value=4.0).save(out)                       # the next run cleans up after the killed one
    assert O.leftovers(out, "t") == []
    assert json.loads((out / "t" / "results.json").read_text())["x"] == 4.0
    assert not (out / "t" / O.MARKER).exists()


HOLD_LOCK = textwrap.dedent("""
    import sys, time
    from lavendersim.labs import output as O

    with O.lab_lock(sys.argv[1], sys.argv[2]):
        print("locked", flush=True)
        time.sleep(600)
""")


def _holder(out, name):
    p = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(out), name], stdout=subprocess.PIPE, text=True)
    line = []
    t = threading.Thread(target=lambda: line.append(p.stdout.readline()), daemon=True)
    t.start()
    t.join(DEADLINE)
    assert line == ["locked\n"], "the lock holder did not start"
    return p


def _stop(p):
    p.kill()
    p.wait(DEADLINE)


def test_a_second_run_into_the_same_folder_is_refused_naming_the_running_ones_pid(tmp_path):
    out = tmp_path / "out"
    p = _holder(out, "01")
    try:
        line = _one_line(_main("lab", "01", "--damping", "100", "--out", out))
        assert str(p.pid) in line and str(out / "01") in line
        assert not (out / "01").exists()          # refused before anything was written
        line = _one_line(_main("lab", "all", "--out", out))   # lab all takes every lab's folder first
        assert str(p.pid) in line
        with pytest.raises(LavenderInputError, match=f"pid {p.pid}"):
            _result(lab="01").save(out)
        _result(lab="02").save(out)             # another lab's folder in the same OUT is free
    finally:
        _stop(p)
    # the holder was killed: the kernel released its lock, the next run writes
    r = _main("lab", "01", "--damping", "100", "--out", out, "--quiet")
    assert r.returncode == 1 and (out / "01" / "results.json").is_file()


def test_two_threads_saving_one_folder_never_mix_their_files(tmp_path):
    out = tmp_path / "out"
    outcomes: dict[float, object] = {}

    def save(v):
        try:
            outcomes[v] = _result(value=v).save(out)
        except LavenderInputError as exc:   # refused while the other one wrote
            outcomes[v] = exc

    threads = [threading.Thread(target=save, args=(v,)) for v in (1.0, 2.0, 3.0)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(DEADLINE)
    assert any(not isinstance(o, Exception) for o in outcomes.values())
    for o in outcomes.values():
        if isinstance(o, Exception):
            assert "is writing it" in str(o)
    # whichever won last, its three files agree with each other
    x = json.loads((out / "t" / "results.json").read_text())["x"]
    assert (out / "t" / "notes.md").read_text() == f"value {x}\n"
    assert sorted(os.listdir(out / "t")) == ["notes.md", "plot.png", "results.json"]


def test_the_lock_is_reentrant_in_one_thread_and_released_after(tmp_path):
    with O.lab_lock(tmp_path, "t"):
        _result().save(tmp_path)                  # the command line holds it while the lab computes, then saves
    with O.lab_lock(tmp_path, "t"):
        pass
    assert O.lock_path(tmp_path, "t").read_text().strip() == str(os.getpid())


@pytest.mark.needs("control")
def test_export_c_replaces_a_link_planted_in_its_folder_and_keeps_the_target(tmp_path):
    from lavendersim import controller_c as CC
    from lavendersim import spacecraft as S

    target = _secret(tmp_path)
    d = tmp_path / "exported"
    d.mkdir()
    (d / "controller.c").symlink_to(target)
    CC.export_c(S.design(S.load("cube_center")), d)
    assert target.read_text() == "keep me"
    assert not (d / "controller.c").is_symlink() and "controller" in (d / "controller.c").read_text()
    assert sorted(p.name for p in d.iterdir()) == ["controller.c", "controller.h", "main.c"]   # no temporaries left


@pytest.mark.parametrize("argv", [["lab", "01", "--dt", "abc"], ["lab", "nope"], ["nope"], [], ["view"],
                                  ["bench", "--rounds", "x"], ["lab", "01", "--quiet", "--verbose"],
                                  ["lqr", "--scenario", "nope"]])
def test_a_usage_error_is_one_line_naming_the_option_and_help(argv):
    line = _one_line(_main(*argv))
    assert "error:" in line and "--help" in line


@pytest.mark.parametrize("argv", [["lab", "01", "--dt", "abc"], ["nope"], ["lab", "01", "--damping", "-1", "--out", "OUT"],
                                  ["lab", "01", "--damping", "100", "--out", "OUT", "--quiet"]],
                         ids=["usage", "command", "input", "diverged"])
def test_the_command_line_process_says_what_main_says(tmp_path, argv):
    """The tests above run cli.main in-process (_main); `python -m lavendersim.cli` gives the same exit code,
    stdout and stderr (usage errors, bad input, a failed figure)."""
    argv = [a.replace("OUT", str(tmp_path / "a")) for a in argv]
    r = _run(*argv)
    m = _main(*argv)
    assert (r.returncode, r.stdout, r.stderr) == (m.returncode, m.stdout, m.stderr)
    assert r.returncode in (1, 2) and "Traceback" not in r.stderr


def test_without_an_atomic_exchange_the_two_renames_leave_one_whole_folder(tmp_path, monkeypatch):
    from lavendersim.derive import atomic

    monkeypatch.setattr(atomic, "exchange", lambda a, b: False)   # a file system without RENAME_EXCHANGE
    target = _secret(tmp_path)
    out = tmp_path / "out"
    _result(value=1.0).save(out)
    (out / "t" / "notes.md").unlink()
    (out / "t" / "notes.md").symlink_to(target)
    _result(value=2.0).save(out)
    assert target.read_text() == "keep me" and O.leftovers(out, "t") == []
    assert (out / "t" / "notes.md").read_text() == "value 2.0\n"
    # killed between the two renames: OUT/NAME missing, the old folder aside; the next run puts it back first
    os.rename(out / "t", out / ".t.lab-old-999999999")
    O.check_folder(out, "t")
    _result(value=3.0).save(out)
    assert O.leftovers(out, "t") == [] and json.loads((out / "t" / "results.json").read_text())["x"] == 3.0


def test_derive_with_an_empty_out_is_refused_and_writes_nothing(monkeypatch, capsys):
    from lavendersim.derive import codegen

    calls = []
    monkeypatch.setattr(codegen, "write", lambda out, *a, **k: calls.append(out) or [])   # never the package's generated/
    monkeypatch.setattr(codegen, "check", lambda out, *a, **k: calls.append(out) or [])
    for argv in (["derive", "--out", ""], ["derive", "--check", "--out", ""]):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "out" in err
    assert calls == []


def test_a_lab_modules_own_compute_and_run_return_the_divergence(tmp_path):
    from lavendersim.labs import lab01_equal_torque as L01

    res = L01.compute("numpy", damping=100)
    assert not res.passed and res["damping"] == 100 and res["dt"] == L01.DT and res["backend"] == "numpy"
    res = L01.run(tmp_path, backend="numpy", damping=100)
    assert json.loads((tmp_path / "01" / "results.json").read_text())["check_no_divergence"] is False
