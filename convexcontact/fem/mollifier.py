"""The mollification S along Γ_C of the nonlocal Coulomb law (Oden, Duvaut)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree


def mollifier(coords: np.ndarray, weights: np.ndarray, radius: float) -> sp.csr_matrix:
    """S (m × m): (S λ)_i = Σ_j ω_ρ(|x_i − x_j|) w_j λ_j / Σ_j ω_ρ(|x_i − x_j|) w_j.

    ω_ρ(r) = exp(ρ²/(r² − ρ²)) for r < ρ, else 0 (the constant cancels in the
    normalization, which also keeps Σ_j S_ij = 1 near the ends of Γ_C). A radius
    below the node spacing gives the identity: the local law.
    """
    pairs = cKDTree(coords).query_pairs(radius, output_type="ndarray")
    i = np.concatenate([np.arange(len(coords)), pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([np.arange(len(coords)), pairs[:, 1], pairs[:, 0]])
    r2 = ((coords[i] - coords[j]) ** 2).sum(axis=1)
    kernel = np.exp(radius**2 / np.minimum(r2 - radius**2, -1e-300)) * weights[j]
    S = sp.csr_matrix((kernel, (i, j)), shape=(len(coords),) * 2)
    return sp.diags(1.0 / np.asarray(S.sum(axis=1)).ravel()) @ S
