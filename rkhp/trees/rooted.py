"""Rooted, non-planar (Butcher) trees: the value, bracket notation, sigma, gamma, enumeration.

Paper §3 (trees T, the grading |t|, the coefficient e(t) of eq. (e)) and Theorem "superconvergence"
(the subset T_0 of trees with no vertex whose only child is a leaf). Conventions: docs/theory.md §1.

A :class:`Tree` is immutable and hashable; equality is isomorphism. Its canonical identity is
``key``: the canonical level sequence (root at level 1, children in decreasing key order), stored as
bytes so that comparisons, hashing and concatenation run in C. Trees are ordered by decreasing
key, the Beyer–Hedetniemi order, which is the order of the paper's Table 1 (tallest tree first).

Enumeration builds every tree of order n as ``b[c1, *rest]`` from its largest child ``c1`` and the
tree ``r = b[rest]`` (all children of r at most c1): sigma, gamma and the key follow in O(1) from
those of c1 and r. T_0 is built the same way from T_0 trees directly (docs/theory.md §1), never by filtering T.
"""

from __future__ import annotations

import gc
from bisect import bisect_right
from fractions import Fraction
from functools import lru_cache
from math import factorial
from operator import itemgetter

from ..base.bounds import BYTES_PER_TREE, check_memory
from ..base.errors import InputError
from ..base.json_form import register

#: Largest order that enumeration accepts (order 18 has 1,721,159 trees, about 1 GB).
MAX_ENUMERATION_ORDER = 18
#: Largest order that counting accepts.
MAX_COUNT_ORDER = 200
#: Deepest tree (levels below the root) and largest tree that parse_tree reads.
MAX_DEPTH = 253
MAX_PARSE_ORDER = 10_000

_SHIFT = bytes([0] + [min(i + 1, 255) for i in range(1, 256)])


class Tree(tuple):
    """A rooted non-planar tree (paper §3), with its order, symmetry and density.

    ``Tree(children)`` builds b[children...] in canonical form; :func:`parse_tree` reads the
    bracket notation. The value is a tuple underneath (fast to build during enumeration), but only
    the named attributes are its interface:

    Attributes:
        children: the subtrees at the root, in canonical (decreasing key) order.
        order: |t|, the number of vertices.
        sigma: the number of automorphisms, sigma(b[t1^m1..tk^mk]) = prod mi! sigma(ti)^mi.
        gamma: the density, gamma(t) = |t| prod gamma(ti); the order condition is a(t) = 1/gamma.
        key: the canonical level sequence as bytes (equality and ordering).
        rest: the tree b[children[1:]] (None for the leaf), so that t = b[children[0]] merged
            with rest: elementary weights need one product per tree (docs/theory.md §2).
    """

    __slots__ = ()

    children = property(itemgetter(0))
    order = property(itemgetter(1))
    sigma = property(itemgetter(2))
    gamma = property(itemgetter(3))
    key = property(itemgetter(4))
    _lead = property(itemgetter(5))  # how many children equal the first one
    rest = property(itemgetter(6))

    def __new__(cls, children=()):
        return from_children(children)

    def __eq__(self, other):
        return isinstance(other, Tree) and self[4] == other[4]

    def __ne__(self, other):
        return not self == other

    def __hash__(self):
        return hash(self[4])

    # canonical order: t < u when t comes later in the Beyer–Hedetniemi order
    def __lt__(self, other):
        return self[4] < other[4]

    def __le__(self, other):
        return self[4] <= other[4]

    def __gt__(self, other):
        return self[4] > other[4]

    def __ge__(self, other):
        return self[4] >= other[4]

    def __repr__(self):
        return f"Tree({format_tree(self)!r})"

    def __str__(self):
        return format_tree(self)

    def __reduce__(self):
        return (parse_tree, (format_tree(self),))

    @property
    def e(self) -> Fraction:
        """e(t) = 1/gamma(t), the coefficient of the exact flow (paper eq. (e))."""
        return Fraction(1, self.gamma)

    @property
    def multiplicity(self) -> int:
        """Butcher's alpha(t) = |t|!/(sigma(t) gamma(t)): the number of monotone labellings."""
        return factorial(self.order) // (self.sigma * self.gamma)

    @property
    def in_t0(self) -> bool:
        """Whether t is in T_0: no vertex has a leaf as its only child (paper, Thm. superconvergence)."""
        return in_t0(self)

    def latex(self) -> str:
        """The paper's LaTeX form, e.g. ``\\forest{b[b,b[b]]}``."""
        return "\\forest{" + format_tree(self) + "}"


_new_tuple = tuple.__new__


def _make(children: tuple[Tree, ...], order: int, sigma: int, gamma: int, key: bytes, lead: int,
          rest: Tree | None) -> Tree:
    return _new_tuple(Tree, (children, order, sigma, gamma, key, lead, rest))


#: The single vertex b.
LEAF = _make((), 1, 1, 1, b"\x01", 0, None)


def from_children(children) -> Tree:
    """The tree b[children...] (any order of the children; the result is canonical).

    Built iteratively from the last (smallest) child: b[c_k], b[c_{k-1}, c_k], ... by
    :func:`graft_child`, so that a root with many children needs no recursion.
    """
    kids = sorted(children, key=_key_of, reverse=True)
    tree = LEAF
    for child in reversed(kids):
        tree = graft_child(child, tree)
    if tree.key and max(tree.key) >= 255:
        raise InputError(f"tree too deep: more than {MAX_DEPTH} levels")
    return tree


def _key_of(t: Tree) -> bytes:
    return t.key


def graft_child(c1: Tree, r: Tree) -> Tree:
    """b[c1, *r.children] when c1 is at least every child of r (O(1) bookkeeping; no sorting)."""
    order = c1.order + r.order
    if r.children and r.children[0].key == c1.key:
        lead = r._lead + 1
    else:
        lead = 1
    sigma = r.sigma * c1.sigma * lead
    gamma = r.gamma // r.order * order * c1.gamma
    key = b"\x01" + c1.key.translate(_SHIFT) + r.key[1:]
    return _make((c1,) + r.children, order, sigma, gamma, key, lead, r)


# ----------------------------------------------------------------------------- notation


def format_tree(t: Tree) -> str:
    """Bracket notation with children in increasing order, as the paper writes ``b[b,b[b]]``."""
    if not t.children:
        return "b"
    return "b[" + ",".join(format_tree(c) for c in reversed(t.children)) + "]"


register(Tree, format_tree)  # a tree's JSON form is its bracket notation


def parse_tree(text: str) -> Tree:
    """Parse the paper's bracket notation: ``b``, ``b[t1,...,tn]``; any child order, spaces allowed.

    Also accepts the LaTeX form ``\\forest{...}``. Raises InputError naming the problem. The parser
    is iterative (an explicit stack), and the text is bounded: at most MAX_PARSE_ORDER vertices
    and MAX_DEPTH levels.
    """
    if not isinstance(text, str):
        raise InputError(f"a tree must be a string in bracket notation, got {type(text).__name__}")
    if len(text) > 8 * MAX_PARSE_ORDER:
        raise InputError(f"tree text of {len(text)} characters; a tree may have at most {MAX_PARSE_ORDER} vertices")
    s = "".join(text.split())
    if s.startswith("\\forest{") and s.endswith("}"):
        s = s[len("\\forest{"):-1]
    if not s:
        raise InputError("empty tree string (expected bracket notation such as b[b,b[b]])")
    shown = text.strip() if len(text.strip()) <= 60 else text.strip()[:57] + "..."

    def syntax_error(msg: str, pos: int):
        raise InputError(f"malformed tree {shown!r}: {msg} at position {pos}")

    stack: list[list[Tree]] = []  # the children read so far of each open b[
    pos, vertices = 0, 0
    while True:  # at pos a tree starts
        if pos >= len(s) or s[pos] != "b":
            syntax_error("expected 'b'", pos)
        vertices += 1
        if vertices > MAX_PARSE_ORDER:
            syntax_error(f"more than {MAX_PARSE_ORDER} vertices", pos)
        pos += 1
        if pos < len(s) and s[pos] == "[":
            if len(stack) >= MAX_DEPTH:
                syntax_error(f"more than {MAX_DEPTH} levels", pos)
            stack.append([])
            pos += 1
            continue
        tree = LEAF
        while True:  # a tree is complete: attach it, closing the brackets that end here
            if not stack:
                if pos != len(s):
                    syntax_error("unexpected text after the tree", pos)
                return tree
            stack[-1].append(tree)
            if pos < len(s) and s[pos] == ",":
                pos += 1
                break
            if pos >= len(s) or s[pos] != "]":
                syntax_error("expected ',' or ']'", pos)
            pos += 1
            tree = from_children(stack.pop())


def in_t0(t: Tree) -> bool:
    """No vertex, root included, has a leaf as its only child (docs/theory.md §1)."""
    if len(t.children) == 1 and t.children[0].order == 1:
        return False
    return all(in_t0(c) for c in t.children)


# ----------------------------------------------------------------------------- enumeration


def check_order(n, maximum: int = MAX_ENUMERATION_ORDER, what: str = "order") -> int:
    """Validate an order argument: an integer 1 <= n <= maximum."""
    if isinstance(n, bool) or not isinstance(n, int):
        raise InputError(f"{what} must be an integer, got {n!r}")
    if n < 1:
        raise InputError(f"{what} must be at least 1, got {n}")
    if n > maximum:
        raise InputError(f"{what} {n} is above the supported maximum {maximum}")
    return n


class _TreeTable:
    """Trees of orders 1..size of T or T_0, grown in place when a larger order is asked for.

    by_order[n]: the trees of order n in canonical (decreasing key) order. rests[m]: the trees
    b[M] of order m (M a multiset of admissible children) in increasing key order, first_keys[m]
    the keys of their largest children (increasing too). For T_0 the rests are the T_0 trees plus
    b[b], since b[c1, b] is in T_0 whenever c1 is.
    """

    def __init__(self, degenerate: bool):
        self.degenerate = degenerate
        self.by_order: list[tuple[Tree, ...]] = [(), (LEAF,)]
        self.rests: list[list[Tree]] = [[], [LEAF]]
        self.first_keys: list[list[bytes]] = [[], [b""]]

    @property
    def size(self) -> int:
        return len(self.by_order) - 1

    def grow(self, max_order: int) -> None:
        """Extend to max_order. The cyclic garbage collector is paused meanwhile: trees hold no
        cycles, and its repeated scans of the growing heap would otherwise take most of the time."""
        enabled = gc.isenabled()
        gc.disable()
        try:
            for n in range(self.size + 1, max_order + 1):
                self._add_order(n)
        finally:
            if enabled:
                gc.enable()

    def _add_order(self, n: int) -> None:
        """Every tree of order n as b[c1, *r.children], c1 its largest child (graft_child, inlined)."""
        by_order, rests, first_keys = self.by_order, self.rests, self.first_keys
        shift = _SHIFT
        make = _new_tuple
        smaller = sorted((t for m in range(1, n) for t in by_order[m]), key=_key_of, reverse=True)
        out: list[Tree] = []
        append = out.append
        for c1 in smaller:
            c1_order, c1_sigma, c1_gamma, c1_key = c1[1], c1[2], c1[3], c1[4]
            m = n - c1_order
            shifted = b"\x01" + c1_key.translate(shift)
            # rests whose children are all <= c1 form a prefix of the increasing list
            stop = bisect_right(first_keys[m], c1_key)
            rest_m = rests[m]
            for i in range(stop - 1, -1, -1):
                r = rest_m[i]
                r_kids, r_order, r_sigma, r_gamma, r_key, r_lead, _ = r
                lead = r_lead + 1 if r_kids and r_kids[0][4] == c1_key else 1
                append(make(Tree, ((c1,) + r_kids, n, r_sigma * c1_sigma * lead,
                                   r_gamma // r_order * n * c1_gamma, shifted + r_key[1:], lead, r)))
        if self.degenerate and n == 2:
            out = []  # b[b] is not in T_0, but it is a rest: b[c1, b] is
            rest = [graft_child(LEAF, LEAF)]
        else:
            rest = out[::-1]
        by_order.append(tuple(out))
        rests.append(rest)
        first_keys.append([r[0][0][4] for r in rest])


_TABLES: dict[bool, _TreeTable] = {}


def _table(max_order: int, degenerate: bool) -> list[tuple[Tree, ...]]:
    """The trees of orders 0..(at least) max_order by order (index 0 empty), grown on demand."""
    table = _TABLES.get(degenerate)
    if table is None:
        table = _TABLES[degenerate] = _TreeTable(degenerate)
    if table.size < max_order:
        table.grow(max_order)
    return table.by_order


def _reset_tables() -> None:
    """Forget the enumerated trees (benchmarks measure enumeration from scratch)."""
    _TABLES.clear()


def trees_of_order(n: int, degenerate: bool = False) -> tuple[Tree, ...]:
    """All trees of order exactly n in T (or T_0 when degenerate), in canonical order."""
    check_order(n)
    return _table(n, degenerate)[n]


def trees_up_to(n: int, degenerate: bool = False) -> list[Tree]:
    """All trees of order 1..n in T (or T_0), grouped by increasing order, canonical within."""
    check_order(n)
    table = _table(n, degenerate)
    return [t for m in range(1, n + 1) for t in table[m]]


# ----------------------------------------------------------------------------- counting


@lru_cache(maxsize=8)
def _counts(max_order: int, degenerate: bool) -> tuple[int, ...]:
    """Counts by order 0..max_order through the multiset (Euler) transform, no trees built.

    T: t_{n+1} = [x^n] prod_k (1-x^k)^{-t_k} (OEIS A000081). T_0: a tree is a root with a multiset
    of T_0 children other than {b}, so t0_{n+1} = [x^n] MSET(T_0) - [n == 1].
    """
    t = [0] * (max_order + 1)
    t[1] = 1
    # mset[n] = [x^n] prod_k (1-x^k)^{-t_k}, via n*m_n = sum_{j=1}^n c_j m_{n-j}, c_j = sum_{d|j} d t_d
    mset = [1] + [0] * max_order
    c = [0] * (max_order + 1)
    for n in range(1, max_order):
        c[n] = sum(d * t[d] for d in range(1, n + 1) if n % d == 0)
        mset[n] = sum(c[j] * mset[n - j] for j in range(1, n + 1)) // n
        t[n + 1] = mset[n] - (1 if degenerate and n == 1 else 0)
    return tuple(t)


def count_trees(n: int, degenerate: bool = False) -> int:
    """Number of trees of order n in T (OEIS A000081) or in T_0, without building any tree."""
    check_order(n, MAX_COUNT_ORDER)
    return _counts(max(n, 16), degenerate)[n]


def check_tree_memory(order: int, degenerate: bool = False, what: str = "the enumeration",
                      per_tree: float = BYTES_PER_TREE) -> None:
    """The memory check of work on every tree of order <= `order` (of T, or T_0), `per_tree` bytes each."""
    total = sum(count_trees(n, degenerate) for n in range(1, order + 1))
    check_memory(float(total) * per_tree, f"{what} ({total} trees up to order {order})")
