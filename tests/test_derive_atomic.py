"""`lavendersim derive` writes generated/ atomically: killed at any moment, the folder is old-and-intact
or new-and-complete, and the next run cleans up what the killed one left.

The kill tests run `lavendersim derive --out DIR` in a process of its own on a temporary copy of generated/
whose content is an "old generation" (every file changed, one retired file, a manifest recording
them), SIGKILL it at seeded times spread over its run, and compare DIR's file set and sha256s with
the old and the new manifests after every kill. The quick test skips the SymPy derivation (render()
returns the committed files, which the manifest fast path proved current), forks each derive from one
interpreter that imported the CLI once, and stretches every fsync by a few tens of milliseconds, so the
kills land while files are being written; the slow one kills the real, unpatched derivation (a fresh
`python -m lavendersim.cli derive` each time).
"""
from __future__ import annotations

import hashlib
import json
import os
import queue
import random
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from lavendersim import cli
from lavendersim.cli import generated_dir
from lavendersim.derive import atomic, codegen

GEN = generated_dir()
DEADLINE = 300.0   # s: generous, the machine is shared and loaded

# The quick kill test's derives: the real CLI and codegen.write, with render() returning the committed
# files (no SymPy) and each fsync stretched by DELAY so the write phase is long enough to hit. One server
# interpreter imports them once; each derive is a process forked from it (a process of its own, killed by pid),
# so a run does not pay an interpreter's start and the imports (~0.8 s CPU each, 14 runs).
# Server protocol: a line "OUT<TAB>DELAY<TAB>PAUSE_AT<TAB>STDERR_FILE" forks a derive; the server prints
# "pid N", releases it, prints "ended" when it has ended (not yet reaped, so a kill by pid cannot reach another
# process), and after a line "reap", "exit RC" (a killed one: -9); the derive prints "started", "writing"
# (first fsync), "paused" (in fsync PAUSE_AT, where it then sleeps to be killed).
FAST_DERIVE = textwrap.dedent("""
    import os, sys, time, traceback
    from pathlib import Path
    from lavendersim import cli
    from lavendersim.derive import codegen
    gen = Path(sys.argv[1])
    files = {p.name: p.read_text(encoding="utf-8") for p in gen.iterdir() if p.is_file() and p.name != "manifest.json"}
    codegen.render = lambda progress=None: dict(files)
    _fsync = os.fsync

    def derive(out, delay, pause_at):
        calls = []
        def slow_fsync(fd):
            calls.append(fd)
            if len(calls) == 1:
                print("writing", flush=True)
            if len(calls) == pause_at:      # stop here for good: the test kills the process at this point
                print("paused", flush=True)
                time.sleep(3600)
            time.sleep(delay)
            _fsync(fd)
        os.fsync = slow_fsync
        print("started", flush=True)
        return cli.main(["derive", "--out", out])

    for line in sys.stdin:
        out, delay, pause_at, err = line.rstrip("\\n").split("\\t")
        go_r, go_w = os.pipe()
        pid = os.fork()
        if pid == 0:                        # the derive: waits until its pid is printed, exits as `python -c` would
            os.close(go_w)
            os.read(go_r, 1)
            os.dup2(os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC), 2)
            try:
                code = derive(out, float(delay), int(pause_at))
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException:
                traceback.print_exc()
                code = 1
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        os.close(go_r)
        print(f"pid {pid}", flush=True)
        os.write(go_w, b"g")
        os.close(go_w)
        os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)    # ended, not reaped: its pid stays its own until "reap"
        print("ended", flush=True)
        assert sys.stdin.readline() == "reap\\n"
        print(f"exit {os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])}", flush=True)
""")


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def new_generation() -> tuple[dict[str, str], dict]:
    """The committed files (what derive writes) and the manifest derive writes for them."""
    assert codegen.check(GEN) == [], "generated/ must be current for this test (run `lavendersim derive`)"
    files = {p.name: p.read_text(encoding="utf-8") for p in GEN.iterdir() if p.is_file() and p.name != "manifest.json"}
    return files, json.loads(codegen.manifest_for(files))


def write_old_generation(out: Path, files: dict[str, str]) -> dict:
    """An older derive's output in `out`: every file different, one file the new run no longer writes."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    old = {n: t + ("\n/* older generation */\n" if n.endswith((".c", ".h")) else "\n# older generation\n")
           for n, t in files.items()}
    old["retired_kernels.py"] = '"""generated by derive — do not edit"""\nRETIRED = True\n'
    for n, t in old.items():
        (out / n).write_text(t, encoding="utf-8")
    man = {"header": codegen.HEADER, "derive_sources_sha256": "0" * 64, "tools": codegen.tool_versions(),
           "outputs_sha256": {n: codegen.digest(t) for n, t in sorted(old.items())}}
    (out / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return man


def state(out: Path, old_man: dict, new_man: dict) -> str:
    """'old' or 'new' when out is exactly that generation (file set and every sha256), else what is wrong."""
    if not out.is_dir():
        return "missing folder"
    names = {p.name for p in out.iterdir() if p.name != "__pycache__"}
    try:
        man = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return f"unreadable manifest ({exc})"
    for label, want in (("old", old_man), ("new", new_man)):
        if man != want:
            continue
        expect = set(want["outputs_sha256"]) | {"manifest.json"}
        if names != expect:
            return f"{label} manifest, files differ: {sorted(names ^ expect)}"
        bad = sorted(n for n, h in want["outputs_sha256"].items() if sha(out / n) != h)
        return label if not bad else f"{label} manifest, wrong content: {bad}"
    bad_old = sorted(n for n, h in old_man["outputs_sha256"].items() if not (out / n).is_file() or sha(out / n) != h)
    return f"a mix (manifest of neither run; not old: {bad_old})"


class FastDerives:
    """The FAST_DERIVE server (a context manager): ``run(out, delay, kill_after, wait_for, pause_at)`` is one fast
    derive into out, SIGKILLed kill_after s after it printed `wait_for` (None: let it finish); pause_at=k: the
    derive stops for good in its k-th fsync (and prints "paused"), to be killed there."""

    def __init__(self, tmp_path: Path):
        self.tmp = tmp_path
        self.proc = subprocess.Popen([sys.executable, "-c", FAST_DERIVE, str(GEN)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: queue.Queue = queue.Queue()
        self.reader_stop: list = []            # why the reader thread stopped
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()
        self.runs = 0

    def _read(self):
        try:
            for line in self.proc.stdout:
                self.lines.put(line.strip())
            self.reader_stop.append("end of output")
        except Exception as exc:  # noqa: BLE001 - recorded, reported by the assertion below
            self.reader_stop.append(f"{type(exc).__name__}: {exc}")
        finally:
            self.lines.put(None)

    def _next(self, deadline: float, what: str) -> str:
        try:
            line = self.lines.get(timeout=max(0.1, deadline - time.monotonic()))
        except queue.Empty:
            raise AssertionError(f"derive printed no {what!r} within {DEADLINE} s ({self.reader_stop})") from None
        if line is None:
            raise AssertionError(f"the derive server ended ({self.reader_stop}): {self.proc.stderr.read()}")
        return line

    def run(self, out: Path, delay: float, kill_after: float | None, wait_for: str = "started",
            pause_at: int = 0) -> dict:
        self.runs += 1
        err = self.tmp / f"derive_{self.runs}.stderr"
        self.proc.stdin.write(f"{out}\t{delay}\t{pause_at}\t{err}\n")
        self.proc.stdin.flush()
        deadline = time.monotonic() + DEADLINE
        line = self._next(deadline, "pid")
        assert line.startswith("pid "), line
        pid = int(line.split()[1])
        ended = False
        try:
            while True:     # wait (generously) for the line to time the kill from; "ended": the derive ended
                line = self._next(deadline, wait_for)
                ended = line == "ended"
                if line == wait_for or ended:
                    break
            t0 = time.monotonic()
            if kill_after is not None and not ended:
                time.sleep(kill_after)
                os.kill(pid, signal.SIGKILL)                 # alive, or ended and not reaped: still this derive
            while not ended:
                ended = self._next(deadline, "ended") == "ended"
            seconds = time.monotonic() - t0
        finally:
            if not ended:
                os.kill(pid, signal.SIGKILL)
        self.proc.stdin.write("reap\n")
        self.proc.stdin.flush()
        line = self._next(deadline, "exit")
        assert line.startswith("exit "), line
        return {"rc": int(line.split()[1]), "seconds": seconds, "stderr": err.read_text(errors="replace")}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=60)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self.thread.join(timeout=60)
            self.proc.stdout.close()
            self.proc.stderr.close()


def test_killed_while_writing_generated_is_old_or_new_never_a_mix(tmp_path):
    files, new_man = new_generation()
    out = tmp_path / "generated"
    old_man = write_old_generation(out, files)
    assert state(out, old_man, new_man) == "old"
    with FastDerives(tmp_path) as fast:
        _kill_trials(fast, out, files, old_man, new_man)


def _kill_trials(fast: FastDerives, out: Path, files: dict, old_man: dict, new_man: dict) -> None:
    delay = 0.03                           # s per fsync: 14 fsyncs, a write phase of about half a second
    calib = fast.run(out, delay, None)     # one uninterrupted run: how long the write phase takes here
    assert calib["rc"] == 0, calib["stderr"]
    assert state(out, old_man, new_man) == "new"
    n_fsync = len(files) + 1 + 2           # every file, the manifest, the new folder, the parent after the swap
    window = calib["seconds"]
    rng = random.Random(20261123)
    trials = []
    # (a) killed at fixed points: in the first file's fsync, mid-way, in the new folder's fsync (all
    # written, not yet swapped) and in the parent's fsync right after the swap
    for k in (1, n_fsync // 2, n_fsync - 1, n_fsync):
        old_man = write_old_generation(out, files)   # leftovers of the previous kill stay: the run cleans them
        r = fast.run(out, delay, 0.0, "paused", pause_at=k)
        trials.append((f"fsync {k}", r["rc"], state(out, old_man, new_man)))
    assert all(rc == -signal.SIGKILL for _, rc, _ in trials), trials
    assert [s for *_, s in trials] == ["old", "old", "old", "new"], trials
    # (b) killed at seeded times stratified over 0 … 1.1 × the measured write phase, half of them
    # timed from the start of the command, half from its first fsync
    n = 8
    for k in range(n):
        old_man = write_old_generation(out, files)
        kill_after = window * 1.1 * (k + rng.random()) / n
        wait_for = "writing" if k % 2 else "started"
        r = fast.run(out, delay, kill_after, wait_for)
        trials.append((f"{kill_after:.3f} s after {wait_for}", r["rc"], state(out, old_man, new_man)))
    print("\nkill trials (when, exit code, generated/):", *trials, sep="\n  ")
    assert all(s in ("old", "new") for *_, s in trials), trials
    # the next, uninterrupted run finishes the job and removes every leftover of the killed ones
    r = fast.run(out, 0.0, None)
    assert r["rc"] == 0, r["stderr"]
    assert state(out, old_man, new_man) == "new"
    assert atomic.leftovers(out) == []


@pytest.mark.slow
def test_killed_real_derive_is_old_or_new_never_a_mix(tmp_path):
    """The real `lavendersim derive --out DIR` (SymPy and all), killed at 8 seeded times spread over
    its run, measured first."""
    files, new_man = new_generation()
    out = tmp_path / "generated"
    cmd = [sys.executable, "-m", "lavendersim.cli", "derive", "--out", str(out)]
    old_man = write_old_generation(out, files)
    t0 = time.monotonic()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=DEADLINE * 2)
    run_time = time.monotonic() - t0
    assert r.returncode == 0, r.stderr
    assert state(out, old_man, new_man) == "new"
    rng = random.Random(11)
    trials = []
    n = 8
    for k in range(n):
        old_man = write_old_generation(out, files)
        kill_after = run_time * 1.05 * (k + rng.random()) / n
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            time.sleep(kill_after)
            proc.send_signal(signal.SIGKILL)
            rc = proc.wait(timeout=DEADLINE)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        trials.append((round(kill_after, 2), rc, state(out, old_man, new_man)))
    print(f"\nderive took {run_time:.1f} s; kill trials (kill after s, exit code, generated/):", *trials, sep="\n  ")
    assert all(s in ("old", "new") for *_, s in trials), trials
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=DEADLINE * 2)
    assert r.returncode == 0 and state(out, old_man, new_man) == "new"
    assert atomic.leftovers(out) == []


# ---- the folder replacement itself (derive/atomic.py) -------------------------------------------

def test_replace_folder_writes_only_what_changed_and_keeps_timestamps(tmp_path):
    out = tmp_path / "g"
    assert atomic.replace_folder(out, {"a.py": "A\n", "b.h": "B\n"}) == ["a.py", "b.h"]
    os.utime(out / "a.py", ns=(1_000_000_000, 1_000_000_000))
    assert atomic.replace_folder(out, {"a.py": "A\n", "b.h": "B\n"}) == []          # nothing to do: nothing written
    assert atomic.replace_folder(out, {"a.py": "A\n", "b.h": "B2\n"}) == ["b.h"]
    assert (out / "a.py").stat().st_mtime_ns == 1_000_000_000                     # unchanged file kept its time
    assert sorted(p.name for p in out.iterdir()) == ["a.py", "b.h"]
    assert atomic.leftovers(out) == []


def test_replace_folder_drops_owned_files_and_keeps_kept_entries(tmp_path):
    out = tmp_path / "set"
    atomic.replace_folder(out, {"k.c": "1", "old.md": "x"})
    (out / "build").mkdir()
    (out / "build" / "lib.so").write_bytes(b"\x7fELF")
    (out / "__pycache__").mkdir()
    assert atomic.replace_folder(out, {"k.c": "2"}, owned={"old.md"}, keep=("build",)) == ["k.c"]
    assert sorted(p.name for p in out.iterdir()) == ["build", "k.c"]
    assert (out / "build" / "lib.so").read_bytes() == b"\x7fELF"


def test_a_folder_with_foreign_files_is_refused_untouched(tmp_path):
    out = tmp_path / "home"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    with pytest.raises(atomic.OutputFolderError, match="thesis.tex"):
        atomic.replace_folder(out, {"kernels.c": "x"})
    assert sorted(p.name for p in out.iterdir()) == ["thesis.tex"]
    assert atomic.leftovers(out) == []


def test_cli_refuses_a_foreign_out_folder_with_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(codegen, "render", lambda progress=None: {"kernels.c": "/* x */\n"})   # no SymPy needed here
    out = tmp_path / "notes"
    out.mkdir()
    (out / "todo.txt").write_text("keep me")
    assert cli.main(["derive", "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    # on a pipe derive says each phase on its own line ("derive: writing …", issue 31); the error is one more line
    errors = [line for line in lines if not line.startswith("derive: ")]
    assert len(errors) == 1 and "todo.txt" in errors[0] and errors[0].startswith("lavendersim: derive:"), lines
    assert [p.name for p in out.iterdir()] == ["todo.txt"]


def test_fallback_without_exchange_is_repaired_by_the_next_run(tmp_path, monkeypatch):
    """Where the folders cannot be exchanged in one step (no renameat2), two renames are used; a run
    killed between them leaves the folder missing, and the next run puts the old one back."""
    out = tmp_path / "g"
    atomic.replace_folder(out, {"a": "old", "manifest.json": "old"})
    monkeypatch.setattr(atomic, "exchange", lambda a, b: False)
    real_rename = os.rename
    calls = []

    def rename_then_die(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:
            raise KeyboardInterrupt("killed between the two renames")
        real_rename(src, dst)

    monkeypatch.setattr(atomic.os, "rename", rename_then_die)
    with pytest.raises(KeyboardInterrupt):
        atomic.replace_folder(out, {"a": "new", "manifest.json": "new"})
    monkeypatch.setattr(atomic.os, "rename", real_rename)
    assert not out.exists() and len(atomic.leftovers(out)) == 2      # the window the next run repairs
    done = atomic.recover(out)
    assert any("restored" in d for d in done)
    assert (out / "a").read_text() == "old" and (out / "manifest.json").read_text() == "old"
    assert atomic.replace_folder(out, {"a": "new", "manifest.json": "new"}) == ["a", "manifest.json"]
    assert (out / "a").read_text() == "new" and atomic.leftovers(out) == []


def test_leftovers_of_a_running_process_are_left_alone(tmp_path):
    out = tmp_path / "g"
    atomic.replace_folder(out, {"a": "1"})
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        busy = tmp_path / f".g.derive-new-{proc.pid}"
        busy.mkdir()
        dead = tmp_path / ".g.derive-new-999999999"     # no such process
        dead.mkdir()
        atomic.replace_folder(out, {"a": "2"})
        assert busy.is_dir() and not dead.exists()
    finally:
        proc.kill()
        proc.wait()


def test_exchange_is_available_here():
    """Linux with renameat2: the swap is a single system call (the fallback is the exception)."""
    if not sys.platform.startswith("linux"):
        pytest.skip("renameat2 is Linux-only; elsewhere the two-rename fallback is used")
    assert atomic._EXCHANGE is not None


def test_derive_user_replaces_the_set_folder_whole_and_keeps_its_build_cache(tmp_path):
    """`lavendersim derive --user FILE` writes the set's folder the same way (its build/ carried over)."""
    import re

    from lavendersim import extending

    guide = (Path(__file__).resolve().parent.parent / "docs" / "extending.md").read_text(encoding="utf-8")
    decl_text = re.findall(r"^```python my_effects.py\n(.*?)^```", guide, re.S | re.M)[0]
    decl = tmp_path / "atomic_set.py"
    decl.write_text(decl_text.replace("gravity_gradient", "gg_atomic").replace("quadratic_drag", "qd_atomic")
                    .replace("inertia_cone", "inertia_cone_atomic"), encoding="utf-8")
    sets = tmp_path / "sets"
    s = extending.derive(decl, out=sets, compile=False)
    folder = sets / "atomic_set"
    assert s.directory == folder.resolve() and (folder / "kernels_numpy.py").is_file()
    (folder / "build").mkdir()
    (folder / "build" / "libatomic_set-cached.so").write_bytes(b"cache")
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(atomic.OutputFolderError, match="notes.txt"):
        extending.derive(decl, out=sets, compile=False)
    (folder / "notes.txt").unlink()
    decl.write_text(decl.read_text(encoding="utf-8") + "\n# edited: a new declaration hash\n", encoding="utf-8")
    extending.derive(decl, out=sets, compile=False)
    assert (folder / "build" / "libatomic_set-cached.so").read_bytes() == b"cache"
    assert atomic.leftovers(folder) == []
