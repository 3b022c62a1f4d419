"""The result of an integration: states, Newton counts, and a status that names any failure.

A failed run keeps only the states computed before the failure (never numbers past it), and says
at which step and time it failed and why (paper §5.2: the implicit equation alpha(x, psi(x)) = y
may have no solution for a large step): `cause` (a `rkhp.integrators.failure.Failure`) for
programs, `status` for people.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..base.errors import NumericalFailure
from .failure import Failure, failure_status

GROWTH = 100.0
"""A state counts as grown when its max-norm exceeds this times max(1, |y_0|) (`divergence`)."""
DIVERGENCE = 1e8
"""A grown state whose energy error exceeds this times max(1, |H(y_0)|) ends the run (`divergence`)."""


@dataclass(frozen=True)
class Trajectory:
    """States y_0..y_k at times t_0..t_k of one run.

    Attributes:
        times: shape (k+1,).
        states: shape (k+1, n); for a failed run, only the steps before the failure.
        newton_iterations: shape (k,), Newton iterations per step (zeros for explicit peers).
        stage_sweeps: shape (k,), sweeps of the implicit stages per step (RKHP with an implicit
            tableau; zeros otherwise, empty for the other integrators).
        status: "ok", or a failure message naming the step, the time and the cause.
        failed_step: the 0-based index of the step that failed (step k goes from y_k to y_{k+1};
            it equals the number of completed steps, and states has failed_step + 1 rows), or
            None.
        cause: Failure.OK, or why the run failed (`rkhp.integrators.failure`).
        compile_seconds: time spent compiling (first call of a compiled kernel), apart from run time.
        run_seconds: wall time of the integration itself.
        method: name of the method; system: name of the system.
        extra: free-form details (e.g. Newton tolerance used).
    """

    times: np.ndarray
    states: np.ndarray
    newton_iterations: np.ndarray
    stage_sweeps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    status: str = "ok"
    failed_step: int | None = None
    cause: Failure = Failure.OK
    compile_seconds: float = 0.0
    run_seconds: float = 0.0
    method: str = ""
    system: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.cause == Failure.OK

    @property
    def final_state(self) -> np.ndarray:
        return self.states[-1]

    def raise_if_failed(self) -> Trajectory:
        """Return self when the run succeeded, else raise NumericalFailure with the status."""
        if not self.ok:
            raise NumericalFailure(self.status)
        return self


def divergence(system, states) -> int | None:
    """The index k of the first state y_k that has left every sane range, or None.

    The rule (docs/exit-status.md "Divergence"): y_k is non-finite, or it grew (|y_k| > GROWTH
    max(1, |y_0|), max-norms) and its energy error exceeds DIVERGENCE max(1, |H(y_0)|). The exact
    flow keeps H; a run that still approximates it, however coarsely, keeps its energy error
    near the energy's own size (`rkhp stress` calls a relative error above 1 "not bounded"), far
    below 1e8 times it, while a blow-up passes that within a few steps (H grows like a power of
    |y|). Growth alone is no divergence (a hyperbolic flow grows like e^t with H conserved), and
    requiring it first keeps H's evaluation to the few grown states.
    """
    states = np.asarray(states, dtype=float)
    finite = np.isfinite(states).all(axis=1)
    bad = np.flatnonzero(~finite)
    first_bad = int(bad[0]) if bad.size else None
    size = np.abs(np.where(finite[:, None], states, 0.0)).max(axis=1, initial=0.0)
    grown = np.flatnonzero(finite & (size > GROWTH * max(1.0, size[0])))
    if grown.size:
        h0 = float(system.hamiltonian(states[0]))
        bound = DIVERGENCE * max(1.0, abs(h0))
        for k in grown:
            if first_bad is not None and k > first_bad:
                break
            try:
                with np.errstate(all="ignore"):
                    energy = float(system.hamiltonian(states[k]))
            except (OverflowError, FloatingPointError, ValueError, ZeroDivisionError):
                return int(k)  # H cannot even be evaluated there
            if not abs(energy - h0) <= bound:  # also catches an energy that overflows
                return int(k)
    return first_bad


def checked(trajectory: Trajectory, system) -> Trajectory:
    """The trajectory, or when it diverged (`divergence`), the same run ended before the state
    that diverged: cause Failure.DIVERGED (or NON_FINITE for a non-finite state) at the step that
    produced it."""
    k = divergence(system, trajectory.states)
    if k is None or k == 0:
        return trajectory
    cause = Failure.NON_FINITE if not np.isfinite(trajectory.states[k]).all() else Failure.DIVERGED
    step = k - 1
    h = float(trajectory.times[1] - trajectory.times[0]) if len(trajectory.times) > 1 else 0.0
    return replace(trajectory, times=trajectory.times[:k], states=trajectory.states[:k],
                   newton_iterations=trajectory.newton_iterations[:k],
                   stage_sweeps=trajectory.stage_sweeps[:k], cause=cause, failed_step=step,
                   status=failure_status(cause, step, h, system.domain))
