"""Poincaré sections: the points where an orbit crosses a hypersurface g(x) = 0 in one direction
(docs/solve.md "Poincaré sections").

The crossings are the events of :mod:`rkhp.ivp.events` (located by steps of the method, to
round-off in t), of a solve to a tolerance or by a number of steps (:func:`rkhp.ivp.solve.solve`).
Each point is a step of the method from the grid: a Poisson map, so the points keep the Casimirs
of y_0; the energy error at the points is reported beside them. On an integrable system an orbit
on a resonant torus (a periodic orbit) gives a fixed point of the return map, the same point at
every crossing; a quasi-periodic orbit fills a curve; a chaotic one a region.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..integrators.methods import DEFAULT_METHOD, resolve_system
from .events import expression_event
from .solve import SolveResult, solve

#: the directions a section takes, by name
DIRECTIONS = {"up": 1.0, "down": -1.0, "both": 0.0}


@dataclass(frozen=True)
class Section:
    """The crossings of one orbit with g(x) = 0: their times (k,) and points (k, n), the
    expression and direction, and the solve that found them."""

    expression: str
    direction: str
    times: np.ndarray
    points: np.ndarray
    result: SolveResult

    json_keys = (("system", "result.system"), ("section", "expression"), "direction", ("method", "result.method"),
                 ("steps", "result.steps"), ("h", "result.h"), ("tolerance", "result.tolerance"),
                 ("estimated_error", "result.estimated_error"), "count", "times", "points",
                 ("casimir_error_max", "result.casimir_error_max"), ("energy_error_max", "result.energy_error_max"),
                 ("invariant_errors_max", "result.invariant_errors_max"), ("status", "result.status"),
                 ("message", "result.message"))

    @property
    def count(self) -> int:
        """The number of crossings."""
        return len(self.times)


def poincare_section(system, expression: str, t_final: float | None = None, method=DEFAULT_METHOD, tol=None, *,
            steps=None, direction: str = "up", x0=None, realisation: str = "symmetric", on_plan=None,
            on_progress=None, on_candidate=None) -> Section:
    """The Poincaré section of ``system``'s orbit (from ``x0``, default its start) over [0,
    ``t_final``] (default the system's T) with the hypersurface ``expression`` = 0 (an expression
    in x1..xn, the safe reader), crossed ``direction`` ("up": g increasing, "down", "both"), by
    :func:`rkhp.ivp.solve.solve` with ``method`` and ``tol`` or ``steps``."""
    if direction not in DIRECTIONS:
        raise InputError(f"direction {direction!r}: one of {', '.join(DIRECTIONS)}")
    poisson = resolve_system(system, realisation, x0)
    event = expression_event(expression, poisson.x0, DIRECTIONS[direction], where="--section")
    end = poisson.t_final if t_final is None else t_final
    result = solve(poisson, (0.0, end), method, tol, steps=steps, t_eval=[end], events=[event],
                   on_plan=on_plan, on_progress=on_progress, on_candidate=on_candidate)
    return Section(expression, direction, result.t_events[0], result.y_events[0], result)


def axes_of(names, dim: int) -> tuple[int, int]:
    """The two coordinates of a plot, from names such as ("x1", "x3") (0-based indices)."""
    if len(names) != 2:
        raise InputError(f"--axes: two coordinates, got {len(names)}")
    known = {f"x{i + 1}": i for i in range(dim)}
    out = []
    for name in names:
        if name not in known:
            raise InputError(f"--axes: {name!r} is not a coordinate (x1..x{dim})")
        out.append(known[name])
    if out[0] == out[1]:
        raise InputError("--axes: two different coordinates")
    return out[0], out[1]
