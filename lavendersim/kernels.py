"""The generated NumPy kernels, loaded from generated/ (never from SymPy).

Importing generated/kernels_numpy.py through lavendersim checks it against generated/manifest.json first
(lavendersim._integrity's import hook): a hand-edited or truncated file raises GeneratedFileError naming the
file and `lavendersim derive`.
"""
from __future__ import annotations

from .generated import kernels_numpy as K  # noqa: F401  (re-exported)

__all__ = ["K"]
