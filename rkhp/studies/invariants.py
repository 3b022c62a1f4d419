"""Casimir and energy errors along a trajectory (paper §5: RKHP methods keep every Casimir)."""

from __future__ import annotations

import numpy as np

from ..integrators.trajectory import energies


def energy_deviations(system, states) -> np.ndarray:
    """Per state: |H(x_n) - H(x_0)| (H by the compiled loop on a long trajectory,
    `rkhp.integrators.trajectory.energies`)."""
    values = energies(system, np.asarray(states, dtype=float))
    return np.abs(values - values[0])


def invariant_deviations(system, states) -> tuple[np.ndarray, np.ndarray]:
    """Per state: max over the Casimirs of |C(x_n) - C(x_0)|, and |H(x_n) - H(x_0)|.

    A system without Casimirs (e.g. a symplectic one) gets zeros for the first array.
    """
    states = np.asarray(states, dtype=float)
    energy = energy_deviations(system, states)
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
