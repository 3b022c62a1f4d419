"""The tree algebra of the paper (§3–4): grafting, its exponential, the BCK coproduct, characters
and the Butcher product.

Linear combinations of trees are plain dicts ``{Tree: coefficient}`` (integers or Fractions).
A forest is a tuple of trees in canonical order (decreasing key); the empty forest ``()`` is the
unit 1. A character is any mapping ``Tree -> number`` extended multiplicatively to forests with
a(1) = 1 (paper §4, the Butcher group G_B when a(b) = 1).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from fractions import Fraction
from math import prod

from .rooted import LEAF, Tree, check_order, from_children, trees_up_to

Combination = dict  # Tree -> coefficient
Forest = tuple  # tuple[Tree, ...], canonical order


def forest(trees: Iterable[Tree]) -> Forest:
    """The canonical form of a forest (a multiset of trees)."""
    return tuple(sorted(trees, reverse=True))


# ----------------------------------------------------------------------------- grafting


def graft(t1: Tree, t2: Tree) -> Combination:
    """t1 ↷ t2: the sum over the vertices v of t2 of t2 with the root of t1 attached to v (paper §3).

    ``graft(b[b], b[b]) == {b[b,b[b]]: 1, b[b[b[b]]]: 1}``.
    """
    out: Counter = Counter()
    for children, mult in _graft_children(t1, t2):
        out[from_children(children)] += mult
    return dict(out)


def _graft_children(t1: Tree, t2: Tree):
    """Yield (children of the root after grafting, multiplicity); equal children grafted once."""
    kids = t2.children
    yield kids + (t1,), 1
    seen: Counter = Counter(kids)
    for child, copies in seen.items():
        k = kids.index(child)
        others = kids[:k] + kids[k + 1:]
        for grafted, mult in graft(t1, child).items():
            yield others + (grafted,), mult * copies


def graft_linear(x: Mapping[Tree, object], y: Mapping[Tree, object]) -> Combination:
    """Bilinear extension of grafting to linear combinations."""
    out: Counter = Counter()
    for t1, c1 in x.items():
        for t2, c2 in y.items():
            for t, m in graft(t1, t2).items():
                out[t] += c1 * c2 * m
    return {t: c for t, c in out.items() if c}


def hamilton_jacobi_expansion(order: int, degenerate: bool = False) -> dict[int, Combination]:
    """exp^↷(t b) truncated at t^order: {n: coefficients of t^n/n!} (paper §3, eq. HJ).

    The coefficients are computed by iterated grafting over all of T; with ``degenerate`` the
    result is restricted to T_0 (paper, the degenerate expansion), trees outside T_0 dropped.
    Each coefficient equals Butcher's multiplicity |t|!/(sigma(t) gamma(t)).
    """
    check_order(order)
    out: dict[int, Combination] = {}
    x: Combination = {LEAF: 1}
    for n in range(1, order + 1):
        if n > 1:
            nxt: Counter = Counter()
            for t, c in x.items():
                for u, m in graft(LEAF, t).items():
                    nxt[u] += c * m
            x = dict(nxt)
        terms = {t: c for t, c in x.items() if not degenerate or t.in_t0}
        out[n] = dict(sorted(terms.items(), key=lambda kv: kv[0], reverse=True))
    return out


# ----------------------------------------------------------------------------- BCK coproduct


def coproduct(t: Tree) -> dict[tuple[Forest, Tree | None], int]:
    """Delta_BCK(t) = sum over rooted subtrees s of t (root kept, empty allowed) of (t \\ s) ⊗ s.

    Keys are (forest cut off, s), with s None for the empty subtree (the term t ⊗ 1) and the
    forest () for the unit (the term 1 ⊗ t). Paper §4, eq. (BCK_ex).
    """
    out: Counter = Counter()
    for cut, sub, m in _admissible_cuts(t):
        out[(forest(cut), sub)] += m
    out[((t,), None)] += 1
    return dict(out)


def _admissible_cuts(t: Tree):
    """Yield (forest cut off, rooted subtree kept, multiplicity) over non-empty rooted subtrees."""
    options_per_child = []
    for child in t.children:
        opts = [((child,), None, 1)]  # cut the whole child off
        opts.extend(_admissible_cuts(child))
        options_per_child.append(opts)
    results: Counter = Counter()
    for choice in _product(options_per_child):
        cut = tuple(x for c, _, _ in choice for x in c)
        kept = [s for _, s, _ in choice if s is not None]
        mult = prod(m for _, _, m in choice)
        results[(forest(cut), from_children(kept))] += mult
    for (cut, sub), m in results.items():
        yield cut, sub, m


def _product(lists):
    if not lists:
        yield ()
        return
    for head in lists[0]:
        for tail in _product(lists[1:]):
            yield (head,) + tail


# ----------------------------------------------------------------------------- characters


Character = Callable[[Tree], object]


def forest_value(a: Character, f: Forest):
    """A character extended multiplicatively to forests, with a(1) = 1."""
    value = 1
    for t in f:
        value = value * a(t)
    return value


def butcher_product(a1: Character, a2: Character, t: Tree):
    """(a1 * a2)(t) = sum over Delta(t) of a1(t \\ s) a2(s), a2(empty) = 1 (paper §4).

    a1 is the method applied first: the composition of B-series (docs/theory.md §3).
    """
    total = 0
    for (cut, sub), m in coproduct(t).items():
        total += m * forest_value(a1, cut) * (1 if sub is None else a2(sub))
    return total


def compose(a1: Mapping[Tree, object], a2: Mapping[Tree, object], order: int) -> dict[Tree, object]:
    """The character a1 * a2 on every tree of T up to ``order`` (a1, a2 given as mappings)."""
    return {t: butcher_product(a1.__getitem__, a2.__getitem__, t) for t in trees_up_to(order)}


def inverse(a: Mapping[Tree, object], order: int) -> dict[Tree, object]:
    """The inverse of a in the Butcher group (the antipode): a * a^{-1} = epsilon (paper §4).

    From (a * b)(t) = a(t) + b(t) + sum over proper non-empty subtrees s of a(t \\ s) b(s) = 0,
    solved for b(t) by increasing order.
    """
    inv: dict[Tree, object] = {}
    for t in trees_up_to(order):
        acc = -a[t]
        for (cut, sub), m in coproduct(t).items():
            if sub is None or not cut:
                continue
            acc -= m * forest_value(a.__getitem__, cut) * inv[sub]
        inv[t] = acc
    return inv


def exact_flow_character(order: int) -> dict[Tree, Fraction]:
    """e(t) = 1/gamma(t) on every tree up to ``order`` (paper eq. (e))."""
    return {t: t.e for t in trees_up_to(order)}
