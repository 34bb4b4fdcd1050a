"""The generated NumPy kernels, loaded from generated/ (never from SymPy)."""
from __future__ import annotations

from lavendersim.generated import kernels_numpy as K  # noqa: F401  (re-exported)

__all__ = ["K"]
