"""Adaptive peers of the RKHP integrators, each on the field a user of it would write (docs/studies.md "Peers").

A peer integrates ``xdot = pi(x) grad H(x)`` from x0 to T at a tolerance rtol (atol = 1e-3 rtol)
and returns the end state. Its field is generated from the system (`rkhp.systems.field_code`), so
that built-in systems and spec files are raced alike:

- ``scipy:NAME``: scipy's ``solve_ivp`` (DOP853, RK45, ...) on the field written with plain
  arithmetic on Python floats (form ``numpy``): a Python call per evaluation;
- ``numbalsoda:dop853``: Hairer's DOP853 in Fortran (numbalsoda) calling the field as a numba
  ``cfunc`` ``void(t, u*, du*, p*)`` (form ``cfunc``): the whole loop compiled;
- ``diffrax:dopri8``, ``diffrax:tsit5``: diffrax's Dopri8 and Tsit5 with a PID step-size controller,
  the whole solve traced by ``jax.jit`` (CPU, float64; form ``jax``).

The compiled peers need the optional extra ``peers`` (``pip install 'rkhp[peers]'``; numbalsoda
builds with a Fortran compiler, Debian's ``gfortran``). :func:`absent` names a missing one in one
line; the studies report it rather than leave it out unseen. :func:`prepare` compiles a peer's field
and solver once (the compile or trace time is measured apart, :attr:`Prepared.compile_seconds`) and
returns the solve to time.
"""

from __future__ import annotations

import importlib.util
import time
import weakref
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError, NumericalFailure
from ..integrators.methods import SCIPY_METHODS
from ..systems.field_code import compiled
from ..systems.field_code import field_code as generate
from .reference import Reference, reference

ATOL_RATIO = 1e-3
"""atol = ATOL_RATIO rtol, for every peer."""
MAX_STEPS = 1_000_000
"""Steps after which a compiled peer gives up (its status then says so)."""
EXTRA = "pip install 'rkhp[peers]'"


class Peer(NamedTuple):
    """A peer: its name (``kind:solver``), the package that runs it, the solver's own name and the
    modules it needs."""

    name: str
    kind: str
    solver: str
    modules: tuple[str, ...]


COMPILED_PEERS: dict[str, Peer] = {
    "numbalsoda:dop853": Peer("numbalsoda:dop853", "numbalsoda", "dop853", ("numbalsoda",)),
    "diffrax:dopri8": Peer("diffrax:dopri8", "diffrax", "Dopri8", ("jax", "diffrax")),
    "diffrax:tsit5": Peer("diffrax:tsit5", "diffrax", "Tsit5", ("jax", "diffrax")),
}
ADAPTIVE_KINDS = ("scipy", "numbalsoda", "diffrax")
"""The kinds of peers run by tolerance (the others by number of steps)."""


def compiled_peer(name) -> Peer | None:
    """The compiled peer called ``name`` (case-insensitive), or None."""
    return COMPILED_PEERS.get(name.strip().lower()) if isinstance(name, str) else None


def scipy_peer(solver: str) -> Peer:
    """scipy's solve_ivp method ``solver`` (its scipy name, e.g. DOP853) as a peer."""
    key = next((k for k, v in SCIPY_METHODS.items() if v == solver), None)
    if key is None:
        raise InputError(f"unknown scipy method {solver!r}; choose one of {', '.join(SCIPY_METHODS.values())}")
    return Peer(f"scipy:{key}", "scipy", solver, ("scipy",))


def absent(peer: Peer) -> str | None:
    """One line naming what ``peer`` lacks to run here (None when it can run)."""
    missing = [m for m in peer.modules if importlib.util.find_spec(m) is None]
    if not missing:
        return None
    build = "; numbalsoda builds with a Fortran compiler (Debian: gfortran)" if "numbalsoda" in missing else ""
    return f"{peer.name} is absent: {', '.join(missing)} not installed ({EXTRA}{build})"


class Solution(NamedTuple):
    """A peer's end state at T, whether it got there, its f evaluations (None where the solver
    does not count them), and its states at the sample times (:func:`sample_times`)."""

    state: np.ndarray
    ok: bool
    evaluations: int | None
    message: str
    states: np.ndarray


def sample_times(t_final: float, samples: int) -> np.ndarray:
    """The times a peer reports states at: ``samples`` + 1 equally spaced from 0 to T."""
    return np.linspace(0.0, float(t_final), samples + 1)


class Prepared(NamedTuple):
    """A peer ready to time: ``solve(x0, rtol) -> Solution`` to T, compiled and warmed up (its
    compile, trace or field generation time: ``compile_seconds``)."""

    peer: Peer
    solve: Callable[[np.ndarray, float], Solution]
    compile_seconds: float


_CODES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def cached_field_code(system, form: str):
    """The system's field in ``form`` (`rkhp.systems.field_code`), generated once per system."""
    codes = _CODES.setdefault(system, {})
    if form not in codes:
        codes[form] = generate(system, form)
    return codes[form]


def plain_field(system):
    """``f(t, x)``: the system's field written with plain arithmetic (form ``numpy``)."""
    return compiled(cached_field_code(system, "numpy"))


def _scipy(peer: Peer, system, t_final: float, samples: int):
    from scipy.integrate import solve_ivp

    f = plain_field(system)
    times = sample_times(t_final, samples) if samples > 1 else None

    def solve_scipy(x0, rtol):
        sol = solve_ivp(f, (0.0, t_final), x0, method=peer.solver, rtol=rtol, atol=ATOL_RATIO * rtol, t_eval=times)
        end = sol.y[:, -1]
        ok = bool(sol.success and np.all(np.isfinite(end)))
        return Solution(end, ok, int(sol.nfev), "ok" if ok else f"failed: {sol.message}", sol.y.T)

    return solve_scipy


def _numbalsoda(peer: Peer, system, t_final: float, samples: int):
    import numba
    from numbalsoda import dop853, lsoda_sig

    rhs = numba.cfunc(lsoda_sig)(compiled(cached_field_code(system, "cfunc")))
    address = rhs.address
    times = sample_times(t_final, samples)

    def solve_numbalsoda(x0, rtol):
        usol, ok = dop853(address, np.asarray(x0, dtype=np.float64), times, rtol=rtol, atol=ATOL_RATIO * rtol,
                          mxstep=MAX_STEPS)
        end = usol[-1].copy()
        ok = bool(ok and np.all(np.isfinite(end)))
        return Solution(end, ok, None, "ok" if ok else "failed: dop853 stopped before T", usol)

    solve_numbalsoda.keep = rhs  # the cfunc lives as long as the solve that calls it at its address
    return solve_numbalsoda


def enable_float64() -> None:
    """jax computes in float64 (its default is float32): set before any jax array is made."""
    import jax

    jax.config.update("jax_enable_x64", True)


def _diffrax(peer: Peer, system, t_final: float, samples: int):
    enable_float64()
    import diffrax
    import jax
    import jax.numpy as jnp

    term = diffrax.ODETerm(compiled(cached_field_code(system, "jax")))
    solver = getattr(diffrax, peer.solver)()
    saveat = diffrax.SaveAt(ts=sample_times(t_final, samples)) if samples > 1 else diffrax.SaveAt(t1=True)

    @jax.jit
    def diffeqsolve_jit(y0, rtol):
        sol = diffrax.diffeqsolve(term, solver, 0.0, float(t_final), None, y0,
                                  stepsize_controller=diffrax.PIDController(rtol=rtol, atol=ATOL_RATIO * rtol),
                                  saveat=saveat, max_steps=MAX_STEPS, throw=False)
        return sol.ys, sol.result == diffrax.RESULTS.successful

    def solve_diffrax(x0, rtol):
        states, ok = jax.block_until_ready(diffeqsolve_jit(jnp.asarray(x0, dtype=jnp.float64), jnp.float64(rtol)))
        states = np.asarray(states)
        ok = bool(ok) and bool(np.all(np.isfinite(states[-1])))
        return Solution(states[-1], ok, None, "ok" if ok else "failed: diffrax stopped before T", states)

    return solve_diffrax


_BUILDERS = {"scipy": _scipy, "numbalsoda": _numbalsoda, "diffrax": _diffrax}


def prepare(peer: Peer, system, t_final: float, x0=None, samples: int = 1) -> Prepared:
    """``peer`` on ``system`` to ``t_final`` (its solutions hold the states at ``samples`` + 1 times,
    :func:`sample_times`): its field generated and compiled, its solver compiled or traced, and one
    warm-up solve from ``x0`` (default the system's) at rtol 1e-6, all timed together as
    ``compile_seconds``. InputError (the line of :func:`absent`) when it cannot run."""
    reason = absent(peer)
    if reason:
        raise InputError(reason)
    started = time.perf_counter()
    solve = _BUILDERS[peer.kind](peer, system, float(t_final), samples)
    solve(np.asarray(system.x0 if x0 is None else x0, dtype=np.float64), 1e-6)
    return Prepared(peer, solve, time.perf_counter() - started)


#: the compiled DOP853 reference: a solve at REFERENCE_RTOL, its error estimated by the distance
#: to one at CHECK_RTOL (atol: ATOL_RATIO rtol)
REFERENCE_RTOL = 1e-15
CHECK_RTOL = 1e-14
EPS = float(np.finfo(float).eps)


def compiled_reference(system, t_final: float, x0=None):
    """x(T) by the compiled DOP853 (numbalsoda) at rtol REFERENCE_RTOL, its error estimated by the
    distance to a solve at CHECK_RTOL (at least 10 eps |x(T)|): a
    :class:`rkhp.studies.reference.Reference` of kind ``dop853-compiled``. NumericalFailure if a
    solve fails; InputError when numbalsoda is absent."""
    x0 = np.asarray(system.x0 if x0 is None else x0, dtype=np.float64)
    prepared = prepare(COMPILED_PEERS["numbalsoda:dop853"], system, t_final, x0)
    tight, loose = prepared.solve(x0, REFERENCE_RTOL), prepared.solve(x0, CHECK_RTOL)
    if not (tight.ok and loose.ok):
        raise NumericalFailure(f"reference solve (compiled DOP853, rtol {REFERENCE_RTOL:g}) failed on {system.name}")
    estimate = max(float(np.linalg.norm(tight.state - loose.state)), 10 * EPS * float(np.linalg.norm(tight.state)))
    detail = (f"numbalsoda DOP853 (compiled) at rtol {REFERENCE_RTOL:g}, atol {ATOL_RATIO * REFERENCE_RTOL:g}; "
              f"error estimated against a solve at rtol {CHECK_RTOL:g}")
    return Reference("dop853-compiled", float(t_final), tight.state, estimate, detail)


def best_reference(system, t_final: float, x0=None):
    """The most accurate reference rkhp has here: the closed form where the system has one from
    this start (`rkhp.studies.reference`), else the compiled DOP853 (:func:`compiled_reference`)
    when numbalsoda is installed and its estimate is the smaller, else scipy's DOP853."""
    ref = reference(system, t_final, x0)
    if ref.kind == "exact" or absent(COMPILED_PEERS["numbalsoda:dop853"]):
        return ref
    compiled = compiled_reference(system, t_final, x0)
    gap = float(np.linalg.norm(compiled.state - ref.state))
    if gap > 10 * (ref.error_estimate + compiled.error_estimate):
        raise NumericalFailure(f"the compiled DOP853 reference of {system.name} disagrees with scipy's by {gap:.3g} "
                               f"(estimates {compiled.error_estimate:.3g}, {ref.error_estimate:.3g})")
    return compiled if compiled.error_estimate < ref.error_estimate else ref
