"""Writing a file the package names inside a folder the user gave, without following a link there.

``replace_file(folder / name, data)`` writes a new file in the same folder under a temporary name and moves it
over ``name`` with ``os.replace``: a link planted at ``name`` is replaced by the file (its target untouched), and
a reader sees the old content or the new, never half of it. Standard library only.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path


def replace_file(path: str | os.PathLike, data: str | bytes, *, encoding: str = "utf-8") -> Path:
    """Write ``data`` to ``path`` through a temporary sibling and ``os.replace`` (never through a link at ``path``).

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist.
    data : str or bytes
        The content (str is encoded with ``encoding``).
    encoding : str, default "utf-8"

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    OSError
        The folder cannot be written (nothing is left behind), or ``path`` is a folder.
    """
    path = Path(path)
    raw = data.encode(encoding) if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path
