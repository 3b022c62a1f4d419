"""A constant-step run of a method over [t0, t1], in chunks (docs/solve.md).

The run is N steps of size h = (t1 - t0) / N of one method from y_0, the same steps as one call
of :meth:`rkhp.integrators.methods.Method.integrate`: the system is autonomous, so a step from
y_n does not depend on t_n, and a run continued from its last state gives the same states. Split
into chunks, it reports its progress after each (a long solve shows a bar on a terminal), a
caller may stop it after any chunk (a terminal event) and needs to keep only what it uses (the
states at chosen times, the largest drifts), and the times are t0 + n h, the last one exactly t1.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..base import bounds
from ..base.errors import InputError
from ..integrators.failure import Failure
from ..integrators.trajectory import Trajectory

#: steps of one chunk at least (a call of the compiled loop costs about 0.1-0.5 ms on its own)
MIN_CHUNK = 2_000
#: a long run is reported in about this many chunks
CHUNKS = 50


@dataclass(frozen=True)
class Span:
    """The time span of a run: from ``t0`` to ``t1`` (t1 < t0 runs backwards)."""

    t0: float
    t1: float

    @property
    def length(self) -> float:
        return self.t1 - self.t0

    def step(self, steps: int) -> float:
        """h = (t1 - t0) / steps."""
        return self.length / steps

    def times(self, steps: int, first: int = 0, count: int | None = None, exact_end: bool = True) -> np.ndarray:
        """The grid times t0 + n h (h = span / steps) for n = first .. first + count - 1 (default:
        to the end), t_N exactly t1 when ``exact_end`` (else N h, which may miss t1 by round-off,
        as the times of one call of the method)."""
        count = steps + 1 - first if count is None else count
        n = np.arange(first, first + count, dtype=np.float64)
        times = self.t0 + n * self.step(steps)
        if exact_end and first + count - 1 == steps:
            times[-1] = self.t1
        return times


def check_span(t_span) -> Span:
    """The span (t0, t1) of two finite, distinct numbers (InputError otherwise)."""
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError):
        raise InputError("t_span must be two numbers (t0, t1)") from None
    for value, name in ((t0, "t0"), (t1, "t1")):
        bounds.number(value, f"t_span: {name}")
    if t0 == t1:
        raise InputError("t_span: t0 and t1 must differ")
    return Span(t0, t1)


def chunk_size(steps: int) -> int:
    """Steps per chunk: about steps / CHUNKS, at least MIN_CHUNK."""
    return max(MIN_CHUNK, -(-steps // CHUNKS))


@dataclass(frozen=True)
class Chunk:
    """Consecutive grid points of a run: y_first .. y_(first + m) (the first one the last of the
    chunk before) at their times, the Newton iterations and stage sweeps of the m steps, and how
    the last of them ended (``status``: "ok" or the failure line, naming the step counted from
    y_0)."""

    first: int
    times: np.ndarray
    states: np.ndarray
    newton_iterations: np.ndarray
    stage_sweeps: np.ndarray
    cause: Failure
    status: str
    run_seconds: float
    compile_seconds: float

    @property
    def ok(self) -> bool:
        return self.cause == Failure.OK


def chunks(system, method, span: Span, steps: int, x0=None, exact_end: bool = True) -> Iterator[Chunk]:
    """The chunks of ``steps`` steps of ``method`` (a Method) on ``system`` (a PoissonSystem) over
    ``span`` from ``x0`` (default: the system's start); a failed chunk is the last. The times:
    :meth:`Span.times`."""
    h = span.step(steps)
    state = system.start(x0)
    done = 0
    size = chunk_size(steps)
    while done < steps:
        part = method.integrate(system, h, min(size, steps - done), state)
        m = len(part.states) - 1
        status = "ok" if part.ok else failure_line(part.cause, done + m, span, h, system.domain)
        yield Chunk(done, span.times(steps, done, m + 1, exact_end), part.states,
                    np.asarray(part.newton_iterations, dtype=np.int64)[:m],
                    np.asarray(part.stage_sweeps, dtype=np.int64)[:m], part.cause, status, part.run_seconds,
                    part.compile_seconds)
        if not part.ok:
            return
        done += m
        state = part.states[-1]


def failure_line(cause: Failure, step: int, span: Span, h: float, domain: str) -> str:
    """The status line of a run that failed in step ``step`` (counted from y_0, as
    `rkhp.integrators.failure`), with the times of that step on the span's grid."""
    text = cause.text + (f" ({domain})" if cause == Failure.LEFT_DOMAIN and domain else "")
    return (f"failed at step {step} (t = {span.t0 + step * h:.6g} -> {span.t0 + (step + 1) * h:.6g}): "
            f"{text}")


def trajectory(system, method, span: Span, steps: int, x0=None, on_progress=None) -> Trajectory:
    """The whole run as one :class:`~rkhp.integrators.trajectory.Trajectory`, its states and times
    t0 + n h those of one call of the method, ``on_progress(done, steps)`` after each chunk; a
    failed run keeps the states before the failure, as one call of the method would."""
    bounds.check_trajectory(steps, system.dim)
    parts = list(_with_progress(chunks(system, method, span, steps, x0, exact_end=False), steps, on_progress))
    states = np.concatenate([parts[0].states] + [c.states[1:] for c in parts[1:]])
    last = parts[-1]
    return Trajectory(np.concatenate([parts[0].times] + [c.times[1:] for c in parts[1:]]), states,
                      np.concatenate([c.newton_iterations for c in parts]),
                      np.concatenate([c.stage_sweeps for c in parts]), last.status,
                      None if last.ok else len(states) - 1, last.cause,
                      sum(c.compile_seconds for c in parts), sum(c.run_seconds for c in parts),
                      method.name, system.name, poisson=system)


def _with_progress(parts, steps: int, on_progress):
    for chunk in parts:
        if on_progress is not None:
            on_progress(chunk.first + len(chunk.states) - 1, steps)
        yield chunk
