"""RKHP integrators: Taylor-tower step, Newton, compiled loops, classical peers (paper §5.2).

Names load lazily (numba is imported only when an integrator runs):
`integrate_rkhp`, `integrate_ensemble` (RKHP, explicit tableaux), `integrate_taylor` (THP, paper
Thm 5.1), `integrate_classical`, `integrate_midpoint` (peers), `integrate_spray_euler` (RKHP
Euler and its compositions on the spray realisation, direct form), `integrate_closed_euler` (the
same on the constant, lie-poisson and log-canonical families), `Trajectory`, `states_at`
(states at chosen times).
"""

from __future__ import annotations

from .._lazy import lazy_getattr

_LAZY = {
    "integrate_rkhp": "rkhp.integrators.rkhp_method",
    "integrate_ensemble": "rkhp.integrators.rkhp_method",
    "integrate_taylor": "rkhp.integrators.driver",
    "integrate_classical": "rkhp.integrators.classical",
    "integrate_midpoint": "rkhp.integrators.classical",
    "integrate_spray_euler": "rkhp.integrators.driver",
    "integrate_closed_euler": "rkhp.integrators.driver",
    "Trajectory": "rkhp.integrators.trajectory",
    "states_at": "rkhp.integrators.output_times",
    "TimedStates": "rkhp.integrators.output_times",
}

__all__ = sorted(_LAZY)


__getattr__ = lazy_getattr("rkhp.integrators", _LAZY)
