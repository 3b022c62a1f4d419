"""Order verification of a tableau in every class of conditions (paper §5, Theorems 5.1–5.2).

A tableau has order p in a class when every condition of order <= p holds: in the general class
a(t) = 1/gamma(t) for all t in T, in the degenerate class for t in T_0, in the symmetric class
the combinations of :func:`rkhp.trees.conditions.conditions_of_order` (docs/theory.md §2, §8). Every condition
up to the order found plus one is checked (at most ``max_order``), from the elementary weights of
all trees of T computed in one pass (:mod:`rkhp.tableaux.weights`).

How each residual is decided (``Verification.tolerance_rule``):

- ``exact``: the residual is computed in Q or in an algebraic number field and compared with 0;
- ``float`` / D digits: |residual| <= tolerance = 10^4 u, with u = 2^-52 in float64 and
  u = 10^(1-D) at D digits (D at most the digits the entries are given with). The pass itself
  runs with 32 guard bits, so u is the rounding of the given coefficients.

The residual of a single-tree condition is a(t) - 1/gamma(t); of a combination
sum_k w_k r(t_k) = 0 (r = gamma a - 1) it is that sum divided by sum_k |w_k| gamma(t_k), which is
the same thing for one tree. The principal error of a class of order p is the 2-norm of the
residuals divided by sigma (of the condition's first tree) over the conditions of order p + 1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from ..base.bounds import BYTES_PER_TREE
from ..base.errors import InputError, NumericalFailure
from ..trees.conditions import CLASSES, OrderCondition, check_class, conditions_of_order
from ..trees.rooted import MAX_ENUMERATION_ORDER, Tree, check_order, check_tree_memory
from .files import load_tableau
from .tableau import Tableau
from .weights import (
    MAX_PRECISION_DIGITS,
    ExactArithmetic,
    NoNumberField,
    arithmetic_for,
    tree_plan,
    weights_by_order,
)

#: Tolerance factor on the rounding unit u (float64 or the given digits).
TOLERANCE_FACTOR = 1e4
#: Without --max-order, the check grows up to this order at most.
AUTO_MAX_ORDER = 16
#: Digits of the verification when the entries' number field is out of reach.
FIELD_FALLBACK_DIGITS = 50
#: Rational entries with a denominator at least this long are read as approximations too.
APPROXIMATION_DENOMINATOR = 10**7
#: bytes of one weight in exact or fixed-point arithmetic (measured: verify feagin14, 35 stages of
#: 60 digits, takes 570 MB up to order 15, about 110 bytes per tree and stage)
BYTES_PER_VALUE = 120


class FailingCondition(NamedTuple):
    """A failing condition: the tree (single-tree classes) or the OrderCondition, and its residual.

    The residual is a float; in exact precision ``Verification.failing_exact`` holds its exact
    value, in the same order.
    """

    item: Tree | OrderCondition
    residual: float

    @property
    def label(self) -> str:
        """The tree in bracket notation, or the combination ``r(t1) - r(t2)``."""
        if isinstance(self.item, Tree):
            return str(self.item)
        if self.item.is_single:
            return str(self.item.tree)
        return combination_label(self.item)


class OrderBound(NamedTuple):
    """An order as a document gives it: ``order`` n, and ``lower_bound`` true when the check ended
    at n, so that the order is only known to be at least n (the table's ``>= n``)."""

    order: int
    lower_bound: bool


class ClaimedOrders(NamedTuple):
    """The orders a tableau file claims, by the keys of the verified ones (None: no claim)."""

    order: int | None
    degenerate_order: int | None
    symmetric_order: int | None


class StageDifference(NamedTuple):
    """A stage (from 1) whose given c_i differs from the row sum of A, and by how much."""

    stage: int
    difference: float


class FailureList(Sequence):
    """The failures of one class, largest residual first; FailingCondition values built on access."""

    def __init__(self, items=(), residuals=()):
        self._items = items
        self._residuals = np.asarray(residuals, dtype=float)

    def __len__(self) -> int:
        return len(self._residuals)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        return FailingCondition(self._items[k], float(self._residuals[k]))

    def __repr__(self) -> str:
        return f"FailureList({len(self)} failures)"


@dataclass(frozen=True)
class Verification:
    """The verified orders of a tableau, with the evidence."""

    name: str
    stages: int
    kind: str
    orders: dict[str, int]
    checked_up_to: int
    precision: str
    tolerance: float
    tolerance_rule: str
    failing: dict[str, FailureList]
    principal_error: dict[str, float | None]
    principal_error_max: dict[str, float | None]
    claimed: dict[str, int | None]
    claims: dict[str, str]
    c_mismatch: tuple[tuple[int, float], ...] = field(default=())
    class_checked_up_to: dict[str, int] = field(default_factory=dict)
    failing_exact: dict[str, tuple[str, ...]] = field(default_factory=dict)
    conditions_checked: dict[str, int] = field(default_factory=dict)
    approximate: Verification | None = None

    #: docs/json.md "rkhp verify": the orders with their bounds, then the evidence
    json_keys = ("name", "stages", "kind", ("order", "general_bound"), ("degenerate_order", "degenerate_bound"),
                 ("symmetric_order", "symmetric_bound"), "checked_up_to", "precision", "tolerance", "principal_error",
                 ("failing", "failing_rows"), ("claimed", "claimed_orders"), "claim_ok", ("orders", "order_bounds"),
                 "claims", "tolerance_rule", "principal_error_max", "class_checked_up_to", "conditions_checked",
                 ("c_mismatch", "stage_differences"), ("approximate_orders", "approximate_bounds"),
                 "approximate_precision")

    @property
    def order(self) -> int | None:
        """General order (over T); None when that class was not checked."""
        return self.orders.get("general")

    @property
    def degenerate_order(self) -> int | None:
        """Degenerate order (over T_0); None when that class was not checked."""
        return self.orders.get("degenerate")

    @property
    def claim_ok(self) -> bool:
        """Whether every claimed order equals the verified one."""
        return all(v == "ok" for v in self.claims.values())

    @property
    def overstated(self) -> tuple[str, ...]:
        """The classes whose claimed order is above the verified one (a failed check)."""
        return tuple(cls for cls, status in self.claims.items() if status == "overstated")

    def is_lower_bound(self, cls: str) -> bool:
        """Whether the order in ``cls`` reached the end of the check (so is only a lower bound)."""
        return self.orders[cls] >= self.class_checked_up_to.get(cls, self.checked_up_to)

    def order_bound(self, cls: str) -> OrderBound | None:
        """The order in ``cls`` with whether it is only a lower bound; None if not checked."""
        if cls not in self.orders:
            return None
        return OrderBound(self.orders[cls], self.is_lower_bound(cls))

    @property
    def order_bounds(self) -> dict[str, OrderBound]:
        """:meth:`order_bound` of every class checked."""
        return {cls: self.order_bound(cls) for cls in self.orders}

    @property
    def general_bound(self) -> OrderBound | None:
        return self.order_bound("general")

    @property
    def degenerate_bound(self) -> OrderBound | None:
        return self.order_bound("degenerate")

    @property
    def symmetric_bound(self) -> OrderBound | None:
        return self.order_bound("symmetric")

    @property
    def approximate_orders(self) -> dict[str, int] | None:
        """The orders at the digits that rational approximations pin down (None unless the
        entries look like rational approximations whose exact residuals fall below them)."""
        return None if self.approximate is None else self.approximate.orders

    @property
    def approximate_bounds(self) -> dict[str, OrderBound] | None:
        """:attr:`approximate_orders` with their bounds."""
        return None if self.approximate is None else self.approximate.order_bounds

    @property
    def approximate_precision(self) -> str | None:
        return None if self.approximate is None else self.approximate.precision

    @property
    def claimed_orders(self) -> ClaimedOrders:
        return ClaimedOrders(self.claimed.get("general"), self.claimed.get("degenerate"),
                             self.claimed.get("symmetric"))

    @property
    def stage_differences(self) -> tuple[StageDifference, ...]:
        return tuple(StageDifference(i + 1, d) for i, d in self.c_mismatch)

    @property
    def failing_rows(self) -> dict[str, list[dict]]:
        """Per class, each failing condition's ``tree`` (or combination) and ``residual``, and in
        exact precision its ``exact`` value."""
        return {cls: self._failing_rows(cls) for cls in self.failing}

    def _failing_rows(self, cls: str) -> list[dict]:
        exact = self.failing_exact.get(cls)
        out = [{"tree": f.label, "residual": f.residual} for f in self.failing[cls]]
        if exact:
            for item, text in zip(out, exact, strict=True):
                item["exact"] = text
        return out




def combination_label(condition: OrderCondition) -> str:
    """``r(t1) - 2 r(t2) = 0`` style text of a combined condition, r(t) = gamma(t) a(t) - 1."""
    parts = []
    for k, (w, t) in enumerate(zip(condition.weights, condition.trees, strict=True)):
        sign = "-" if w < 0 else "+"
        mag = "" if abs(w) == 1 else f"{abs(w)} "
        head = ("-" if sign == "-" else "") if k == 0 else f" {sign} "
        parts.append(f"{head}{mag}r({t})")
    return "".join(parts)


# ----------------------------------------------------------------------------- precision


def default_precision(tableau: Tableau):
    """exact when every entry is exact, else the digits given when above 17, else float."""
    if tableau.is_exact:
        return "exact"
    if tableau.digits is not None and tableau.digits > 17:
        return tableau.digits
    return "float"


def parse_precision(text):
    """``float``, ``exact`` or a number of digits (as text or int); None stays None."""
    if text is None or isinstance(text, int):
        return text
    s = str(text).strip().lower()
    if s in ("float", "exact"):
        return s
    if s.isascii() and s.isdigit() and len(s) <= 9:
        return int(s)
    shown = text if len(str(text)) <= 40 else str(text)[:37] + "..."
    raise InputError(f"precision must be float, exact or a number of digits, got {shown!r}")


def _tolerance(arithmetic, tableau: Tableau) -> tuple[float, str]:
    if arithmetic.exact:
        K = arithmetic.field
        field_ = "Q" if K is None else f"Q({', '.join(map(str, K.orig_ext))})"
        return 0.0, f"exact: each residual computed in {field_} and compared with 0"
    if arithmetic.name == "float":
        return TOLERANCE_FACTOR * arithmetic.unit, \
            "|a(t) - 1/gamma(t)| <= 1e4 u, u = 2^-52 (float64)"
    digits = min(arithmetic.digits, tableau.digits or arithmetic.digits)
    unit = 10.0 ** (1 - digits)
    return TOLERANCE_FACTOR * unit, \
        f"|a(t) - 1/gamma(t)| <= 1e4 u, u = 10^(1-{digits}) ({digits} digits; fixed point " \
        f"with {arithmetic.bits} bits)"


# ----------------------------------------------------------------------------- classes


def available_classes() -> tuple[str, ...]:
    """The condition classes whose conditions can be built (symmetric needs rkhp.trees.relations)."""
    out = []
    for cls in CLASSES:
        try:
            conditions_of_order(1, cls)
        except ImportError:
            continue
        out.append(cls)
    return tuple(out)


def _single_tree_class(cls: str) -> bool:
    """general and degenerate: one condition a(t) = 1/gamma(t) per tree of T or T_0."""
    return cls in ("general", "degenerate")


@dataclass
class _ClassState:
    cls: str
    order: int | None = None  # set at the first failing order
    limit: int | None = None  # set when the class has no conditions beyond this order
    checked: int = 0  # conditions checked
    failing: FailureList = field(default_factory=FailureList)
    failing_exact: tuple = ()
    principal: float | None = None
    principal_max: float | None = None

    @property
    def done(self) -> bool:
        return self.order is not None or self.limit is not None


def _evaluate_class(state, n, blk, R, plan, arithmetic, tol):
    """Check the conditions of order n of one class; record the first failing order."""
    if _single_tree_class(state.cls):
        positions = np.arange(blk.stop - blk.start) if state.cls == "general" \
            else np.nonzero(plan.in_t0[blk])[0]
        conditions = _Indexed(plan.trees, positions + blk.start)
        R_sel = R[positions]
        denominators = plan.gamma_float[blk][positions]
        sig = plan.sigma_float[blk][positions]
    else:
        try:
            conditions = list(conditions_of_order(n, state.cls))
        except InputError:  # e.g. symmetric relations shipped only up to some order
            state.limit = n - 1
            return
        start = plan.starts[n]
        R_sel = [_combine(arithmetic, [R[plan.index(t) - start] for t in c.trees], c.weights)
                 for c in conditions]
        denominators = np.array([float(sum(abs(w) * t.gamma for w, t in
                                           zip(c.weights, c.trees, strict=True)))
                                 for c in conditions])
        sig = np.array([c.trees[0].sigma for c in conditions], dtype=float)
    state.checked += len(conditions)
    if not len(conditions):
        return
    residuals = arithmetic.to_floats(R_sel) / denominators
    if arithmetic.exact:
        bad = np.array([not arithmetic.is_zero(x) for x in R_sel])
    else:
        bad = ~(np.abs(residuals) <= tol)
    if not bad.any():
        return
    state.order = n - 1
    weighted = residuals / sig
    state.principal = float(np.linalg.norm(weighted))
    state.principal_max = float(np.abs(weighted).max())
    order = np.argsort(-np.abs(residuals[bad]), kind="stable")
    failing = np.nonzero(bad)[0][order]
    state.failing = FailureList(_Indexed(conditions, failing), residuals[failing])
    if arithmetic.exact:
        state.failing_exact = tuple(_exact_residual(arithmetic, R_sel[k], _exact_denominator(
            conditions[k])) for k in failing)


class _Indexed:
    """seq[indices[k]] for k = 0.. (a view that builds nothing)."""

    def __init__(self, seq, indices):
        self.seq = seq
        self.indices = indices

    def __len__(self):
        return len(self.indices)

    def __getitem__(self, k):
        return self.seq[self.indices[k]]


def _combine(arithmetic, values, weights):
    if arithmetic.exact:
        return sum((arithmetic.scale(x, w) for x, w in zip(values, weights, strict=True)),
                   arithmetic.scale(values[0], Fraction(0)))
    if arithmetic.name == "float":
        return sum(float(w) * x for x, w in zip(values, weights, strict=True))
    return sum((w * x for x, w in zip(values, weights, strict=True)), Fraction(0))


def _exact_denominator(item) -> Fraction:
    """gamma(t) for a tree; sum_k |w_k| gamma(t_k) for a condition (see the module docstring)."""
    if isinstance(item, Tree):
        return Fraction(item.gamma)
    return sum((abs(w) * t.gamma for w, t in zip(item.weights, item.trees, strict=True)),
               Fraction(0))


def _exact_residual(arithmetic: ExactArithmetic, R, denominator: Fraction) -> str:
    """The exact residual as text: ``-1/80`` or ``-1/20 - sqrt(3)/48``."""
    if arithmetic.field is None:
        return str(R / denominator)
    import sympy

    value = arithmetic.to_sympy(R) / sympy.Rational(denominator.numerator, denominator.denominator)
    return str(sympy.radsimp(sympy.expand(value)))


# ----------------------------------------------------------------------------- verify


def verify(tableau, max_order: int | None = None, precision=None, classes=None,
           on_order=None) -> Verification:
    """Verify the orders of a tableau (a Tableau, a built-in name or a file) in every class.

    ``precision``: "float", "exact", a number of digits, or None for :func:`default_precision`
    (exact when every entry is exact and their number field is within reach, else
    FIELD_FALLBACK_DIGITS digits). ``max_order``: check every condition up to this order; by
    default up to the order found plus one (at most AUTO_MAX_ORDER). ``on_order(n, N)`` is called
    after each order (progress). Rational entries with long denominators that miss an order by
    less than the digits they pin down get :attr:`Verification.approximate` (docs/verify.md).
    """
    tableau = load_tableau(tableau)
    precision = parse_precision(precision)
    note = ""
    if precision is None:
        precision = default_precision(tableau)
        try:
            arithmetic = arithmetic_for(tableau, precision)
        except NoNumberField as exc:
            precision = FIELD_FALLBACK_DIGITS
            note = f"no exact number field ({exc.reason}), so {FIELD_FALLBACK_DIGITS} digits: "
            arithmetic = arithmetic_for(tableau, precision)
    else:
        arithmetic = arithmetic_for(tableau, precision)
    result = _verify(tableau, max_order, arithmetic, classes, on_order, note)
    digits = approximation_digits(tableau) if arithmetic.exact else None
    if digits is not None and any(s < result.checked_up_to for s in result.orders.values()):
        approximate = _verify(tableau, max_order, arithmetic_for(tableau, digits), classes, None, "")
        if approximate.orders != result.orders:
            result = replace(result, approximate=approximate,
                             claims=_claims(tableau, approximate.orders, approximate.class_checked_up_to))
    return result


_CLASS_ORDERS: dict[tuple, dict[str, int]] = {}


def class_orders(tableau, precision=None) -> dict[str, int]:
    """Order per condition class ("general", "degenerate", "symmetric") of a tableau, by
    :func:`verify` at ``precision`` (cached by the tableau, which compares by value, and
    precision): what `rkhp converge` expects of an RKHP method (default precision) and what the
    implicit stage solve is accurate to ("float": docs/implicit.md).

    Each class's conditions follow from the previous class's (T_0 is part of T; the symmetric
    conditions combine T_0 residuals), so its order is at least theirs: this matters where a
    class is checked to a lower order (the symmetric relations ship up to order 8).
    """
    tableau = load_tableau(tableau)
    key = (tableau, precision)
    if key not in _CLASS_ORDERS:
        orders = verify(tableau, precision=precision, classes=("general", "degenerate", "symmetric")).orders
        general = int(orders["general"])
        degenerate = max(general, int(orders["degenerate"]))
        _CLASS_ORDERS[key] = {"general": general, "degenerate": degenerate,
                              "symmetric": max(degenerate, int(orders["symmetric"]))}
    return _CLASS_ORDERS[key]


def approximation_digits(tableau: Tableau) -> int | None:
    """Digits that long rational entries pin down, or None when the entries are not all rational
    or none has a long denominator (at least APPROXIMATION_DENOMINATOR).

    A rational p/q read as an approximation of a real number fixes it to about 1/q^2 (a best
    approximation is within 1/q^2) or, for a decimal (q divides a power of 10), to 1/q; the
    shortest long denominator decides: 2 log10 q or log10 q digits (at least 16, at most
    MAX_PRECISION_DIGITS: a longer denominator is checked to that many).
    """
    if not tableau.is_rational:
        return None
    digits = []
    for x in tableau.entries():
        q = x.denominator
        if q >= APPROXIMATION_DENOMINATOR:
            decimal = 10 ** len(str(q)) % q == 0
            digits.append(int(math.log10(q) * (1 if decimal else 2)))
    return min(max(16, min(digits)), MAX_PRECISION_DIGITS) if digits else None


def _verify(tableau, max_order, arithmetic, classes, on_order, note: str) -> Verification:
    tolerance, rule = _tolerance(arithmetic, tableau)
    classes = tuple(check_class(c) for c in classes) if classes else available_classes()
    if max_order is not None:
        check_order(max_order, MAX_ENUMERATION_ORDER, "max order")
        states, N = _run(tableau, max_order, arithmetic, tolerance, classes, on_order)
    else:
        claimed = [x for x in tableau.claims.values() if x]
        N = min(max(claimed, default=5) + 1, AUTO_MAX_ORDER)
        while True:
            states, checked = _run(tableau, N, arithmetic, tolerance, classes, on_order)
            if all(s.done for s in states.values()) or N >= AUTO_MAX_ORDER:
                N = checked
                break
            N = min(N + 2, AUTO_MAX_ORDER)
    orders = {cls: _found(s, N) for cls, s in states.items()}
    class_checked = {cls: _checked(s, N) for cls, s in states.items()}
    return Verification(
        name=tableau.name, stages=tableau.stages, kind=tableau.kind, orders=orders,
        checked_up_to=N, precision=arithmetic.name, tolerance=tolerance, tolerance_rule=note + rule,
        failing={cls: s.failing for cls, s in states.items()},
        principal_error={cls: s.principal for cls, s in states.items()},
        principal_error_max={cls: s.principal_max for cls, s in states.items()},
        claimed=tableau.claims, claims=_claims(tableau, orders, class_checked),
        c_mismatch=tuple(tableau.c_mismatch()), class_checked_up_to=class_checked,
        failing_exact={cls: s.failing_exact for cls, s in states.items() if s.failing_exact},
        conditions_checked={cls: s.checked for cls, s in states.items()})


def _claims(tableau: Tableau, orders, class_checked) -> dict[str, str]:
    claimed = tableau.claims
    return {cls: _claim_status(claimed[cls], orders[cls], class_checked[cls])
            for cls in claimed if claimed[cls] is not None and cls in orders}


def _checked(state: _ClassState, N: int) -> int:
    """The last order whose conditions were checked in the class."""
    if state.order is not None:
        return state.order + 1
    return state.limit if state.limit is not None else N


def _found(state: _ClassState, N: int) -> int:
    if state.order is not None:
        return state.order
    return state.limit if state.limit is not None else N


def _claim_status(claimed: int, found: int, checked: int) -> str:
    if found >= checked and claimed > found:
        return f"not verified (checked up to order {checked})"
    if claimed > found:
        return "overstated"
    if claimed < found:
        return "understated"
    return "ok"


def _run(tableau, N, arithmetic, tolerance, classes, on_order):
    """Check every class order by order up to N; stop once each class has failed.

    Returns the class states and the last order checked.
    """
    value_bytes = 8 if arithmetic.name == "float" else BYTES_PER_VALUE
    check_tree_memory(N, False, f"verifying {tableau.name} to order {N}",
                      per_tree=BYTES_PER_TREE + tableau.stages * value_bytes)
    plan = tree_plan(N)
    states = {cls: _ClassState(cls) for cls in classes}
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow of float weights is refused below
        for n, blk, a in weights_by_order(tableau, N, arithmetic):
            R = arithmetic.residuals(a, plan.gamma_float[blk] if arithmetic.name == "float"
                                     else plan.gamma[blk])
            if arithmetic.name == "float" and not np.all(np.isfinite(R)):
                raise NumericalFailure(f"{tableau.name}: the weights of order {n} overflow float arithmetic "
                                       "(entries too large for float64): verify with --precision exact")
            for state in states.values():
                if state.done is False:
                    _evaluate_class(state, n, blk, R, plan, arithmetic, tolerance)
            if on_order is not None:
                on_order(n, N)
            if all(s.done for s in states.values()):
                break
    return states, n
