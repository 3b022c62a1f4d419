"""Long-time energy behaviour: the growth of |H(y_n) - H(y_0)| over 10^6 steps and more, fitted
as a power of t (docs/stability.md "Long-time behaviour").

A method with a modified Hamiltonian (every RKHP method with an exact birealisation, docs/theory.md
§11; compositions of them) keeps the energy error bounded over exponentially long times near
Liouville tori (Cosserat, "Some stability properties of Hamiltonian Poisson integrators",
arXiv 2511.14303): the running maximum of the error flattens, exponent about 0. A method without
one (scipy's DOP853 at a fixed tolerance) drifts: exponent about 1 (a systematic drift per step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..integrators.methods import Method, resolve_method
from .bench import solve_peer
from .invariants import declared_errors, energy_deviations

#: samples of the running maximum, log-spaced in t
SAMPLES = 60
#: the fit uses the last decades of t: t >= t_final * FIT_FROM
FIT_FROM = 1e-3


@dataclass(frozen=True)
class Growth:
    """One method's run: times, the running maximum of |H - H(y_0)| there, the fitted exponent
    (slope of log error against log t over t >= t_final * FIT_FROM; None when the errors there are
    all at zero) and the final error."""

    method: str
    h: float | None
    steps: int | None
    tolerance: float | None
    times: tuple[float, ...]
    errors: tuple[float, ...]
    exponent: float | None
    status: str
    invariant_errors: tuple[float, ...] = ()

    json_keys = ("method", "h", "steps", "tolerance", "times", ("energy_errors", "errors"), "exponent", "status",
                 ("invariant_errors_max", "invariant_errors"))


def log_sample_times(t_final: float, h: float) -> np.ndarray:
    """SAMPLES times log-spaced from 10 h to t_final."""
    return np.geomspace(10 * h, t_final, SAMPLES)


def running_max_at(times_all: np.ndarray, errors_all: np.ndarray, times: np.ndarray) -> np.ndarray:
    """max_{s <= t} error(s) at each t of `times` (errors_all given at times_all, increasing)."""
    running = np.maximum.accumulate(errors_all)
    idx = np.searchsorted(times_all, times, side="right") - 1
    return running[np.clip(idx, 0, len(running) - 1)]


def fit_exponent(times, errors, t_final: float) -> float | None:
    """Least-squares slope of log(error) against log(t) over t >= t_final * FIT_FROM, errors > 0."""
    t, e = np.asarray(times), np.asarray(errors)
    keep = (t >= t_final * FIT_FROM) & (e > 0)
    if keep.sum() < 3:
        return None
    return float(np.polyfit(np.log(t[keep]), np.log(e[keep]), 1)[0])


def energy_growth(system, method, h: float, steps: int, tolerance: float = 1e-10) -> Growth:
    """Run `method` (an RKHP or other fixed-step method: `steps` steps of size h; a scipy method:
    to t = h * steps at rtol `tolerance`) and fit the growth of its energy error."""
    m: Method = resolve_method(method)
    t_final = h * steps
    times = log_sample_times(t_final, h)
    if m.kind == "scipy":
        sol = solve_peer(system, m.solver, np.asarray(system.x0, dtype=float), t_final, tolerance)
        if not sol.success:
            return Growth(m.name, None, None, tolerance, (), (), None, f"failed: {sol.message}")
        err = energy_deviations(system, sol.y.T)
        errors = running_max_at(sol.t, err, times)
        return Growth(m.name, None, None, tolerance, tuple(times), tuple(errors),
                      fit_exponent(times, errors, t_final), "ok", tuple(declared_errors(system, sol.y.T)))
    run = m.integrate(system, h, steps)
    if not run.ok:
        return Growth(m.name, h, steps, None, (), (), None, run.status)
    stride = max(1, steps // 200_000)  # the running maximum over at least 2 10^5 points
    states = run.states[::stride]
    err = energy_deviations(system, states)
    errors = running_max_at(run.times[::stride], err, times)
    return Growth(m.name, h, steps, None, tuple(times), tuple(errors), fit_exponent(times, errors, t_final), "ok",
                  tuple(declared_errors(system, states)))


def check_long_time(h: float, steps: int) -> None:
    """InputError unless h > 0 is finite and 1 <= steps <= 10^8 with at least 100 steps."""
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"--h must be positive and finite, got {h}")
    if not 100 <= steps <= 10**8:
        raise InputError(f"--steps must be from 100 to 10^8, got {steps}")
