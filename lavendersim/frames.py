"""The hidden principal frames of bodies given a full inertia tensor.

A body's public frame is always the user's body frame B. The kernels step each body about its
principal axes P (diagonal inertia), a constant rotation of the body: ``R_bp`` (columns: the principal
axes in B), as a quaternion ``q_bp``. The conversions at the public boundary are

    q_wp = q_wb ⊗ q_bp,     omega_p = R_bpᵀ omega_b,     v_p = R_bpᵀ v_b   (any body-frame vector),

and back (right multiplication by the constant q_pb / q_bp: a 4x4 matrix built once from the
printed quaternion product). Only bodies whose R_bp is not the identity are touched (a scene of principal bodies has no
PrincipalFrames at all and pays nothing).
"""
from __future__ import annotations

import numpy as np

from .generated.layout import STATE_OMEGA_B, STATE_Q
from .kernels import K


class PrincipalFrames:
    """The constant principal-axis rotations of the bodies of one Sim that are not principal already.

    Parameters
    ----------
    R_bp : ndarray, shape (nb, 3, 3)
        Per body, the principal axes as columns in the body frame (identity: the body frame is principal).

    Attributes
    ----------
    idx : ndarray of int, shape (k,)
        The bodies with a rotation (k >= 1).
    R : ndarray, shape (k, 3, 3)
        Their R_bp.
    q_bp, q_pb : ndarray, shape (k, 4)
        R_bp as a unit quaternion (x, y, z, w), and its conjugate.
    """

    def __init__(self, R_bp: np.ndarray) -> None:
        eye = np.eye(3)
        self.idx = np.array([i for i in range(len(R_bp)) if not np.array_equal(R_bp[i], eye)], dtype=np.int64)
        self.R = np.ascontiguousarray(R_bp[self.idx], dtype=np.float64)
        self.q_bp = K.quat_normalize(K.matrix_to_quat(self.R))
        self.q_pb = K.quat_conj(self.q_bp)
        self._pos = {int(i): k for k, i in enumerate(self.idx)}
        # right multiplication by a constant quaternion is linear: q ⊗ c = M(c) q, M's columns the printed product
        # of the basis quaternions with c (evaluated once here; each conversion is then a 4x4 product)
        basis = np.eye(4)[:, None, :]                                   # (4 basis, 1, 4)
        self._to_b = np.moveaxis(K.quat_mul(basis, self.q_pb[None]), 0, -1)   # (k, 4, 4): q_wp -> q_wb
        self._to_p = np.moveaxis(K.quat_mul(basis, self.q_bp[None]), 0, -1)   # (k, 4, 4): q_wb -> q_wp

    @classmethod
    def of(cls, bodies) -> "PrincipalFrames | None":
        """The frames of a list of Body, or None when every body frame is principal."""
        if all(b.principal for b in bodies):
            return None
        return cls(np.stack([b.R_bp for b in bodies]))

    def rotation(self, i: int) -> np.ndarray | None:
        """Body i's R_bp (3, 3), or None when its frame is principal."""
        k = self._pos.get(int(i))
        return None if k is None else self.R[k]

    # ---- states -----------------------------------------------------------------------------
    def public(self, x: np.ndarray) -> np.ndarray:
        """A copy of the internal state rows x (..., nb, 13) in the body frames (q_wb, omega_b)."""
        out = np.array(x, dtype=np.float64, copy=True)
        rows = out[..., self.idx, :]
        rows[..., STATE_Q] = np.einsum("kij,...kj->...ki", self._to_b, rows[..., STATE_Q])
        rows[..., STATE_OMEGA_B] = np.einsum("kij,...kj->...ki", self.R, rows[..., STATE_OMEGA_B])
        out[..., self.idx, :] = rows
        return out

    def public_row(self, i: int, x: np.ndarray) -> np.ndarray:
        """Body i's internal state row (13,) in its body frame (a copy)."""
        k = self._pos.get(int(i))
        out = np.array(x, dtype=np.float64, copy=True)
        if k is not None:
            out[STATE_Q] = self._to_b[k] @ out[STATE_Q]
            out[STATE_OMEGA_B] = self.R[k] @ out[STATE_OMEGA_B]
        return out

    def internal_row(self, i: int, x: np.ndarray) -> np.ndarray:
        """Body i's public state row (13,) (q_wb, omega_b) in its principal frame (a copy)."""
        k = self._pos.get(int(i))
        out = np.array(x, dtype=np.float64, copy=True)
        if k is not None:
            # q_wb and q_bp are unit: the normalization only removes the product's rounding
            out[STATE_Q] = K.quat_normalize(self._to_p[k] @ out[STATE_Q])
            out[STATE_OMEGA_B] = self.R[k].T @ out[STATE_OMEGA_B]
        return out


def public_rows(frames: "PrincipalFrames | None", x: np.ndarray) -> np.ndarray:
    """x (..., nb, 13) in the body frames: x itself when there are no frames, else a converted copy."""
    return x if frames is None else frames.public(x)
