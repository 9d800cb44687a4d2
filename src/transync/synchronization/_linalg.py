"""Small linear-algebra kernels shared by the synchronization methods (private)."""

from __future__ import annotations

import numpy as np

__all__: list[str] = []


def polar(M: np.ndarray) -> np.ndarray:
    """Orthogonal polar factor ``U V^T`` of ``M = U S V^T`` (the nearest matrix with
    orthonormal rows/columns in Frobenius norm); works on stacks ``(..., m, n)``."""
    U, _, Vt = np.linalg.svd(M, full_matrices=False)
    return U @ Vt
