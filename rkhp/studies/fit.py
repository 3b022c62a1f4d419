"""Observed orders of convergence: local orders, the asymptotic range, the fitted slope, verdicts.

docs/theory.md §6: the observed order is the least-squares slope of log(error) against log(h) over the
asymptotic range, leaving out the points at the round-off floor. Here the asymptotic range is found
from the data alone (never from the expected order): the finest run of at least three consecutive
usable rows whose local orders agree to within ``spread``, extended to coarser rows while they
still agree; usable rows coarser than the run are "pre-asymptotic", finer ones the "round-off
floor" once their error no longer falls (local order at most MIN_ORDER) and "order drift"
before that. Rows whose error is not above the reference's accuracy are "below reference
accuracy" and never enter a fit; failed runs are "failed".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError

SPREAD = 0.2
"""Largest difference between local orders inside the asymptotic range."""

VERDICT_TOLERANCE = 0.2
"""Largest |observed - expected| order for which the expected order counts as confirmed."""

MIN_ORDER = 0.5
"""Local orders inside the asymptotic range exceed this. A row finer than the range whose local
order is not above it (the error no longer falls) starts the round-off floor; a finer row whose
error still falls is "order drift"."""

DRIFT = 0.1
"""Local orders of a fitted range that move steadily (every one below, or every one above, the one
before) by more than this in all are a drift (:func:`drift`)."""

MIN_FIT_POINTS = 3
"""A fit needs at least this many step sizes (two local orders)."""


@dataclass(frozen=True)
class OrderFit:
    """The result of :func:`fit_order`.

    Attributes:
        slope: least-squares slope of log(error) against log(h) over ``fit_rows``; None when no
            asymptotic range of MIN_FIT_POINTS consistent points exists.
        fit_rows: indices (into the input) of the rows used by the fit.
        excluded: (row index, reason) for every row left out.
        local_orders: per row, log(e_prev/e)/log(h_prev/h) against the previous usable row.
    """

    slope: float | None
    fit_rows: tuple[int, ...]
    excluded: tuple[tuple[int, str], ...]
    local_orders: tuple[float | None, ...]


def local_order(h0: float, e0: float, h1: float, e1: float) -> float:
    """Observed order between two runs: log(e0/e1) / log(h0/h1)."""
    return math.log(e0 / e1) / math.log(h0 / h1)


def _usable(err: float | None, floor: float) -> str | None:
    if err is None or not math.isfinite(err):
        return "failed"
    if err <= floor:
        return "below reference accuracy"
    return None


def fit_order(h, errors, floor: float = 0.0, spread: float = SPREAD) -> OrderFit:
    """Fit the observed order over the asymptotic range of a convergence table.

    Args:
        h: step sizes, strictly decreasing.
        errors: global errors (None or nan for a failed run), same length.
        floor: errors at or below this are not measurements (reference accuracy).
        spread: largest spread of the local orders inside the asymptotic range.

    Returns:
        An :class:`OrderFit`.
    """
    h = [float(v) for v in h]
    if len(h) != len(errors):
        raise InputError(f"{len(h)} step sizes but {len(errors)} errors")
    if len(h) < MIN_FIT_POINTS:
        raise InputError(f"a fit needs at least {MIN_FIT_POINTS} step sizes, got {len(h)}")
    if any(b >= a for a, b in zip(h, h[1:], strict=False)):
        raise InputError("step sizes must be strictly decreasing")
    excluded: dict[int, str] = {}
    usable = []
    for i, e in enumerate(errors):
        reason = _usable(None if e is None else float(e), floor)
        if reason:
            excluded[i] = reason
        else:
            usable.append(i)
    orders: list[float | None] = [None] * len(h)
    for a, b in zip(usable, usable[1:], strict=False):
        orders[b] = local_order(h[a], errors[a], h[b], errors[b])
    best = _asymptotic_window(usable, orders, spread)
    if best is None:
        for i in usable:
            excluded[i] = "no asymptotic range"
        return OrderFit(None, (), tuple(sorted(excluded.items())), tuple(orders))
    lo, hi = best
    rows = tuple(usable[lo:hi + 1])
    for i in usable[:lo]:
        excluded[i] = "pre-asymptotic"
    floor_reached = False
    for i in usable[hi + 1:]:
        floor_reached = floor_reached or orders[i] <= MIN_ORDER
        excluded[i] = "round-off floor" if floor_reached else "order drift"
    x = np.log([h[i] for i in rows])
    y = np.log([float(errors[i]) for i in rows])
    slope = float(np.polyfit(x, y, 1)[0])
    return OrderFit(slope, rows, tuple(sorted(excluded.items())), tuple(orders))


def _asymptotic_window(usable: list[int], orders: list, spread: float):
    """(lo, hi) positions in ``usable`` of the asymptotic range, or None.

    A run of rows is consistent when its local orders (pairs inside it) all exceed MIN_ORDER and
    differ by at most ``spread``. The range ends at the finest row that ends a consistent run of
    MIN_FIT_POINTS rows, and extends to coarser rows while the run stays consistent.
    """

    def consistent(lo: int, hi: int) -> bool:
        inner = [orders[usable[k]] for k in range(lo + 1, hi + 1)]
        return min(inner) > MIN_ORDER and max(inner) - min(inner) <= spread

    for hi in range(len(usable) - 1, MIN_FIT_POINTS - 2, -1):
        lo = hi - MIN_FIT_POINTS + 1
        if consistent(lo, hi):
            while lo > 0 and consistent(lo - 1, hi):
                lo -= 1
            return lo, hi
    return None


def drift(fit: OrderFit) -> str | None:
    """"falling" or "rising" when the local orders inside the fitted range move steadily: each one
    below (above) the one before, by more than DRIFT in all; else None. The range is then not yet
    asymptotic (the slope averages orders that are still changing), and the order the rows tend
    to lies beyond the last local order, not at the slope."""
    inner = [fit.local_orders[i] for i in fit.fit_rows[1:]]
    if len(inner) < 2 or any(p is None for p in inner):
        return None
    steps = [b - a for a, b in zip(inner, inner[1:], strict=False)]
    if all(d < 0 for d in steps) and inner[0] - inner[-1] > DRIFT:
        return "falling"
    if all(d > 0 for d in steps) and inner[-1] - inner[0] > DRIFT:
        return "rising"
    return None


def verdict(observed: float | None, expected: int | None, fit: OrderFit | None = None,
            tol: float = VERDICT_TOLERANCE) -> str:
    """"confirmed", "higher than expected", "lower than expected" or "inconclusive".

    With the ``fit``, a discrepancy is claimed only when the rows show it: "higher" (or "lower")
    becomes "inconclusive" when the local orders of the fitted range fall (rise) steadily towards
    the expected order (:func:`drift`), i.e. when the slope is the mean of a drift, not a limit.
    """
    if observed is None or expected is None:
        return "inconclusive"
    if abs(observed - expected) <= tol:
        return "confirmed"
    moving = drift(fit) if fit is not None else None
    if observed > expected:
        return "inconclusive" if moving == "falling" else "higher than expected"
    return "inconclusive" if moving == "rising" else "lower than expected"
