"""Reference baselines outside the convex-programming path: penalty / regularized sparse Newton, and return
mapping for plastic histories."""

from .penalty import PenaltyResult, newton, penalty_coulomb, penalty_signorini, regularized_tresca
from .return_mapping import ReturnMappingResult, return_mapping_history

__all__ = ["PenaltyResult", "ReturnMappingResult", "newton", "penalty_coulomb", "penalty_signorini",
           "regularized_tresca", "return_mapping_history"]
