"""Casimir and energy errors along a trajectory (paper §5: RKHP methods keep every Casimir)."""

from __future__ import annotations

import numpy as np

COMPILED_FROM = 20_000
"""From this many states on, H is evaluated by the compiled loop
(:func:`rkhp.integrators.energy.hamiltonian_values`); below, by the system's own evaluation
(about 27 us per state on the rigid body), which spares short studies a cold compilation of the
loop (about 7 s CPU measured)."""


def energies(system, states) -> np.ndarray:
    """H at every row of ``states``."""
    if len(states) >= COMPILED_FROM:
        from ..integrators.energy import hamiltonian_values

        return hamiltonian_values(system, states)
    return np.fromiter((system.hamiltonian(x) for x in states), dtype=float, count=len(states))


def invariant_deviations(system, states) -> tuple[np.ndarray, np.ndarray]:
    """Per state: max over the Casimirs of |C(x_n) - C(x_0)|, and |H(x_n) - H(x_0)|.

    A system without Casimirs (e.g. a symplectic one) gets zeros for the first array.
    """
    states = np.asarray(states, dtype=float)
    energy = energies(system, states)
    energy = np.abs(energy - energy[0])
    casimir = np.zeros(len(states))
    for C in system.casimirs:
        values = np.fromiter((C(x) for x in states), dtype=float, count=len(states))
        casimir = np.maximum(casimir, np.abs(values - values[0]))
    return casimir, energy


def max_deviations(system, states) -> tuple[float | None, float]:
    """(max Casimir error, max energy error) over a trajectory; the Casimir error is None for a
    system without Casimirs (no such quantity, shown as a dash)."""
    casimir, energy = invariant_deviations(system, states)
    return (float(casimir.max()) if system.casimirs else None), float(energy.max())


def window_maxima(values, windows: int) -> list[float]:
    """The maximum of ``values`` in each of ``windows`` consecutive, near-equal windows."""
    return [float(np.max(chunk)) for chunk in np.array_split(np.asarray(values), windows) if len(chunk)]
