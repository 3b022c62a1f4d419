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


def declared_deviations(system, states, start=None) -> np.ndarray:
    """Per state and declared invariant (`PoissonSystem.invariants`, a spec file's
    ``invariants``): |I(x_n) - I(x_0)|, shape (m, k), x_0 = ``start`` (default the first state)."""
    states = np.asarray(states, dtype=float)
    first = states[0] if start is None else np.asarray(start, dtype=float)
    out = np.zeros((len(states), len(system.invariants)))
    for k, invariant in enumerate(system.invariants):
        values = np.fromiter((invariant(x) for x in states), dtype=float, count=len(states))
        out[:, k] = np.abs(values - invariant(first))
    return out


def declared_errors(system, states, start=None) -> list[float]:
    """The largest |I(x_n) - I(x_0)| over ``states`` of each declared invariant (empty without any)."""
    if not system.invariants or len(states) == 0:
        return []
    return [float(v) for v in declared_deviations(system, states, start).max(axis=0)]


def declared_error(system, states, start=None) -> float | None:
    """The largest drift of any declared invariant over ``states``; None for a system without any."""
    errors = declared_errors(system, states, start)
    return max(errors) if errors else None


def declared_columns(system, columns: dict) -> dict:
    """The columns of a trajectory file (`rkhp.integrators.trajectory.state_columns`) with
    ``invariant1..`` (the declared invariants at each state) after the Casimirs."""
    if not system.invariants:
        return columns
    n = system.dim
    states = np.column_stack([columns[f"x{i + 1}"] for i in range(n)])
    out = {}
    for key, value in columns.items():
        if key == "newton_iterations":
            for k, invariant in enumerate(system.invariants):
                out[f"invariant{k + 1}"] = np.fromiter((invariant(x) for x in states), dtype=float,
                                                        count=len(states))
        out[key] = value
    return out
