"""The substep providers of the driver, and the table that says which one runs a system and a method
(docs/engine.md "One driver, many substeps").

An RKHP method runs as a composition of substeps gamma_1 h, ..., gamma_s h of one base method
(a tableau alone is the composition of one substep of size h; docs/theory.md §12). A substep
provider computes one such substep of its base method on a system; the driver
(`rkhp.integrators.driver`) runs the step loop over it. Providers:

- ``tower``: the Taylor tower of any tableau, explicit or implicit, on any system
  (`rkhp.integrators.tower_substep`, docs/theory.md §5, §7, §10);
- ``closed``: RKHP Euler in direct form on a family whose symmetric birealisation is in closed form
  (constant, lie-poisson, log-canonical; `rkhp.integrators.closed_euler`, docs/theory.md §12);
- ``spray``: RKHP Euler in direct form on the full Poisson-spray realisation of the general family
  (`rkhp.integrators.spray_euler`, docs/theory.md §9);
- ``thp``: the Taylor Hamiltonian Poisson integrator of order N on any system
  (`rkhp.integrators.taylor`, paper Thm 5.1, docs/theory.md §5): not a tableau, so in no row of
  the table; `rkhp.integrators.driver.integrate_taylor` names it.

`SUBSTEPS` is the table, keyed by the system's family and the kind of base method (`EULER`: the
RKHP Euler tableau, alone or as a composition's base; `TABLEAU`: any other); each row lists the
providers in order of preference, and the first that accepts the system runs (a direct form needs
the symmetric realisation and tapes it can evaluate). `choose` reads it; `rkhp integrate
--explain` prints its choice.

A provider is three compiled functions over its data (a NamedTuple of its own class, whose field
``y`` is the state the substeps advance: the driver records it and checks it): ``begin(data, y0)``
starts a run at y0 and returns a context, ``resume(data, y)`` sets the state to y and keeps what
each substep remembers of the steps before (the start of its iterations: the driver's inverse
processor runs from each kept state of a run), ``substep(data, context, i, hs, solver)`` takes
substep i of size hs from the state and returns (Failure, iterations, stage sweeps). The driver's
loop calls the stubs `begin`, `resume` and `substep` below, which numba resolves by the class of
the data (`_by_class`), so the loop is written once and compiled once per provider.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from ..systems import families
from ..taylor.compiler import NJIT_NORC, overload
from ..taylor.compiler import numba as nb
from . import closed_euler, spray_euler, taylor, tower_substep
from .direct_form import DIRECT_TOLERANCE

EULER, TABLEAU = "euler", "tableau"
"""The kinds of base method of the table: the RKHP Euler tableau (b = (1), A = (0)), any other."""


class Provider(NamedTuple):
    """A substep provider: its name; the class of its compiled data (what the driver's stubs
    dispatch on); whether it accepts a system (`accepts(system) -> bool`; the tower accepts every
    system); how it builds its data for a run (`prepare(system, tableau, substeps, **options) ->
    data`; the tower's option: ``stage_degree``, `tower_substep.tower_substep`; THP's tableau is
    its `taylor.ThpMethod`); what a run reports of it (`extra(data) -> dict`); its default
    tolerance (relative to max(1, |y|)); its compiled ``begin`` and ``resume``, and
    ``substep_for(data type)``, its compiled ``substep`` for data of that numba type (see the
    module)."""

    name: str
    data_class: type
    accepts: Callable
    prepare: Callable
    extra: Callable
    tolerance: float
    begin: object
    resume: object
    substep_for: Callable


def _tower_substep_for(data):
    """The tower's substep for data of numba type `data`: without the implicit tower when its
    stage solve is None (an explicit tableau)."""
    stage = dict(zip(data.fields, data.types))["stage"]
    return tower_substep.explicit_substep if stage == nb.types.none else tower_substep.implicit_substep


TOWER = Provider("tower", tower_substep.TowerSubstep, lambda system: True,
                 tower_substep.tower_substep,
                 tower_substep.tower_extra, tower_substep.TOLERANCE,
                 tower_substep.begin, tower_substep.resume, _tower_substep_for)
CLOSED = Provider("closed", closed_euler.ClosedSubstep, closed_euler.closed_form_available,
                  lambda system, tableau, s, **options: closed_euler.closed_substep_data(system, s),
                  closed_euler.closed_extra, DIRECT_TOLERANCE,
                  closed_euler.begin, closed_euler.resume, lambda data: closed_euler.substep)
SPRAY = Provider("spray", spray_euler.SpraySubstep, spray_euler.direct_form_available,
                 lambda system, tableau, s, **options: spray_euler.spray_substep_data(system, s),
                 spray_euler.spray_extra, DIRECT_TOLERANCE,
                 spray_euler.begin, spray_euler.resume, lambda data: spray_euler.substep)
THP = Provider("thp", taylor.ThpSubstep, lambda system: True,
              lambda system, method, s, **options: taylor.thp_substep(system, method, s),
              taylor.thp_extra, taylor.TOLERANCE, taylor.begin, taylor.resume, lambda data: taylor.substep)
PROVIDERS = {p.name: p for p in (TOWER, CLOSED, SPRAY, THP)}

SUBSTEPS: dict[tuple[str, str], tuple[Provider, ...]] = {
    (families.CONSTANT, EULER): (CLOSED, TOWER),
    (families.LIE_POISSON, EULER): (CLOSED, TOWER),
    (families.LOG_CANONICAL, EULER): (CLOSED, TOWER),
    (families.GENERAL, EULER): (SPRAY, TOWER),
}
"""Providers by (family, kind of base method), in order of preference; a key not listed runs on
the tower (`DEFAULT`)."""
DEFAULT = (TOWER,)


def base_kind(tableau) -> str:
    """`EULER` for the RKHP Euler tableau (one stage, a = 0, b = 1), else `TABLEAU`."""
    if tableau.stages == 1 and tableau.A_float[0][0] == 0.0 and tableau.b_float[0] == 1.0:
        return EULER
    return TABLEAU


class Choice(NamedTuple):
    """The provider that runs a system and base method, the table's key, and the providers of
    its row that refused the system (before it)."""

    provider: Provider
    key: tuple[str, str]
    refused: tuple[str, ...]


def choose(system, tableau) -> Choice:
    """The first provider of the row of `SUBSTEPS` for (the system's family, `base_kind(tableau)`)
    that accepts `system`: a direct form takes only the symmetric realisation; the tower, which
    ends every row, takes every system."""
    key = (system.family, base_kind(tableau))
    row = SUBSTEPS.get(key, DEFAULT)
    refused = []
    for provider in row[:-1]:
        if system.realisation == "symmetric" and provider.accepts(system):
            return Choice(provider, key, tuple(refused))
        refused.append(provider.name)
    return Choice(row[-1], key, tuple(refused))


class Explained(NamedTuple):
    """What runs a method's steps on a system (`rkhp integrate --explain`, docs/json.md): the
    table's key (family, kind of base method; None for a method that is not RKHP), the row's
    providers in order, those that refused the system, and the one that runs (``thp`` for THP,
    which is not a tableau and has no row; None: the method's own loop, a classical peer)."""

    system: str
    method: str
    key: tuple[str, str] | None
    row: tuple[str, ...]
    refused: tuple[str, ...]
    provider: str | None


def explain(system, method) -> Explained:
    """The provider `choose` picks for a resolved method (`rkhp.integrators.methods.Method`) on
    `system`, with the row of `SUBSTEPS` it read (THP: its provider, no row)."""
    if method.kind == "taylor":
        return Explained(system.name, method.name, None, (), (), THP.name)
    if method.kind not in ("rkhp", "composition"):
        return Explained(system.name, method.name, None, (), (), None)
    choice = choose(system, method.tableau)
    row = tuple(p.name for p in SUBSTEPS.get(choice.key, DEFAULT))
    return Explained(system.name, method.name, choice.key, row, choice.refused, choice.provider.name)


# ---------------------------------------------------------------------------------------------
# the stubs the driver's loop calls, resolved by the class of the provider's data


def _by_class(data) -> Provider:
    """The provider whose data is of numba type `data` (a NamedTuple type)."""
    for provider in PROVIDERS.values():
        if data.instance_class is provider.data_class:
            return provider
    raise TypeError(f"no substep provider has data of class {data.instance_class.__name__}")


def begin(data, y0):
    """Start a run at y0; returns the provider's context (compiled code only)."""
    raise NotImplementedError("compiled code only")


def resume(data, y):
    """Set the state to y, each substep's memory kept (compiled code only)."""
    raise NotImplementedError("compiled code only")


def substep(data, context, i, hs, solver):
    """Substep i of size hs; returns (Failure, iterations, stage sweeps) (compiled code only)."""
    raise NotImplementedError("compiled code only")


_OPTIONS = dict(_nrt=NJIT_NORC["_nrt"], error_model=NJIT_NORC["error_model"])


@overload(begin, inline="always", jit_options=_OPTIONS)
def _begin(data, y0):
    impl = _by_class(data).begin

    def begin_with(data, y0):
        return impl(data, y0)

    return begin_with


@overload(resume, inline="always", jit_options=_OPTIONS)
def _resume(data, y):
    impl = _by_class(data).resume

    def resume_with(data, y):
        impl(data, y)

    return resume_with


@overload(substep, inline="always", jit_options=_OPTIONS)
def _substep(data, context, i, hs, solver):
    impl = _by_class(data).substep_for(data)

    def substep_with(data, context, i, hs, solver):
        return impl(data, context, i, hs, solver)

    return substep_with
