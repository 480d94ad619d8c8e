"""Reference baselines outside the convex-programming path: penalty / regularized sparse Newton."""

from .penalty import PenaltyResult, newton, penalty_coulomb, penalty_signorini, regularized_tresca

__all__ = ["PenaltyResult", "newton", "penalty_coulomb", "penalty_signorini", "regularized_tresca"]
