"""Array operations numpy lacks, shared by the layers (no mechanics, no solver)."""

from __future__ import annotations

import numpy as np


def group_ranks(groups: np.ndarray) -> np.ndarray:
    """Each item's rank among the items of its group, in their order."""
    order = np.argsort(groups, kind="stable")
    starts = np.searchsorted(groups[order], groups[order])  # each item's group's first place in the order
    ranks = np.empty_like(groups)
    ranks[order] = np.arange(groups.size) - starts
    return ranks
