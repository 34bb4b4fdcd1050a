"""Tests-only helpers for following docs/extending.md literally (test_extending, test_user_tableaux): its fenced code
blocks by info string, the lavendersim command run as a user would, and the guide's first two steps (write the
declaration file, run the documented command) in a fresh folder with LAVENDERSIM_USER_DIR set to a folder in it."""
from __future__ import annotations

import contextlib
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Iterator

from lavendersim import extending

GUIDE = Path(__file__).resolve().parent.parent / "docs" / "extending.md"


def guide_block(info: str) -> str:
    """The fenced code block of docs/extending.md whose info string is exactly `info`."""
    blocks = re.findall(r"^```" + re.escape(info) + r"\n(.*?)^```", GUIDE.read_text(encoding="utf-8"), re.S | re.M)
    assert len(blocks) == 1, f"docs/extending.md must have exactly one ```{info} block"
    return blocks[0]


def run_lavendersim(args: list[str], cwd, env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lavendersim", *args], cwd=cwd, env=env, capture_output=True, text=True)


@contextlib.contextmanager
def followed(work: Path, declaration: str, command: str) -> Iterator[dict]:
    """Write the ```python DECLARATION block as work/DECLARATION and run the ```COMMAND block (lavendersim derive
    --user ...) in work with LAVENDERSIM_USER_DIR = work/userdir, also set in this process (which then finds the set
    by name, as a user's would) until the block exits. Yields {"work", "user", "env", "cmd", "run" (the command's
    CompletedProcess), "set" (the printed set's folder)}."""
    user = work / "userdir"
    (work / declaration).write_text(guide_block(f"python {declaration}"), encoding="utf-8")
    env = {**os.environ, extending.ENV: str(user)}
    cmd = shlex.split(guide_block(command).strip())
    assert cmd[:3] == ["lavendersim", "derive", "--user"]
    r = run_lavendersim(cmd[1:], work, env)
    assert r.returncode == 0, r.stdout + r.stderr
    old = os.environ.get(extending.ENV)
    os.environ[extending.ENV] = str(user)
    try:
        yield {"work": work, "user": user, "env": env, "cmd": cmd, "run": r,
               "set": user / "sets" / Path(declaration).stem}
    finally:
        if old is None:
            os.environ.pop(extending.ENV, None)
        else:
            os.environ[extending.ENV] = old
