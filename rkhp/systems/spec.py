"""Poisson systems from spec files (TOML or JSON).

Keys (docs/spec-files.md): the common keys below, and the spec key of the family (the registry
`rkhp.systems.families`) holding its structure:

    name = "my-body"                       # optional (default: the file name)
    family = "lie-poisson"                 # or "log-canonical" or "constant"
    structure_constants = [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]]
                                           # lie-poisson: {x_i, x_j} = sum_k value x_k (1-based;
                                           # {x_j, x_i} = -{x_i, x_j} is implied)
    # lambda = [[0, 1, 2], [-1, 0, 1], [-2, -1, 0]]   # log-canonical: pi_ij = lambda_ij x_i x_j
    # poisson = [[0, 1], [-1, 0]]                      # constant pi
    # family = "general": poisson = [["0", "x3", "-x2"], ["-x3", "0", "x1"], ["x2", "-x1", "0"]]
    #                                   # any pi(x): a matrix of expressions in x1..xn, checked
    #                                   # (antisymmetry, Jacobi, Casimirs, finite at x0)
    hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"        # an expression in x1..xn (sympy syntax)
    x0 = [0.4536, 0.0, 0.8912]
    t_final = 10.0                         # optional (default 10)
    casimirs = ["x1^2 + x2^2 + x3^2"]      # optional
    invariants = ["x1^2/2 + x2^2 + 3*x3^2/2"]  # optional: first integrals to report, like H

Expressions are read by the safe reader `rkhp.base.expressions` (no code is ever executed) and recorded
on a tape (`rkhp.taylor.tape`) that the compiled engine differentiates; the functions allowed are
those of the opcode table (`rkhp.taylor.ops.FUNCTIONS`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..base import documents
from ..base.bounds import MAX_DIMENSION
from ..base.documents import parse_document, read_text
from ..base.errors import InputError
from ..base.expressions import parse_expression as read
from ..base.expressions import variable_names
from .core import PoissonSystem
from .families import FAMILIES, GENERAL, family_system, short
from .general import general
from .program import numeric_function, to_program
from .structure import check_structure

COMMON_KEYS = ("name", "family", "hamiltonian", "x0", "t_final", "casimirs", "invariants")
#: the relative size of {I, H}(x0) above which a declared invariant I is refused
INVARIANT_TOLERANCE = 1e-9
#: the most Casimirs, and the most invariants, of one system
MAX_EXPRESSIONS = 64


def family_names() -> tuple[str, ...]:
    """The families a spec file may name."""
    return tuple(FAMILIES)


def spec_keys() -> tuple[str, ...]:
    """Every key a spec file may have: the common ones and each family's."""
    return COMMON_KEYS + tuple(dict.fromkeys(f.spec_key for f in FAMILIES.values()))


def spec_text(path) -> str:
    """The text of a spec file, read safely (`rkhp.base.documents.read_text`: a regular file,
    its size bounded, UTF-8)."""
    path = Path(path)
    if not documents.path_exists(path):
        raise InputError(f"spec file {path} not found")
    return read_text(path, "spec file")


def _keys(text: str, path: Path) -> dict:
    """The keys of a spec file's text, parsed safely (`rkhp.base.documents`: nesting, repeated
    keys; JSON for a .json file, TOML otherwise) and checked against `spec_keys`."""
    data = parse_document(text, str(path), "json" if path.suffix.lower() == ".json" else "toml")
    keys = spec_keys()
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise InputError(f"{path}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(keys)}")
    return data


def parse_spec_expression(text, n: int, where: str):
    """A sympy expression in x1..xn read by the safe reader (`rkhp.base.expressions`), with its
    symbols (InputError naming unknown symbols, bad syntax or anything outside the grammar)."""
    names = variable_names(n)
    expr = read(text, names, where=where)
    import sympy

    return expr, tuple(sympy.Symbol(name, real=True) for name in names)


def check_finite_at(exprs, symbols, x0, where: str, gradient: bool = True) -> None:
    """Each (label, expression) and, with ``gradient``, its gradient are finite real numbers at x0
    (InputError naming the first that is not: a Hamiltonian or Casimir undefined or infinite at
    the initial point, a constant beyond the float range)."""
    import sympy

    point = [float(v) for v in x0]
    for label, expr in exprs:
        values = [expr] + ([sympy.diff(expr, s) for s in symbols] if gradient else [])
        try:
            got = sympy.lambdify(symbols, values, "math")(*point)
        except (ValueError, OverflowError, ZeroDivisionError, TypeError) as exc:
            got = [f"undefined ({' '.join(str(exc).split()) or type(exc).__name__})"]
        bad = [v for v in got if not (isinstance(v, int | float) and math.isfinite(v))]
        if bad:
            what = "its gradient" if got[0] is not bad[0] else "its value"
            raise InputError(f"{where}: {label} {short(str(expr))} is not finite at x0 = {point}: "
                             f"{what} is {bad[0]}")


def check_start(system, where: str = "x0") -> None:
    """For a system started elsewhere (``--x0``): the Hamiltonian and the Casimirs, with the
    gradient of H, and the structure pi are finite at its x0; InputError otherwise. A system from
    a spec file is checked from its expressions (:func:`check_finite_at`, no compiled code),
    another (a built-in) by its own functions (:func:`check_values_finite`)."""
    if "expressions" in system.extra:
        symbols, expressions = system.extra["expressions"]
        check_finite_at(expressions, symbols, system.x0, where)
    else:
        check_values_finite(system, where)
    check_structure_finite(system, where)


def check_values_finite(system, where: str) -> None:
    """H, grad H and the Casimirs as ``system`` computes them (the tapes the integrators evaluate)
    are finite at its x0 (InputError naming the first that is not: a state so large that the energy
    overflows, where no step can be taken)."""
    x0 = system.x0
    with np.errstate(all="ignore"):
        values = [("hamiltonian", "its value", system.hamiltonian(x0)),
                  ("hamiltonian", "its gradient", system.grad_hamiltonian(x0))]
        values += [(f"casimir {i + 1}", "its value", casimir) for i, casimir in enumerate(system.casimir_values(x0))]
    for label, what, value in values:
        if not np.all(np.isfinite(value)):
            raise InputError(f"{where}: {label} of {system.name} is not finite at x0 = {x0.tolist()}: "
                             f"{what} is {np.asarray(value).tolist()}")


def check_structure_finite(system, where: str) -> None:
    """pi(x0) of ``system`` is finite (InputError naming its first entry that is not: data of the
    structure, or a state, so large that pi overflows there)."""
    with np.errstate(all="ignore"):
        pi = np.asarray(system.poisson(system.x0), dtype=np.float64)
    bad = np.argwhere(~np.isfinite(pi))
    if bad.size:
        i, j = (int(v) for v in bad[0])
        raise InputError(f"{where}: the structure pi of {system.name} is not finite at x0 = {system.x0.tolist()}: "
                         f"entry ({i + 1}, {j + 1}) is {pi[i, j]}")


def load_spec(path, realisation: str = "symmetric") -> PoissonSystem:
    """A PoissonSystem from a spec file (see the module docstring for the keys).

    Everything is checked before the system is used (docs/input.md "Spec files"): the types of
    the keys (booleans are not numbers), finite numbers, x0 in the domain, H and the Casimirs with
    their gradients finite at x0, the structure (antisymmetry, Jacobi identity) and that every
    declared Casimir Poisson-commutes with every x_i (`rkhp.systems.structure`).
    """
    return spec_system(spec_text(path), path, realisation)


def spec_system(text: str, path, realisation: str = "symmetric") -> PoissonSystem:
    """:func:`load_spec` of a spec file whose text is `text` (read by :func:`spec_text`)."""
    path = Path(path)
    return system_from_keys(_keys(text, path), str(path), path.stem, path.name, realisation)


#: where the errors of :func:`system` say they come from
PYTHON_SOURCE = "rkhp.system"


def system(*, realisation: str = "symmetric", **keys) -> PoissonSystem:
    """A PoissonSystem from the keys of a spec file given as Python values (docs/spec-files.md):
    ``rkhp.system(family="general", poisson=[["0", "-x3", "x2"], ...], hamiltonian="...",
    x0=[...], casimirs=[...])``. Expressions are strings or sympy expressions (read back through
    the same safe reader as a file's, from their text), matrices nested lists (or a sympy Matrix,
    a numpy array), numbers Python or numpy numbers. The checks and the errors are those of
    :func:`load_spec`, the errors naming ``rkhp.system`` instead of a file; ``name`` defaults
    to "system".
    """
    data = {key: _plain_value(value) for key, value in keys.items()}
    allowed = spec_keys()
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise InputError(f"{PYTHON_SOURCE}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}")
    return system_from_keys(data, PYTHON_SOURCE, "system", "Python", realisation)


def _plain_value(value):
    """A Python value as a parsed spec document holds it: sympy expressions as their text, sympy
    matrices and numpy arrays as nested lists, numpy scalars as Python numbers (booleans stay
    booleans, which the readers refuse as numbers)."""
    if isinstance(value, str | bool | int | float) or value is None:
        return value
    if type(value).__module__.split(".")[0] == "sympy":
        if hasattr(value, "tolist"):  # a Matrix
            return _plain_value(value.tolist())
        return str(value)
    if isinstance(value, np.ndarray | np.generic):
        return _plain_value(value.tolist())
    if isinstance(value, list | tuple):
        return [_plain_value(v) for v in value]
    return value


def _square_size(value) -> int | None:
    """n for a value that is an n x n list of lists (of a family whose key is a matrix), else None
    (the family's reader then says what is wrong with it)."""
    if isinstance(value, list) and value and all(isinstance(row, list) and len(row) == len(value) for row in value):
        return len(value)
    return None


def _expressions(data: dict, key: str, n: int, where: str) -> list:
    """The list of expressions under ``key`` (casimirs, invariants), read by the safe reader."""
    if key not in data:
        return []
    if not isinstance(data[key], list):
        raise InputError(f"{where}: {key} must be a list of expressions")
    if len(data[key]) > MAX_EXPRESSIONS:
        raise InputError(f"{where}: {len(data[key])} {key}; at most {MAX_EXPRESSIONS}")
    return [parse_spec_expression(c, n, f"{where}: {key}[{i + 1}]")[0] for i, c in enumerate(data[key])]


def check_invariants(system, exprs, symbols, where: str) -> None:
    """Each declared invariant I Poisson-commutes with H at x0: {I, H}(x0) = grad I . pi grad H
    is at most INVARIANT_TOLERANCE times |grad I| |pi grad H| (InputError naming the first that
    does not: it changes along the flow from the start on, docs/spec-files.md)."""
    import sympy

    point = [float(v) for v in system.x0]
    field = np.asarray(system.vector_field(np.asarray(point)), dtype=float)
    for i, expr in enumerate(exprs):
        gradient = np.array(sympy.lambdify(symbols, [sympy.diff(expr, s) for s in symbols], "math")(*point),
                            dtype=float)
        bracket = float(gradient @ field)
        if abs(bracket) > INVARIANT_TOLERANCE * (float(np.linalg.norm(gradient)) * float(np.linalg.norm(field))):
            raise InputError(f"{where}: invariants[{i + 1}] {short(str(expr))} is not conserved: its rate of "
                             f"change {{I, H}} at x0 is {bracket:.3g}, not 0")


def system_from_keys(data: dict, where: str, default_name: str, source: str,
                     realisation: str = "symmetric") -> PoissonSystem:
    """A PoissonSystem from the keys of a spec document (:func:`load_spec`'s checks; messages
    start with ``where``; ``source`` names the origin in the description)."""
    family = data.get("family")
    if family not in family_names():
        raise InputError(f"{where}: family must be one of {', '.join(family_names())}, got {short(family)}")
    if "x0" not in data:
        raise InputError(f"{where}: missing key x0")
    x0 = np.array(documents.number_list(data["x0"], f"{where}: x0", max_size=MAX_DIMENSION))
    n = x0.size
    name = documents.string(data.get("name", default_name), f"{where}: name")
    t_final = documents.document_number(data.get("t_final", 10.0), f"{where}: t_final", 0.0, low_open=True)
    needed = FAMILIES[family].spec_key
    for key in set(spec_keys()) - set(COMMON_KEYS):
        if key != needed and key in data:
            raise InputError(f"{where}: key {key} does not belong to family {family}")
    if needed not in data:
        raise InputError(f"{where}: family {family} needs key {needed}")
    if "hamiltonian" not in data:
        raise InputError(f"{where}: missing key hamiltonian")
    size = _square_size(data[needed]) if FAMILIES[family].matrix else None
    if size is not None and size != n:
        raise InputError(f"{where}: x0 has {n} entries but {needed} is {size} x {size}: the state has one "
                         f"entry per row of {needed}")
    structure = FAMILIES[family].read(data[needed], n, f"{where}: {needed}")
    h_expr, symbols = parse_spec_expression(data["hamiltonian"], n, f"{where}: hamiltonian")
    exprs = _expressions(data, "casimirs", n, where)
    invariant_exprs = _expressions(data, "invariants", n, where)
    H = to_program(h_expr, symbols)
    casimirs = tuple(numeric_function(e, symbols) for e in exprs)
    names = tuple(str(e) for e in exprs)
    common = dict(name=name, t_final=t_final, realisation=realisation, x0=x0,
                  description=f"from {source}: H = {H.expression}", hamiltonian_expression=lambda: h_expr)
    if family == GENERAL:
        # the structure and the declared Casimirs are checked (docs/theory.md §9)
        system = general(structure, H, casimirs=exprs, where=f"{where}: poisson", **common)
    else:
        system = family_system(family, structure, H, casimirs=casimirs or None, casimir_names=names,
                               **common)
    if not system.in_domain(x0):
        raise InputError(f"{where}: x0 = {x0.tolist()} is outside the domain ({system.domain})")
    check_structure_finite(system, where)
    expressions = [("hamiltonian", h_expr)] + [(f"casimir {i + 1}", e) for i, e in enumerate(exprs)]
    expressions += [(f"invariant {i + 1}", e) for i, e in enumerate(invariant_exprs)]
    check_finite_at(expressions, symbols, x0, where)
    if invariant_exprs:
        check_invariants(system, invariant_exprs, symbols, where)
        system = replace(system, invariants=tuple(numeric_function(e, symbols) for e in invariant_exprs),
                         invariant_names=tuple(str(e) for e in invariant_exprs))
    system.extra["expressions"] = (symbols, expressions)
    if family != GENERAL:  # the general family checks its structure and Casimirs itself
        check_structure(FAMILIES[family].symbolic(structure), casimirs=exprs, x0=x0,
                        where=f"{where}: the {family} structure")
    return system
