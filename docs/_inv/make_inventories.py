"""Write the small local intersphinx inventories in this folder (python, numpy, control, gymnasium).

The documentation is built without network access (CI has none), so intersphinx cannot fetch the
projects' own objects.inv; these list the objects the pages link, with the projects' published URLs
(relative to the base URLs in docs/conf.py's intersphinx_mapping). Run after adding a name:
    python docs/_inv/make_inventories.py
"""
from __future__ import annotations

import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent

# project: (title, version, [(name, domain:role, uri relative to the base; $ = the name)])
INVENTORIES = {
    "python": ("Python", "3.11", [
        ("pathlib.Path", "py:class", "library/pathlib.html#$"),
        ("tomllib", "py:module", "library/tomllib.html#module-$"),
        ("concurrent.futures.ProcessPoolExecutor", "py:class", "library/concurrent.futures.html#$"),
        ("float", "py:class", "library/functions.html#$"),
        ("dict", "py:class", "library/stdtypes.html#$"),
        ("ValueError", "py:exception", "library/exceptions.html#$"),
    ]),
    "numpy": ("NumPy", "2", [
        ("numpy.ndarray", "py:class", "reference/generated/$.html"),
        ("numpy.float64", "py:class", "reference/arrays.scalars.html#$"),
        ("numpy.float32", "py:class", "reference/arrays.scalars.html#$"),
        ("numpy.linalg.norm", "py:function", "reference/generated/$.html"),
    ]),
    "control": ("python-control", "0.10", [
        ("control.lqr", "py:function", "generated/$.html"),
        ("control.dlqr", "py:function", "generated/$.html"),
        ("control.ss", "py:function", "generated/$.html"),
        ("control.StateSpace", "py:class", "generated/$.html"),
    ]),
    "gymnasium": ("Gymnasium", "1.0", [
        ("gymnasium.Env", "py:class", "api/env/#$"),
        ("gymnasium.make", "py:function", "api/registry/#$"),
        ("gymnasium.make_vec", "py:function", "api/registry/#$"),
        ("gymnasium.vector.VectorEnv", "py:class", "api/vector/#$"),
        ("gymnasium.spaces.Box", "py:class", "api/spaces/fundamental/#$"),
    ]),
}


def main() -> None:
    for key, (project, version, entries) in INVENTORIES.items():
        head = (f"# Sphinx inventory version 2\n# Project: {project}\n# Version: {version}\n"
                "# The remainder of this file is compressed using zlib.\n")
        body = "".join(f"{name} {role} 1 {uri.replace('$', name)} -\n" for name, role, uri in entries)
        (HERE / f"{key}.inv").write_bytes(head.encode() + zlib.compress(body.encode()))


if __name__ == "__main__":
    main()
