"""An elasto-viscoplastic step (von Mises, Perzyna, backward Euler) as one conic program (docs/plasticity.md).

Unknowns: the contact program's x (u on the free DOFs first) and, at each plastic point q, the increment Δα_q of
the deviatoric plastic strain (k orthonormal coordinates) with an epigraph t_q ≥ ‖Δα_q‖:

    min  ½ Σ_q w_q [λ (tr ε_q)² + 2μ ‖Πᵀε_q(u) − α_q^old − Δα_q‖²] + Σ_q w_q [η_p/(2Δt) ‖Δα_q‖² + √(2/3) σ_Y t_q]
         − fᵀu + (the contact program's own terms)   s.t. its cones, (t_q, Δα_q) ∈ SOC(k + 1).

Its u-block is K (the points integrate ε:ε exactly), so the contact program is kept as it is and only the
coupling −uᵀGΔα, the diagonal w(2μ + η_p/Δt), the cones and the linear terms of α^old and of the prescribed
displacement are added.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution, soc


@dataclass(frozen=True)
class PlasticStep:
    """A step's plastic data, scaled, on the plastic points (coordinates point-major, k per point).

    ``coupling`` G on the free DOFs (n × k·points) and ``prescribed`` Gᵀ of the prescribed displacement;
    ``stiffness`` w·2μ and ``viscosity`` w·η_p/Δt per coordinate; ``dissipation`` w·√(2/3)σ_Y per point;
    ``old`` α at the end of the last step."""

    coupling: sp.csr_matrix
    prescribed: np.ndarray
    stiffness: np.ndarray
    viscosity: np.ndarray
    dissipation: np.ndarray
    old: np.ndarray
    components: int


def plastic(program: ConicProgram, step: PlasticStep):
    """The step's program and the map from its solution to the contact program's (for ``recover``). Δα is read
    off u afterwards (:func:`~convexcontact.results.plastic_state.radial_return`): at fixed u the program is separable
    over the points, each one's minimizer in closed form."""
    size, rows, n = program.n_variables, program.n_constraints, step.coupling.shape[0]
    count, k = step.dissipation.size, step.components
    coupling = sp.vstack([step.coupling, sp.csr_matrix((size - n, count * k))])
    P = sp.bmat([[program.P, -coupling, None],
                 [-coupling.T, sp.diags(step.stiffness + step.viscosity), None],
                 [None, None, sp.csr_matrix((count, count))]], format="csc")
    q = np.concatenate([program.q - coupling @ step.old, step.stiffness * step.old - step.prescribed,
                        step.dissipation])
    # cone q holds the rows (t_q, Δα_q): A = −I on those columns in that order, so the slack b − Ax is (t_q, Δα_q)
    order = np.column_stack([size + count * k + np.arange(count), size + np.arange(count * k).reshape(count, k)])
    cones_A = sp.csr_matrix((-np.ones(order.size), (np.arange(order.size), order.ravel())),
                            shape=(order.size, size + count * (k + 1)))
    A = sp.vstack([sp.hstack([program.A, sp.csr_matrix((rows, count * (k + 1)))]), cones_A], format="csc")
    extended = ConicProgram(P, q, A, np.concatenate([program.b, np.zeros(order.size)]),
                            program.cones + (soc(k + 1),) * count)

    def contact(solution: ConicSolution) -> ConicSolution:
        return replace(solution, x=solution.x[:size], z=solution.z[:rows], s=solution.s[:rows])

    return extended, contact
