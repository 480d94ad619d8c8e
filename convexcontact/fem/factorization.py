"""One sparse factorization of the stiffness, reused for every solve with it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..scene.model import SceneError

BLOCK = 64
"""Right-hand sides solved at once when building B K⁻¹ Bᵀ (bounds memory to n × BLOCK)."""


class StiffnessFactorization:
    """LU factors of K (SuperLU, scipy) with a blocked multi-right-hand-side solve."""

    def __init__(self, K: sp.spmatrix):
        try:
            self._lu = spla.splu(sp.csc_matrix(K))
        except RuntimeError as error:  # SuperLU: "Factor is exactly singular"
            raise SceneError(
                "dirichlet",
                f"the stiffness is singular ({error}): the body can move rigidly",
                "the dual (Delassus) formulation needs Dirichlet conditions that hold every rigid motion; "
                "use formulation='primal' or fix more components",
            ) from None

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=float))

    def schur(self, B: sp.spmatrix) -> np.ndarray:
        """W = B K⁻¹ Bᵀ (dense), solving for BLOCK columns of Bᵀ at a time."""
        Bt = sp.csc_matrix(B.T)
        W = np.empty((B.shape[0], B.shape[0]))
        for start in range(0, B.shape[0], BLOCK):
            stop = min(start + BLOCK, B.shape[0])
            W[:, start:stop] = B @ self.solve(Bt[:, start:stop].toarray())
        return 0.5 * (W + W.T)
