"""One grammar of method names, for every command and for the Python API (docs/methods.md).

A method is named by a string (or given as a :class:`Method` or a
:class:`~rkhp.tableaux.tableau.Tableau`):

- ``NAME`` or ``FILE``: a tableau (built-in name or alias, or a .toml/.json/.txt tableau file)
  used as an RKHP method (paper §5.2, docs/theory.md §5), e.g. ``rk4`` is RK4 used as an RKHP
  tableau; explicit or implicit (whether the engine integrates an implicit one is the engine's
  business, not the resolver's);
- ``thpN`` / ``thpN-t0``: the Taylor Hamiltonian Poisson integrator of order N over T / over
  T_0 (paper Thm 5.1; :mod:`rkhp.integrators.taylor`);
- ``classical:NAME`` or ``classical:FILE``: that tableau as a classical Runge–Kutta method on
  ``xdot = pi(x) grad H(x)``;
- ``implicit-midpoint``: the implicit midpoint rule (Newton per step);
- ``scipy:NAME``: scipy's adaptive ``solve_ivp`` method NAME (dop853, rk45, rk23, radau, bdf,
  lsoda), run by tolerance: a peer of ``rkhp bench`` only;
- a composition (built-in name such as ``kahan-li8``, or a composition file): substeps
  gamma_1 h, ..., gamma_s h of an RKHP base method (:mod:`rkhp.tableaux.compositions`,
  docs/compositions.md).

The expected order comes from the verify engine: for RKHP, the symmetric order (the reduced
conditions of docs/theory.md §8) on a symmetric realisation, the degenerate order (over T_0) on
a degenerate one and the general order (over T) otherwise (paper, Theorems 4.4 and 5.1); for THP
the same classes applied to its B-series (:func:`taylor_orders`); for a classical method its
order over T; 2 for the midpoint rule; for a composition, the order its coefficients give with
the base's order in the class, the base counted symmetric when the class is symmetric and the base
RKHP method is (:func:`rkhp.tableaux.symmetry.rkhp_symmetry`).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import NamedTuple

from ..base.documents import read_text
from ..base.errors import InputError, NumericalFailure
from ..trees.conditions import conditions_of_order

DEFAULT_METHODS = ("euler", "paper-two-stage", "paper-three-stage", "rk4")
"""The methods `converge` and `stress` compare when they are given none: the paper's."""
BENCH_METHODS = ("paper-three-stage", "kahan-li6", "kahan-li8", "sofroniou-spaletta10")
"""The methods `bench` races when it is given none: the paper's three-stage method and the
compositions of RKHP Euler that the work-precision runs find cheapest (docs/methods.md), less
those whose estimated cost on the system is too large (`rkhp.studies.bench`)."""
DEFAULT_METHOD = "kahan-li8"
"""The method `rkhp integrate` runs when it is given none: Kahan & Li's composition of 17 RKHP
Euler substeps, of order 8 on symmetric birealisations (docs/compositions.md), whose cost grows
linearly with the dimension (docs/methods.md "The default method")."""
COST_NOTICE_SECONDS = 1.0
"""A run whose estimated cost (`Method.cost`) exceeds this many CPU seconds is announced first."""
CLASSICAL_PREFIX = "classical:"
SCIPY_PREFIX = "scipy:"
MIDPOINT = "implicit-midpoint"
SCIPY_METHODS = {"dop853": "DOP853", "rk45": "RK45", "rk23": "RK23", "radau": "Radau", "bdf": "BDF",
                 "lsoda": "LSODA"}
_TAYLOR = re.compile(r"thp([0-9]+)(-t0)?")
KINDS = ("rkhp", "taylor", "classical", "implicit-midpoint", "scipy", "composition")


class DriverPlan(NamedTuple):
    """How an RKHP method or a composition runs: the driver's entry (`rkhp.integrators.driver.
    run_checked`, imported once, not at every call) and what the method passes it besides the
    system and the step: its substeps' coefficients, the processor's length and what the
    trajectory reports of the method (a composition's base and substeps)."""

    run: Callable
    gammas: object
    processor: int
    extra: dict | None


@dataclass(frozen=True)
class Method:
    """A named method.

    Attributes:
        name: the name as given (or the tableau's name).
        kind: one of :data:`KINDS`.
        tableau: a :class:`rkhp.tableaux.tableau.Tableau` (rkhp and classical kinds), else None.
        order: the THP order N (taylor kind), else None.
        degenerate: THP over T_0 (``thpN-t0``).
        solver: scipy's name of the method (scipy kind), else None.
        composition: the :class:`~rkhp.tableaux.compositions.Composition` (composition kind; its
            base tableau is `tableau`), else None.
    """

    name: str
    kind: str
    tableau: object = None
    order: int | None = None
    degenerate: bool = False
    solver: str | None = None
    composition: object = None

    def integrate(self, system, h: float, n_steps: int, x0=None, *, keep_all: bool = True):
        """Run the method; returns a :class:`~rkhp.integrators.trajectory.Trajectory`. RKHP methods
        and compositions run on the driver (`rkhp.integrators.driver`), by the substep provider
        that `rkhp.integrators.substeps.choose` picks for the system and the base method, THP by
        its provider ``thp``; with ``keep_all=False`` they keep the first and the last state only
        (a processed composition then applies its inverse processor once, to the last state:
        docs/compositions.md). The other kinds keep every state."""
        if self.kind in ("rkhp", "composition"):
            plan = self._on_driver
            return plan.run(system, self.tableau, h, n_steps, x0, plan.gammas, 1.0, processor=plan.processor,
                            keep_all=keep_all, name=self.name, extra=plan.extra)
        if self.kind == "taylor":
            from .driver import integrate_taylor

            return integrate_taylor(system, self.order, self.degenerate, h, n_steps, x0, keep_all=keep_all)
        if self.kind == "classical":
            from .classical import integrate_classical

            return integrate_classical(system, self.tableau, h, n_steps, x0)
        if self.kind == "implicit-midpoint":
            from .classical import integrate_midpoint

            return integrate_midpoint(system, h, n_steps, x0)
        raise InputError(f"{self.name} is scipy's adaptive {self.solver}: it runs by tolerance, not "
                         "by steps (a peer of `rkhp bench`, --peers)")

    def integrate_ensemble(self, system, h, n_steps, x0s, *, threads: int | None = None,
                           executor=None):
        """Final states (m, n) of the runs of :meth:`integrate` from the starts ``x0s`` (m, n),
        h and n_steps one value or one per start. RKHP methods, compositions and THP run them at once
        (`rkhp.integrators.driver.run_ensemble`: threads over the compiled loop, or chunks on an
        ``executor``), bit for bit the final states of one run at a time; other methods run one
        after another. NumericalFailure naming the first failing run if any fails."""
        if self.kind == "taylor":
            from .driver import run_ensemble
            from .substeps import THP
            from .taylor import thp_method

            return run_ensemble(system, thp_method(self.order, self.degenerate), h, n_steps, x0s, provider=THP,
                                threads=threads, executor=executor)
        if self.kind in ("rkhp", "composition"):
            from .driver import run_ensemble

            if self.kind == "rkhp":
                return run_ensemble(system, self.tableau, h, n_steps, x0s, threads=threads, executor=executor)
            return run_ensemble(system, self.tableau, h, n_steps, x0s, gammas=self._gammas,
                                processor=len(self.composition.processor), threads=threads, executor=executor)
        import numpy as np

        from .driver import ensemble_plan

        x0s, hs, counts = ensemble_plan(system, h, n_steps, x0s)
        return np.array([self.integrate(system, float(hh), int(nn), x0=x).raise_if_failed().final_state
                         for x, hh, nn in zip(x0s, hs, counts, strict=True)]).reshape(x0s.shape)

    @cached_property
    def _on_driver(self) -> DriverPlan:
        """How an RKHP method or a composition runs on the driver (resolved once per method)."""
        from .driver import ONE, run_checked

        if self.kind == "rkhp":
            return DriverPlan(run_checked, ONE, 0, None)
        comp = self.composition
        extra = {"base": self.tableau.name, "substeps": comp.substeps}
        if comp.processed:
            extra["processor_substeps"] = len(comp.processor)
        return DriverPlan(run_checked, self._gammas, len(comp.processor), extra)

    @cached_property
    def _gammas(self):
        """A composition's substeps of one step as a float64 array (its processor's, its kernel's
        and its inverse processor's: `rkhp.tableaux.compositions.one_step`), once its base is
        known to be explicit."""
        from ..tableaux.compositions import one_step
        from .driver import check_gammas
        from .tower_substep import check_composable

        check_composable(self.tableau, self.name)
        return check_gammas(one_step(self.composition, float))

    def cost(self, system):
        """The estimated cost of the method's steps on `system` when the Taylor tower runs them
        (`rkhp.integrators.tower_substep.tower_cost`: jets of degree s + 1 in n variables, whose
        size grows like n^(s + 1)), else None (a direct form, whose cost grows like n to n^3, a
        classical peer, THP, or a method that runs by tolerance)."""
        if self.kind not in ("rkhp", "composition"):
            return None
        from .substeps import TOWER, choose
        from .tower_substep import tower_cost

        if choose(system, self.tableau).provider is not TOWER:
            return None
        substeps = 1 if self.kind == "rkhp" else self.composition.substeps
        return tower_cost(system, self.tableau, substeps)

    def rkhp_tableau(self, what: str):
        """The tableau of an RKHP method; InputError naming ``what`` needs one for other kinds."""
        if self.kind != "rkhp":
            raise InputError(f"{what} needs an RKHP method (a tableau name or file, docs/methods.md); "
                             f"{self.name} is a {self.kind} method")
        return self.tableau

    def expected_order(self, condition_class: str) -> int:
        """Order expected on a realisation of `condition_class` (see :func:`condition_class`)."""
        if self.kind == "implicit-midpoint":
            return 2
        if self.kind == "taylor":
            return taylor_orders(self.order, self.degenerate)[condition_class]
        if self.kind == "scipy":
            raise InputError(f"{self.name} is adaptive: it has no order in h")
        return self.orders_by_class[condition_class if self.kind != "classical" else "general"]

    @cached_property
    def orders_by_class(self) -> dict[str, int]:
        """The order of an RKHP, classical or composition method on each realisation class, computed
        once per method: its tableau's (:func:`rkhp.tableaux.verification.class_orders`) or, for a
        composition, with its base's order and symmetry in the class
        (:func:`rkhp.tableaux.compositions.class_composition_orders`)."""
        from ..tableaux.verification import class_orders

        if self.kind == "composition":
            from ..tableaux.compositions import class_composition_orders

            return {cls: o.order for cls, o in class_composition_orders(self.composition, self.tableau).items()}
        return class_orders(self.tableau)

    def realisation_bound(self, system) -> int | None:
        """The order the system's realisation allows a method that runs through it (RKHP and THP;
        ``truncated:K``: docs/theory.md §9), or None when it sets no bound."""
        return system.realisation_order if self.kind in ("rkhp", "taylor", "composition") else None

    def expected_order_on(self, system) -> int:
        """Order expected on `system`: the class's order, bounded by :meth:`realisation_bound`."""
        order = self.expected_order(condition_class(system))
        bound = self.realisation_bound(system)
        return order if bound is None else min(order, bound)


def condition_class(system) -> str:
    """The class of order conditions an RKHP method meets on `system`'s realisation: "symmetric"
    (beta(x, p) = alpha(x, -p), docs/theory.md §8), "degenerate" (paper, eq. (degen)) or
    "general"."""
    if system.symmetric:
        return "symmetric"
    return "degenerate" if system.degenerate else "general"


def taylor_orders(order: int, degenerate: bool) -> dict[str, int]:
    """Order per condition class of the THP of order N over T (or T_0 when ``degenerate``).

    Its B-series is exact up to order N on the trees it sums: r(t) = gamma(t) a(t) - 1 is 0 for
    those and -1 for every other tree. A class's order is the last order n whose conditions
    sum_k w_k r(t_k) = 0 all hold; over T_0 the general class fails at b[b] (order 1), and in the
    symmetric class a combination whose weights sum to 0 holds for r = -1 too (so that odd N
    gains an order: docs/methods.md).
    """
    def r(t) -> int:
        return 0 if t.order <= order and (not degenerate or t.in_t0) else -1

    out = {}
    for cls in ("general", "degenerate", "symmetric"):
        n = 0
        while n < order + 4:
            try:
                conditions = conditions_of_order(n + 1, cls)
            except InputError:  # the symmetric relations ship up to some order
                break
            if any(sum(w * r(t) for w, t in zip(c.weights, c.trees, strict=True)) for c in conditions):
                break
            n += 1
        out[cls] = n
    return out


METHODS_KEPT = 64
"""How many methods resolved from names a process keeps (`resolve_method`)."""


def resolve_method(spec) -> Method:
    """The method a name stands for (a Method or a Tableau is taken as it is).

    A name is resolved once: the same name, and for a name that reads a file (a tableau or a
    composition file) the same text of that file, give back the same Method (the METHODS_KEPT
    most recently used are kept); the file is read again on every call, so an edited file is
    resolved again. A built-in composition's name reads no file: it stands for the composition
    whatever files exist. InputError for an empty or unknown name, or a malformed THP or scipy
    name.
    """
    if isinstance(spec, Method):
        return spec
    if not isinstance(spec, str):
        from ..tableaux.tableau import Tableau

        if isinstance(spec, Tableau):
            return Method(spec.name, "rkhp", spec)
        raise InputError(f"a method is a name, a Tableau or a Method, got {type(spec).__name__}")
    spec = spec.strip()
    if not spec:
        raise InputError("empty method name")
    if _names_builtin_composition(spec):
        return _resolved(spec, None)
    text = _file_text(spec[len(CLASSICAL_PREFIX):] if spec.startswith(CLASSICAL_PREFIX) else spec)
    return _resolve_name(spec) if text is _UNREADABLE else _resolved(spec, text)


_UNREADABLE = object()


@lru_cache(maxsize=METHODS_KEPT)
def _names_builtin_composition(spec: str) -> bool:
    """`rkhp.tableaux.compositions.is_builtin_composition`, kept by the name (a call imports
    nothing and reads no file)."""
    from ..tableaux.compositions import is_builtin_composition

    return is_builtin_composition(spec)


def _file_text(name: str):
    """The text of the file `name` reads when it names a file (None when it names none;
    _UNREADABLE when the file cannot be read: the resolver then says why)."""
    try:
        if not os.path.isfile(name):
            return None
        return read_text(name, "method file")
    except (OSError, ValueError, InputError):
        return _UNREADABLE


@lru_cache(maxsize=METHODS_KEPT)
def _resolved(spec: str, text: str | None) -> Method:
    """`_resolve_name(spec)`, kept by the name and the text of the file it reads (the key holds
    the text itself: its hash finds the entry, an equal text confirms it)."""
    return _resolve_name(spec)


def _resolve_name(spec: str) -> Method:
    """The method a stripped, non-empty name stands for (the grammar of the module)."""
    from ..tableaux.files import load_tableau

    if spec == MIDPOINT:
        return Method(spec, "implicit-midpoint")
    taylor = _TAYLOR.fullmatch(spec)
    if taylor:
        order = int(taylor[1]) if len(taylor[1]) <= 6 else 0  # never parse a huge number
        if not 1 <= order <= 8:
            raise InputError(f"method {spec}: the THP order N must be from 1 to 8")
        return Method(spec, "taylor", order=order, degenerate=bool(taylor[2]))
    if spec.startswith(SCIPY_PREFIX):
        key = spec[len(SCIPY_PREFIX):].lower()
        if key not in SCIPY_METHODS:
            raise InputError(f"method {spec}: unknown scipy method (known: "
                             f"{', '.join(SCIPY_PREFIX + k for k in SCIPY_METHODS)})")
        return Method(spec, "scipy", solver=SCIPY_METHODS[key])
    if spec.startswith(CLASSICAL_PREFIX):
        return Method(spec, "classical", load_tableau(spec[len(CLASSICAL_PREFIX):]))
    from ..tableaux.compositions import is_composition_name, load_composition

    if is_composition_name(spec):
        composition = load_composition(spec)
        return Method(spec, "composition", load_tableau(composition.base), composition=composition)
    return Method(spec, "rkhp", load_tableau(spec))


def resolve_methods(specs) -> tuple[Method, ...]:
    """Resolve several names (the default methods when none are given); duplicates are refused."""
    specs = tuple(specs) or DEFAULT_METHODS
    names = [s if isinstance(s, str) else getattr(s, "name", s) for s in specs]
    if len(set(names)) != len(names):
        raise InputError(f"a method is named twice in {', '.join(map(str, names))}")
    return check_distinct([resolve_method(s) for s in specs])


def check_distinct(methods) -> tuple[Method, ...]:
    """The methods, if no two are the same method under two names (an alias, a file: ``rk4`` and
    ``classical``); InputError naming both otherwise (docs/input.md)."""
    keys = [(m.kind, getattr(m.tableau, "name", None), m.order, m.degenerate, m.solver,
             getattr(m.composition, "gamma", None), getattr(m.composition, "processor", None)) for m in methods]
    for i, key in enumerate(keys):
        if key in keys[:i]:
            raise InputError(f"{methods[keys.index(key)].name} and {methods[i].name} are the same method")
    return tuple(methods)


def require_steps(methods) -> tuple[Method, ...]:
    """The methods, if each runs by steps (InputError for a scipy method, which runs by tolerance)."""
    for m in methods:
        if m.kind == "scipy":
            raise InputError(f"{m.name} runs by tolerance, not by steps: it is a peer of `rkhp bench` "
                             "(--peers); converge and stress need methods of fixed step")
    return tuple(methods)


@lru_cache(maxsize=1)
def _systems():
    """The package `rkhp.systems`, imported on first use (about 0.1 s, which commands that run no
    system never pay); later calls import nothing."""
    from .. import systems

    return systems


def resolve_system(system, realisation: str = "symmetric", x0=None):
    """A :class:`~rkhp.systems.PoissonSystem` from a built-in name, a spec file or a system
    object (kept with its own realisation), started at ``x0`` when given."""
    systems = _systems()
    if not isinstance(system, systems.PoissonSystem):
        system = systems.get_system(system, realisation)
    if x0 is None:
        return system
    from ..systems.spec import check_start

    started = system.with_x0(x0)
    check_start(started, "x0")
    return started


def integrate(system, method, h, n_steps, x0=None, *, realisation: str = "symmetric",
              allow_failure: bool = False, keep_all: bool = True):
    """Integrate ``system`` (a name, a spec file or a PoissonSystem) with ``method`` (any name of
    the grammar above, a Tableau or a Method): ``n_steps`` steps of size ``h`` from ``x0`` (default:
    the system's start). Returns a :class:`~rkhp.integrators.trajectory.Trajectory`.

    A run that fails (Newton did not converge, the state left the system's domain or diverged:
    docs/exit-status.md) raises :class:`~rkhp.base.errors.NumericalFailure` naming the step, as
    `rkhp integrate` exits with status 1; the failed trajectory is the exception's
    ``trajectory``. With ``allow_failure=True`` it is returned instead: ``ok`` False, ``cause``,
    ``failed_step``, and the states before the failure. With ``keep_all=False`` an RKHP method or
    a composition keeps the first and the last state only (:meth:`Method.integrate`).

    ``rkhp.integrate("rigid-body", "rk4", 0.1, 100)`` integrates the rigid body (symmetric
    realisation) with RK4 used as an RKHP method.
    """
    chosen, resolved = resolve_method(method), resolve_system(system, realisation)
    trajectory = chosen.integrate(resolved, h, n_steps, x0, keep_all=keep_all)
    if not trajectory.ok and not allow_failure:
        raise NumericalFailure(f"{resolved.name}, {chosen.name}, h = {h:g}: {trajectory.status}",
                               trajectory=trajectory)
    return trajectory
