"""The numbers of steps of a convergence study chosen for the method and the system (docs/studies.md,
"How the steps are chosen").

Pilot runs of the method find its coarsest usable run: from PILOT_START steps, doubled while a run
fails or its error at T is above TOP_ERROR |x(T)| (pre-asymptotic); then, while the rows it leaves
between itself and the reference's floor are fewer than the default's doublings, coarsened by
COARSENING while runs succeed and stay below that bound. The expected order p then predicts, from
the finest pilot run above the floor, the finest run worth measuring, where the error C h^p meets
FLOOR_MARGIN times the reference's floor;
the study takes ROWS numbers of steps from the coarsest to that finest (doublings where there is
room for them, a geometric progression otherwise). A range narrower than MIN_SPAN in h is
"narrow": the reference, not the method, limits the study.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .fit import MIN_FIT_POINTS

#: the first pilot run, and the coarsest step of the default study
PILOT_START = 20
#: the studies' default: ROWS numbers of steps, each twice the one before
ROWS = 7
#: an error above this times max(1, |x(T)|) is pre-asymptotic (relative to the state)
TOP_ERROR = 0.1
#: the finest run is where the predicted error is this many times the reference's floor
FLOOR_MARGIN = 10.0
#: the pilot runs go coarser by this factor
COARSENING = 1.25
#: pilot runs going finer stop past this many steps
MAX_PILOT_STEPS = 20_480
#: a step range narrower than this ratio of h is narrow
MIN_SPAN = 4.0


@dataclass(frozen=True)
class StepChoice:
    """The numbers of steps chosen for one method (coarsest first), the pilot runs that chose them
    (steps and error at T, None for a failed run), whether the range is narrow (MIN_SPAN) and how
    it was chosen, in words."""

    counts: tuple[int, ...]
    pilots: tuple[tuple[int, float | None], ...]
    narrow: bool
    how: str


def choose_steps(final_state: Callable, reference, order: int) -> StepChoice:
    """The steps of a study of a method of expected order `order` against `reference`;
    ``final_state(n)`` is x(T) of the method's run of n steps (None where it fails), cached by the
    caller so that another reference reuses the runs (module docstring)."""
    top = TOP_ERROR * max(1.0, float(np.linalg.norm(reference.state)))
    bottom = FLOOR_MARGIN * reference.floor
    pilots: dict[int, float | None] = {}

    def error(n: int) -> float | None:
        if n not in pilots:
            x = final_state(n)
            pilots[n] = None if x is None else float(np.linalg.norm(x - reference.state))
        return pilots[n]

    def usable(e) -> bool:
        return e is not None and math.isfinite(e) and e <= top

    def finest(n: int) -> float:
        """The number of steps where C h^p meets the bottom, from the finest pilot run of at least
        n steps whose error is above it (n itself when none is)."""
        above = [(k, e) for k, e in pilots.items() if k >= n and usable(e) and e > bottom]
        k, e = max(above) if above else (n, bottom)
        return k * (e / bottom) ** (1.0 / order)

    def span(n: int) -> float:
        return finest(n) / n

    n = PILOT_START
    while not usable(error(n)):
        if 2 * n > MAX_PILOT_STEPS:
            return StepChoice(_doublings(PILOT_START), _listed(pilots), False,
                              f"no pilot run up to {n} steps ran with an error at T below {top:.1g}: "
                              f"the default {_range(_doublings(PILOT_START))}")
        n *= 2
    while span(n) < 2 ** (ROWS - 1):
        coarser = int(n / COARSENING)
        if coarser < 1 or coarser == n or not usable(error(coarser)):
            break
        n = coarser
    e = error(n)
    ratio = span(n)
    counts = _doublings(n) if ratio >= 2 ** (ROWS - 1) else _progression(n, ratio)
    narrow = ratio < MIN_SPAN
    coarser = [k for k in pilots if k < n]
    if coarser:
        k = max(coarser)
        stop = f"{k} steps fail" if pilots[k] is None else f"{k} steps: error {pilots[k]:.1e} above {top:.1g}"
    else:
        stop = "the first pilot run"
    fine_end = ("doublings: the error stays above the reference's floor" if ratio >= 2 ** (ROWS - 1)
                else f"where order {order} brings the error to {FLOOR_MARGIN:g}x the reference's floor")
    how = (f"{counts[0]} to {counts[-1]}, chosen by pilot runs of {', '.join(str(k) for k in sorted(pilots))} "
           f"steps: from {n} (error at T {e:.1e}; {stop}) to {counts[-1]} ({fine_end})"
           f"{'; a narrow range' if narrow else ''}")
    return StepChoice(counts, _listed(pilots), narrow, how)


def _doublings(n: int) -> tuple[int, ...]:
    return tuple(n * 2**k for k in range(ROWS))


def _progression(n: int, ratio: float) -> tuple[int, ...]:
    """ROWS numbers of steps from n to n * ratio in geometric progression, rounded and distinct; at
    least MIN_FIT_POINTS (n, n + 1, ... where the range holds fewer integers)."""
    counts = sorted({round(n * ratio ** (k / (ROWS - 1))) for k in range(ROWS)})
    while len(counts) < MIN_FIT_POINTS:
        counts.append(counts[-1] + 1)
    return tuple(counts)


def _listed(pilots) -> tuple[tuple[int, float | None], ...]:
    return tuple(sorted(pilots.items()))


def _range(counts) -> str:
    return f"{counts[0]} to {counts[-1]} steps"
