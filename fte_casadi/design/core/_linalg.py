"""Small matrix helpers shared by the certificate (:mod:`._certify`) and the conic layer (:mod:`._sdp`)."""

from __future__ import annotations

import numpy as np

__all__ = []  # public: docs/api.md


def sym(M: np.ndarray) -> np.ndarray:
    """The symmetric part ``(M + M^T) / 2`` (also of a cvxpy expression)."""
    return 0.5 * (M + M.T)
