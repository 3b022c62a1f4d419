"""One failure vocabulary for every integrator: how a run ends, and the status line that says so.

The RKHP engine (explicit and implicit tableaux), the THP integrator and the classical peers
(explicit Runge–Kutta, implicit midpoint) return a :class:`Failure` per run (compiled kernels
return the member; numba passes IntEnum members through unchanged); the Trajectory keeps it as
``cause`` next to the human ``status`` line built by :func:`failure_status`.

Step numbering (``Trajectory.failed_step`` and the status line): steps are numbered from 0 like
the states, step k going from y_k (t = k h) to y_{k+1}; the failing step's index equals the number
of steps completed, so a failed trajectory keeps states y_0..y_k, ``failed_step + 1`` of them.
"""

from __future__ import annotations

from enum import IntEnum


class Failure(IntEnum):
    """Why a run stopped (OK: it did not)."""

    OK = 0
    NEWTON_NO_CONVERGENCE = 1
    NON_FINITE = 2
    LEFT_DOMAIN = 3
    NEWTON_NON_FINITE = 4
    NEWTON_DIVERGED = 5
    SINGULAR = 6
    STAGES_NO_CONVERGENCE = 7
    DIVERGED = 8

    @property
    def text(self) -> str:
        """The cause in words, as the status line and the studies print it."""
        return _TEXT[self]


_TEXT = {
    Failure.OK: "ok",
    Failure.NEWTON_NO_CONVERGENCE: "Newton did not converge (the step h may be too large)",
    Failure.NON_FINITE: "non-finite values",
    Failure.LEFT_DOMAIN: "left the domain",
    Failure.NEWTON_NON_FINITE: "Newton did not converge: non-finite iterate (the step h may be too large)",
    Failure.NEWTON_DIVERGED: "Newton diverged (the step h may be too large)",
    Failure.SINGULAR: "singular Newton matrix",
    Failure.STAGES_NO_CONVERGENCE: "the implicit stages did not converge (the step h may be too large)",
    Failure.DIVERGED: "diverged: the state grew past 100 times its start and the energy error past 1e8 "
                      "times max(1, |H(x0)|) (docs/exit-status.md; the step h may be too large)",
}


def failure_status(cause: Failure, step: int, h: float, domain: str = "") -> str:
    """The status line of a run that failed in step `step` (0-based, see the module) of size h;
    `domain` (the system's) is named when the cause is LEFT_DOMAIN."""
    text = cause.text + (f" ({domain})" if cause == Failure.LEFT_DOMAIN and domain else "")
    return f"failed at step {step} (t = {step * h:.6g} -> {(step + 1) * h:.6g}): {text}"
