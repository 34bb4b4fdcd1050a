"""The generated NumPy kernels, loaded from generated/ (never from SymPy).

generated/kernels_numpy.py is checked against generated/manifest.json before it is imported
(lavendersim._integrity): a hand-edited or truncated file raises GeneratedFileError naming the file
and `lavendersim derive`.
"""
from __future__ import annotations

from ._integrity import check_generated, generated_dir

check_generated(generated_dir() / "kernels_numpy.py")

from .generated import kernels_numpy as K  # noqa: E402,F401  (re-exported)

__all__ = ["K"]
