"""Events: the times where a function of the state changes sign, located by steps of the method
(docs/solve.md "Events").

An event is g(y) = 0 for an expression g in x1..xn (read by the safe reader
`rkhp.base.expressions`) or a Python function g(t, y) as scipy's ``solve_ivp`` takes. Between
grid points t_n and t_{n+1} where g changes sign (g(y_n) < 0 <= g(y_{n+1}) upwards, g(y_n) > 0 >=
g(y_{n+1}) downwards), the event time is t_n + s with s the root of phi(s) = g(Phi_s(y_n)),
Phi_s one step of the same method of size s (as the dense output, `rkhp.ivp.dense`): Brent's
method on s in [0, h], to round-off in t. The state there is that step, a Poisson map, so it lies
on the leaf of y_0. A sign change where |g| grows towards the located time is a pole of g (1/x1,
tan x1), not a zero, and no event; a value of g that is not finite at a grid point (NaN outside
g's domain) is a NumericalFailure. ``direction`` keeps only upward (> 0) or downward (< 0)
crossings; a ``terminal`` event ends the run at its first occurrence (or at its k-th, for an
integer k).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import InputError, NumericalFailure
from ..base.expressions import parse_expression, variable_names
from ..systems.spec import check_finite_at

EPS = float(np.finfo(float).eps)
#: the most events of one solve
MAX_EVENTS = 32


@dataclass(frozen=True)
class Event:
    """An event function and its flags.

    Attributes:
        name: the expression's text, or the function's name.
        values: states of shape (m, n) and times (m,) -> g at each (m,); None for an expression
            not read yet (:func:`event`: read when the solve knows the start).
        direction: > 0 upward crossings only, < 0 downward only, 0 both.
        terminal: 0: the run goes on; k >= 1: the run ends at the k-th occurrence.
    """

    name: str
    values: Callable | None = field(repr=False, compare=False)
    direction: float = 0.0
    terminal: int = 0

    def value(self, state, t: float) -> float:
        return float(self.values(np.asarray(state, dtype=np.float64)[None, :], np.array([t]))[0])


def event(expression: str, direction: float = 0.0, terminal=False) -> Event:
    """The event ``expression`` = 0 with its flags, for :func:`rkhp.solve` (``rkhp.event("x2",
    direction=1, terminal=True)``): the expression is read when the solve knows the system."""
    if not isinstance(expression, str):
        raise InputError(f"event: the expression must be a string, got {type(expression).__name__}")
    return Event(expression, None, _direction(direction, "event"), _terminal(terminal, "event"))


def expression_event(text: str, start, direction: float = 0.0, terminal=False, where: str = "event") -> Event:
    """The event g(y) = 0 of an expression in x1..xn, n = len(``start``) (the safe reader;
    InputError for anything outside its grammar, or for g not finite at ``start``, the orbit's
    first point: a constant beyond the float range, a start outside g's domain)."""
    import sympy

    names = variable_names(len(start))
    expr = parse_expression(text, names, where=where)
    symbols = [sympy.Symbol(name, real=True) for name in names]
    check_finite_at([("expression", expr)], symbols, start, where, gradient=False)
    function = sympy.lambdify(symbols, expr, "numpy")

    def event_values(states, times):
        with np.errstate(all="ignore"):
            out = function(*np.asarray(states, dtype=np.float64).T)
        return np.broadcast_to(np.asarray(out, dtype=np.float64), (len(states),)).copy()

    return Event(text, event_values, _direction(direction, where), _terminal(terminal, where))


def function_event(function: Callable, direction=None, terminal=None) -> Event:
    """The event of a Python function g(t, y) (scipy's form; its ``direction`` and ``terminal``
    attributes are read when the arguments are None)."""
    where = f"event {getattr(function, '__name__', 'function')}"
    direction = getattr(function, "direction", 0.0) if direction is None else direction
    terminal = getattr(function, "terminal", False) if terminal is None else terminal

    def function_values(states, times):
        return np.array([float(function(float(t), np.array(y))) for t, y in zip(times, states, strict=True)])

    return Event(getattr(function, "__name__", "function"), function_values, _direction(direction, where),
                 _terminal(terminal, where))


def _direction(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{where}: direction must be a finite number (> 0 up, < 0 down, 0 both)")
    return float(np.sign(value))


def _terminal(value, where: str) -> int:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, int) and value >= 0:
        return value
    raise InputError(f"{where}: terminal must be True, False or a count k >= 1 of occurrences")


def as_events(events, start) -> tuple[Event, ...]:
    """Events from an expression, an :class:`Event`, a function g(t, y), or a list of them, of an
    orbit from ``start`` (where an expression must be finite, :func:`expression_event`)."""
    if events is None:
        return ()
    items = list(events) if isinstance(events, list | tuple) else [events]
    if len(items) > MAX_EVENTS:
        raise InputError(f"{len(items)} events; at most {MAX_EVENTS}")
    out = []
    for k, item in enumerate(items):
        if isinstance(item, Event) and item.values is None:
            out.append(expression_event(item.name, start, item.direction, item.terminal, where=f"event {k + 1}"))
        elif isinstance(item, Event):
            out.append(item)
        elif isinstance(item, str):
            out.append(expression_event(item, start, where=f"event {k + 1}"))
        elif callable(item):
            out.append(function_event(item))
        else:
            raise InputError(f"event {k + 1}: an expression, an Event or a function g(t, y), "
                             f"got {type(item).__name__}")
    return tuple(out)


def crossings(event: Event, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Indices k of the intervals where g goes from ``before[k]`` to ``after[k]`` across 0 in the
    event's direction (module docstring)."""
    up = (before < 0) & (after >= 0)
    down = (before > 0) & (after <= 0)
    mask = up if event.direction > 0 else down if event.direction < 0 else (up | down)
    return np.flatnonzero(mask)


@dataclass(frozen=True)
class Occurrence:
    """One located event: its index among the events, the time and the state there."""

    event: int
    t: float
    state: np.ndarray


def locate(event: Event, step: Callable, t_n: float, y_n: np.ndarray, h: float, g_n: float,
           g_next: float) -> tuple[float, np.ndarray] | None:
    """(t, y) of the zero of g between t_n and t_n + h: Brent's method on the substep s, each value
    g(step(y_n, s)) (module docstring). ``step(y, s)`` is one step of the method. None where the
    sign change is a pole of g, not a zero (:func:`is_pole`); NumericalFailure where g is not
    finite near it."""
    from scipy.optimize import brentq

    if g_next == 0.0:
        return t_n + h, step(y_n, h)

    def phi(s):
        return g_n if s == 0.0 else event.value(step(y_n, s), t_n + s)

    low, high = (0.0, h) if h > 0 else (h, 0.0)
    f_low, f_high = (g_n, phi(h)) if h > 0 else (phi(h), g_n)
    if not (math.isfinite(f_low) and math.isfinite(f_high)):
        raise NumericalFailure(f"event {event.name}: not finite near t = {t_n:.6g}")
    if f_low * f_high > 0:  # the step recomputed lands on the other side by round-off
        return t_n + h, step(y_n, h)
    xtol = 4 * EPS * max(abs(t_n), abs(h))
    s = brentq(phi, low, high, xtol=xtol, rtol=4 * EPS)
    state = step(y_n, s)
    g = event.value(state, t_n + s)
    if math.isnan(g):
        raise NumericalFailure(f"event {event.name}: not finite near t = {t_n + s:.6g}")
    return None if is_pole(g, f_low, f_high) else (t_n + s, state)


def is_pole(g: float, g_low: float, g_high: float) -> bool:
    """Whether the sign change of g between the values ``g_low`` and ``g_high`` is a pole, not a
    zero: |g| at the point Brent's method converged to is no smaller than at both ends. Near a
    zero |g| there is the slope times the tolerance in t, far below the ends; near a pole (1/x1,
    tan x1) it grows without bound."""
    return abs(g) >= max(abs(g_low), abs(g_high))


def check_finite_values(event: Event, times: np.ndarray, g: np.ndarray) -> None:
    """NumericalFailure naming the first time where the event's value ``g`` is not finite (NaN
    outside g's domain, as sqrt(x1) for x1 < 0; inf at a pole): whether g crosses 0 there cannot
    be told."""
    bad = np.flatnonzero(~np.isfinite(g))
    if bad.size:
        raise NumericalFailure(f"event {event.name}: not finite at t = {float(times[bad[0]]):.6g} "
                               f"(g = {float(g[bad[0]])}); its crossings cannot be told")


def scan(events, step: Callable, times: np.ndarray, states: np.ndarray, values: list[np.ndarray],
         counts: list[int]) -> tuple[list[Occurrence], bool]:
    """The occurrences of ``events`` between the grid points ``times``/``states`` (the values of
    each event there in ``values``), in the order of time, and whether a terminal event ends the
    run (the occurrences after it left out). ``counts`` (occurrences so far per event) is
    updated."""
    found = []
    for i, event in enumerate(events):
        g = values[i]
        check_finite_values(event, times, g)
        for k in crossings(event, g[:-1], g[1:]):
            h = float(times[k + 1] - times[k])
            located = locate(event, step, float(times[k]), states[k], h, float(g[k]), float(g[k + 1]))
            if located is not None:
                found.append(Occurrence(i, *located))
    direction = 1.0 if times[-1] >= times[0] else -1.0
    found.sort(key=lambda o: direction * o.t)
    kept = []
    for occurrence in found:
        kept.append(occurrence)
        counts[occurrence.event] += 1
        terminal = events[occurrence.event].terminal
        if terminal and counts[occurrence.event] >= terminal:
            return kept, True
    return kept, False
