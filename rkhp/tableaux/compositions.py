"""Compositions of a one-step base method: Phi_h = Phi_{gamma_s h} o ... o Phi_{gamma_1 h}
(docs/compositions.md, docs/theory.md §12; Hairer–Lubich–Wanner, Geometric Numerical Integration,
§II.4, §III.3, §V.3).

A composition is named by its base method (an RKHP tableau, RKHP Euler by default) and its
substep coefficients gamma. Its order follows from the base's modified vector field: a base of
order q has Phi_h = exp(h F_1 + h^(q+1) F_(q+1) + h^(q+2) F_(q+2) + ...), and a symmetric base
(Phi_{-h} = Phi_h^{-1}) has odd powers of h only. Then

    Phi_{gamma_s h} o ... o Phi_{gamma_1 h} = prod_i exp(sum_k gamma_i^k h^k F_k),

and the composition has order p when this product equals exp(h F_1) up to h^p in the free
associative algebra over the letters F_k (weight k): the conditions of the free Lie algebra
(HLW §III.3), written word by word (:func:`composition_order`). The coefficient of a word
u = F_(k_1) ... F_(k_m) of exp(Y), Y = sum_k g^k F_k, is g^|u| / m!, so the product is built
substep by substep over the words of weight <= p.

Built-in compositions ship as ``tables/compositions/*.toml``; user files have the same keys:

    name = "yoshida6"                    # optional (default: the file name)
    kind = "composition"                 # marks a composition file (a file without `kind`
                                         # that has `gamma` and no `A` is one too)
    base = "euler"                       # optional: an RKHP method (tableau name or file)
    gamma = ["0.784513610477557263819", ...]   # numbers or exact expressions (safe reader)
    reference = "..."                    # optional
    order = 6                            # optional: the claimed order with the base on a symmetric
                                         # realisation (Euler's: symmetric, order 2)
    aliases = [...]                      # optional
    processor = ["...", ...]             # optional: a processed composition (below)

A processed composition (Blanes, Casas & Ros 1999; Blanes, Casas & Murua 2006; docs/theory.md
§12) is P^-1 o K^n o P: its kernel K is the composition gamma, its processor P the substeps
c_1 |h|, ..., c_m |h| (coefficients summing to 0), applied once before the first step, and P^-1
(the substeps -c_m |h|, ..., -c_1 |h|: the base is symmetric) once at each output. Its order is
its effective order: that of the substeps of one processed step, P, K, P^-1, as a composition
(:func:`one_step`); the kernel alone has a lower order.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property, lru_cache
from importlib.resources import files
from pathlib import Path

import mpmath

from ..base.bounds import MAX_CLAIMED_ORDER, MAX_STAGES, float_or_infinity
from ..base.documents import is_file, parse_document, read_text
from ..base.errors import InputError
from .files import load_tableau
from .tableau import GivenDecimal, entry_text, is_exact, parse_entry, to_float

KIND = "composition"
#: Most substeps of a composition, as many as a tableau's stages (a file of more is refused before
#: its coefficients are read).
MAX_SUBSTEPS = MAX_STAGES
#: Highest order :func:`composition_order` looks at (376 words of weight <= 12 with a symmetric
#: base of order 2: the order-10 compositions are checked one order past theirs).
MAX_COMPOSITION_ORDER = 12
#: Decimal digits of the evaluation of the conditions when every coefficient is exact.
EXACT_DIGITS = 60
_KEYS = ("name", "kind", "base", "gamma", "reference", "order", "aliases", "notes", "processor")
DEFAULT_BASE = "euler"


@dataclass(frozen=True)
class Composition:
    """A composition of a base method with substeps gamma_1 h, ..., gamma_s h (applied in that
    order).

    Attributes:
        name: the composition's name.
        base: the name (or file) of the base RKHP method.
        gamma: the coefficients as read (Fraction, sympy number or GivenDecimal).
        reference: where the coefficients come from.
        claimed_order: the order claimed by the file (with the base on a symmetric realisation), or None.
        aliases: other names.
        processor: the processor's coefficients c_1 .. c_m (empty: not processed; module
            docstring).
    """

    name: str
    base: str
    gamma: tuple
    reference: str = ""
    claimed_order: int | None = None
    aliases: tuple[str, ...] = ()
    notes: str = field(default="", compare=False)
    processor: tuple = ()

    @cached_property
    def gamma_float(self) -> tuple[float, ...]:
        """The coefficients in float64."""
        return tuple(to_float(g) for g in self.gamma)

    @cached_property
    def processor_float(self) -> tuple[float, ...]:
        """The processor's coefficients in float64 (empty when not processed)."""
        return tuple(to_float(c) for c in self.processor)

    @property
    def processed(self) -> bool:
        return bool(self.processor)

    @property
    def substeps(self) -> int:
        return len(self.gamma)

    @cached_property
    def digits(self) -> int | None:
        """Decimal digits the coefficients are known to (None: all exact)."""
        given = [g.digits for g in (*self.gamma, *self.processor) if isinstance(g, GivenDecimal)]
        return min(given) if given else None

    @cached_property
    def consistent(self) -> bool:
        """Whether the coefficients sum to 1 (to the digits given)."""
        return abs(_residual_sum(self.gamma, self.digits)) <= _residual_tolerance(self.digits)

    @cached_property
    def processor_sum(self):
        """The sum of the processor's coefficients (0 for a processor; 0 when not processed)."""
        return _residual_sum(self.processor, self.digits, 0) if self.processor else 0

    @cached_property
    def symmetric(self) -> bool:
        """Whether gamma reads the same backwards (to the digits given): with a symmetric base the
        composition is then symmetric (HLW §V.3.1)."""
        tol = _residual_tolerance(self.digits)
        with mpmath.workdps(_dps(self.digits)):
            values = [_mp(g) for g in self.gamma]
            return all(abs(a - b) <= tol for a, b in zip(values, reversed(values)))

    def gamma_text(self) -> list[str]:
        return [entry_text(g) for g in self.gamma]

    def processor_text(self) -> list[str]:
        return [entry_text(c) for c in self.processor]


def one_step(comp: Composition, convert=lambda g: g) -> list:
    """The substeps of one step as a composition of the base: gamma, or for a processed composition
    the processor, the kernel and the processor's inverse (c_1 .. c_m, gamma, -c_m .. -c_1; module
    docstring), each coefficient through `convert`."""
    processor = [convert(c) for c in comp.processor]
    return [*processor, *(convert(g) for g in comp.gamma), *(-c for c in reversed(processor))]


# ----------------------------------------------------------------------------- order


@dataclass(frozen=True)
class CompositionOrder:
    """The order of a composition for a base of order `base_order` (symmetric or not).

    Attributes:
        order: the largest p whose conditions all hold (at most `checked_up_to`).
        checked_up_to: the highest weight whose conditions were evaluated.
        base_order: q, the base method's order.
        base_symmetric: whether the base's modified field has odd powers of h only.
        conditions: number of word conditions up to order + 1 (or checked_up_to).
        largest_failing: the largest |residual| among the words of weight order + 1 (None when
            none was checked; inf when it is beyond the float range).
        precision: how the conditions were evaluated ("exact rationals", "60 digits", ...).
    """

    order: int
    checked_up_to: int
    base_order: int
    base_symmetric: bool
    conditions: int
    largest_failing: float | None
    precision: str


def letters(base_order: int, base_symmetric: bool, max_weight: int) -> tuple[int, ...]:
    """Weights of the letters F_k of a base of order q: 1, then q+1, q+2, ... (q+1, q+3, ... for a
    symmetric base), up to `max_weight`."""
    step = 2 if base_symmetric else 1
    return (1, *range(base_order + 1, max_weight + 1, step))


def words_of_weight(weights: tuple[int, ...], weight: int) -> list[tuple[int, ...]]:
    """Every word over the letters (by weight) whose weights sum to `weight` (compositions of
    `weight` into parts from `weights`)."""
    layers: list[list[tuple[int, ...]]] = [[()]]
    for total in range(1, weight + 1):
        layers.append([(k, *rest) for k in weights if k <= total for rest in layers[total - k]])
    return layers[weight]


def _dps(digits: int | None) -> int:
    return EXACT_DIGITS + 15 if digits is None else digits + 15


def _residual_tolerance(digits: int | None):
    """A residual at most this is zero: 10^-(d - 5) for coefficients of d digits, 10^-50 for
    exact ones evaluated at 60 digits."""
    return mpmath.mpf(10) ** -(EXACT_DIGITS - 10 if digits is None else max(digits - 5, 3))


def _mp(g):
    if isinstance(g, Fraction):
        return mpmath.mpf(g.numerator) / g.denominator
    if isinstance(g, mpmath.mpf):
        return mpmath.mpf(g)
    return mpmath.mpf(g.evalf(mpmath.mp.dps + 5))


def _residual_sum(gamma, digits, total: int = 1):
    """sum(gamma) - total as an mpmath number (of any magnitude: no float overflows)."""
    with mpmath.workdps(_dps(digits)):
        return sum((_mp(g) for g in gamma), mpmath.mpf(0)) - total


def _sum_text(residual, total: int) -> str:
    """total + residual (:func:`_residual_sum`) as a message shows it: 17 significant digits, of
    any magnitude."""
    with mpmath.workdps(_dps(None)):
        return mpmath.nstr(total + residual, 17)


def product_coefficients(gamma, weights: tuple[int, ...], max_weight: int):
    """The coefficients of prod_i exp(sum_k gamma_i^k F_k) (docs/compositions.md), weight after
    weight: yields, for p = 1 .. max_weight, a dict word -> coefficient over the words of weight p
    (exact for Fractions, mpmath numbers otherwise). A word's coefficient after substep i sums the
    coefficients of its heads after substep i - 1 times those of its tail in the i-th exponential,
    gamma_i^weight(tail) / len(tail)!; the heads weigh at most p, so each weight needs only the
    lighter ones, and a caller that stops at a failing weight computes no heavier word."""
    one = 1 if isinstance(gamma[0], Fraction) else mpmath.mpf(1)
    powers = [[g ** k for k in range(max_weight + 1)] for g in gamma]
    # after[i][w]: coefficient of w in the product of the first i exponentials
    after = [{(): one} for _ in range(len(gamma) + 1)]
    for p in range(1, max_weight + 1):
        layer = words_of_weight(weights, p)
        for i in range(1, len(gamma) + 1):
            before, now, pw = after[i - 1], after[i], powers[i - 1]
            for w in layer:
                acc = 0
                for cut in range(len(w) + 1):
                    head = before.get(w[:cut])
                    if head:
                        acc += head * pw[p - sum(w[:cut])] / math.factorial(len(w) - cut)
                now[w] = acc
        yield p, {w: after[-1][w] for w in layer}


def _exp_coefficient(w: tuple[int, ...], exact: bool):
    """The coefficient of w in exp(F_1) (a Fraction, or an mpmath number)."""
    value = Fraction(1, math.factorial(len(w))) if all(k == 1 for k in w) else Fraction(0)
    return value if exact else mpmath.mpf(value.numerator) / value.denominator


def composition_order(comp: Composition, base_order: int = 2, base_symmetric: bool = True,
                      max_order: int = MAX_COMPOSITION_ORDER) -> CompositionOrder:
    """The order of `comp` with a base of order `base_order` (HLW §III.3, §V.3): the largest p such
    that prod_i exp(sum_k gamma_i^k F_k) = exp(F_1) on every word of weight <= p, over the substeps
    of one step (:func:`one_step`: a processed composition's effective order)."""
    if base_order < 1:
        raise InputError(f"the base method has order {base_order}: a composition needs order >= 1")
    exact = all(isinstance(g, Fraction) for g in (*comp.gamma, *comp.processor))
    digits = comp.digits
    top = min(max_order, MAX_COMPOSITION_ORDER)
    weights = letters(base_order, base_symmetric, top)
    with mpmath.workdps(_dps(digits)):
        gamma = one_step(comp) if exact else one_step(comp, _mp)
        tol = 0 if exact else _residual_tolerance(digits)
        order, count, failing = 0, 0, None
        for p, coeff in product_coefficients(gamma, weights, top):
            residuals = [abs(c - _exp_coefficient(w, exact)) for w, c in coeff.items()]
            count += len(residuals)
            worst = max(residuals, default=0)
            if worst > tol:
                failing = float_or_infinity(worst)
                break
            order = p
    precision = "exact rationals" if exact else (f"{EXACT_DIGITS} digits" if digits is None
                                                  else f"the {digits} digits given")
    return CompositionOrder(order, min(order + 1, top), base_order, base_symmetric, count, failing,
                            precision)


# ----------------------------------------------------------------------------- files


def _compositions_dir():
    return files("rkhp.tables").joinpath("compositions")


@lru_cache(maxsize=1)
def _builtin_files() -> tuple[tuple[str, dict], ...]:
    """(file name, its keys) of every built-in composition, in file-name order."""
    return tuple((entry.name, tomllib.loads(entry.read_text(encoding="utf-8")))
                 for entry in sorted(_compositions_dir().iterdir(), key=lambda p: p.name)
                 if entry.name.endswith(".toml"))


@lru_cache(maxsize=1)
def _composition_registry() -> dict[str, str]:
    """name or alias (lower case) -> file name of every built-in composition."""
    out = {}
    for file, data in _builtin_files():
        for key in (data.get("name", file[:-5]), *data.get("aliases", ())):
            out[key.lower()] = file
    return out


def builtin_compositions() -> list[str]:
    """Names of the built-in compositions, in file-name order (their coefficients not parsed)."""
    return [data.get("name", file[:-5]) for file, data in _builtin_files()]


def is_builtin_composition(spec: str) -> bool:
    """Whether `spec` is a built-in composition's name or alias (case-insensitive): it stands for
    that composition whatever files exist (`load_composition`)."""
    return spec.lower() in _composition_registry()


def is_composition_name(spec: str) -> bool:
    """Whether `spec` names a built-in composition or a composition file: ``kind = "composition"``,
    or no ``kind`` and the key ``gamma`` without a Butcher matrix ``A`` (a tableau has A)."""
    if is_builtin_composition(spec):
        return True
    path = Path(spec)
    if path.suffix.lower() in (".toml", ".json") and is_file(path):
        try:
            data = _read_composition_file(path)
        except InputError:
            return False
        return data.get("kind") == KIND or ("kind" not in data and "gamma" in data and "A" not in data)
    return False


def load_composition(spec: str) -> Composition:
    """A built-in composition by name or alias, or a composition file (.toml/.json)."""
    if is_builtin_composition(spec):
        file = _composition_registry()[spec.lower()]
        return composition_from_dict(dict(_builtin_files())[file], file[:-5], f"built-in {file}")
    path = Path(spec)
    if not is_file(path):
        raise InputError(f"no composition named {spec!r}")
    return composition_from_dict(_read_composition_file(path), path.stem, str(path))


def _read_composition_file(path: Path):
    """The keys of a composition file: JSON for a .json file, TOML otherwise (read safely,
    `rkhp.base.documents`)."""
    kind = "json" if path.suffix.lower() == ".json" else "toml"
    return parse_document(read_text(path, "composition file"), str(path), kind)


def composition_from_dict(data: dict, default_name: str, where: str) -> Composition:
    """A Composition from the keys of a composition file (module docstring); InputError naming
    the file and key for anything malformed."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: a composition file is a table of keys")
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(_KEYS)})")
    if data.get("kind", KIND) != KIND:
        raise InputError(f"{where}: kind must be {KIND!r}, got {data.get('kind')!r}")
    gamma = data.get("gamma")
    if not isinstance(gamma, list) or not gamma:
        raise InputError(f"{where}: gamma must be a non-empty list of coefficients")
    if len(gamma) > MAX_SUBSTEPS:
        raise InputError(f"{where}: {len(gamma)} substeps, more than {MAX_SUBSTEPS}")
    processor = data.get("processor", [])
    if not isinstance(processor, list):
        raise InputError(f"{where}: processor must be a list of coefficients")
    if len(gamma) + 2 * len(processor) > MAX_SUBSTEPS:
        raise InputError(f"{where}: {len(gamma)} substeps and twice {len(processor)} of the processor, "
                         f"more than {MAX_SUBSTEPS}")
    values = tuple(parse_entry(g, f"{where}: gamma[{k}]") for k, g in enumerate(gamma))
    processor = tuple(parse_entry(c, f"{where}: processor[{k}]") for k, c in enumerate(processor))
    name = _text(data.get("name", default_name), where, "name")
    base = _text(data.get("base", DEFAULT_BASE), where, "base")
    order = data.get("order")
    if order is not None and (isinstance(order, bool) or not isinstance(order, int)
                              or not 1 <= order <= MAX_CLAIMED_ORDER):
        raise InputError(f"{where}: order must be an integer from 1 to {MAX_CLAIMED_ORDER}")
    aliases = data.get("aliases", [])
    if not isinstance(aliases, list):
        raise InputError(f"{where}: aliases must be a list of names")
    comp = Composition(name, base, values, _text(data.get("reference", ""), where, "reference"), order,
                       tuple(_text(a, where, "aliases") for a in aliases),
                       _text(data.get("notes", ""), where, "notes"), processor)
    if not comp.consistent:
        raise InputError(f"{where}: the coefficients sum to {_sum_text(_residual_sum(values, comp.digits), 1)}, "
                         "not 1: not a consistent composition")
    if abs(comp.processor_sum) > _residual_tolerance(comp.digits):
        raise InputError(f"{where}: the processor's coefficients sum to {_sum_text(comp.processor_sum, 0)}, not 0")
    return comp


def _text(value, where: str, key: str) -> str:
    if not isinstance(value, str) or len(value) > 2000:
        raise InputError(f"{where}: {key} must be a text of at most 2000 characters")
    return value


def exact_entries(comp: Composition) -> bool:
    """Whether every coefficient is exact (rational or algebraic)."""
    return all(is_exact(g) for g in (*comp.gamma, *comp.processor))


# ----------------------------------------------------------------------------- verification


@dataclass(frozen=True)
class CompositionVerification:
    """What `rkhp verify` says of a composition.

    Attributes:
        composition: the Composition.
        own: its order with its base on a symmetric realisation (the base's symmetric order q, odd in
            h for a symmetric RKHP base; Euler's q = 2 is how compositions are published): what a
            claimed order states.
        base_symmetric: whether the base RKHP method is symmetric under a symmetric birealisation
            (checked to `base_symmetry_checked` orders, :func:`rkhp.tableaux.symmetry.rkhp_symmetry`).
        by_class: its order with its base on each realisation class (general, degenerate,
            symmetric), the base's order in that class counted as q.
        claim: "confirmed", "overstated" or None (no claimed order).
        kernel_order: the order of the kernel alone in the case of `own` (a processed
            composition's kernel; else `own`'s order).
    """

    composition: Composition
    own: CompositionOrder
    base_symmetric: bool
    base_symmetry_checked: int
    by_class: dict
    claim: str | None
    kernel_order: int

    kind = KIND
    #: docs/compositions.md "JSON keys"
    json_keys = (("name", "composition.name"), "kind", ("base", "composition.base"),
                 ("substeps", "composition.substeps"), ("gamma", "composition.gamma_text"),
                 ("gamma_float", "composition.gamma_float"), ("processor", "composition.processor_text"),
                 ("processor_float", "composition.processor_float"), "kernel_order",
                 ("reference", "composition.reference"),
                 ("symmetric", "composition.symmetric"), "base_symmetric",
                 ("base_symmetry_checked_up_to", "base_symmetry_checked"), ("order", "own.order"), "own",
                 ("orders", "by_class"), ("claimed_order", "composition.claimed_order"), "claim")


def class_composition_orders(comp: Composition, base) -> dict[str, CompositionOrder]:
    """The order of `comp` with the RKHP method `base` (a Tableau) on each realisation class: q is
    the base's order in the class; the base's modified field is odd in h on the symmetric class
    when the base is a symmetric RKHP method (docs/compositions.md). The order depends only on q
    and that symmetry: it is computed once for each such pair."""
    from .symmetry import rkhp_symmetry
    from .verification import class_orders

    orders = class_orders(base)
    symmetric = rkhp_symmetry(base).symmetric
    done = {}
    by_class = {}
    for cls, q in orders.items():
        pair = (q, cls == "symmetric" and symmetric)
        if pair not in done:
            done[pair] = composition_order(comp, *pair)
        by_class[cls] = done[pair]
    return by_class


def verify_composition(comp: Composition) -> CompositionVerification:
    """The orders of a composition with its base on each realisation class, its own (the symmetric
    class's: the base's symmetric order, odd in h when the base is a symmetric RKHP method), its
    symmetry, and its claimed order checked against its own."""
    from .symmetry import rkhp_symmetry

    base = load_tableau(comp.base)
    symmetry = rkhp_symmetry(base)
    by_class = class_composition_orders(comp, base)
    own = by_class["symmetric"]
    claim = None
    if comp.claimed_order is not None:
        claim = "confirmed" if own.order >= comp.claimed_order else "overstated"
    kernel = (composition_order(Composition(comp.name, comp.base, comp.gamma), own.base_order, own.base_symmetric).order
              if comp.processed else own.order)
    return CompositionVerification(comp, own, symmetry.symmetric, symmetry.checked_up_to, by_class, claim, kernel)
