"""Poisson systems from spec files (TOML or JSON).

Keys (README "Spec files"):

    name = "my-body"                       # optional (default: the file name)
    family = "lie-poisson"                 # or "log-canonical" or "constant"
    structure_constants = [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]]
                                           # lie-poisson: {x_i, x_j} = sum_k value x_k (1-based;
                                           # {x_j, x_i} = -{x_i, x_j} is implied)
    # lambda = [[0, 1, 2], [-1, 0, 1], [-2, -1, 0]]   # log-canonical: pi_ij = lambda_ij x_i x_j
    # poisson = [[0, 1], [-1, 0]]                      # constant pi
    hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"        # an expression in x1..xn (sympy syntax)
    x0 = [0.4536, 0.0, 0.8912]
    t_final = 10.0                         # optional (default 10)
    casimirs = ["x1^2 + x2^2 + x3^2"]      # optional

Expressions are read by the safe reader `rkhp.expressions` (no code is ever executed) and recorded
on a tape (`rkhp.systems.tape`) that the compiled engine differentiates.
"""

from __future__ import annotations

import json
from functools import reduce
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..expressions import variable_names
from . import tape as tp
from .core import FAMILIES, PoissonSystem
from .families import constant, lie_poisson, log_canonical

KEYS = ("name", "family", "structure_constants", "lambda", "poisson", "hamiltonian", "x0",
        "t_final", "casimirs")


def _read(path: Path) -> dict:
    if not path.is_file():
        raise InputError(f"spec file {path} not found")
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text())
        else:
            import tomllib

            data = tomllib.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot parse: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a table of keys")
    unknown = sorted(set(data) - set(KEYS))
    if unknown:
        raise InputError(f"{path}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(KEYS)}")
    return data


def _matrix(value, n: int, where: str) -> np.ndarray:
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where} must be a matrix of numbers") from None
    if m.shape != (n, n):
        raise InputError(f"{where} must be {n} x {n} (the size of x0), got shape {m.shape}")
    return m


def _structure(value, n: int, where: str) -> np.ndarray:
    C = np.zeros((n, n, n))
    given: dict[tuple[int, int, int], float] = {}
    if not isinstance(value, list) or not value:
        raise InputError(f"{where} must be a non-empty list of [i, j, k, value]")
    for entry in value:
        if not (isinstance(entry, list) and len(entry) == 4):
            raise InputError(f"{where}: entry {entry!r} is not [i, j, k, value]")
        i, j, k, v = entry
        if not all(isinstance(q, int) and 1 <= q <= n for q in (i, j, k)):
            raise InputError(f"{where}: indices in {entry!r} must be integers from 1 to {n}")
        if i == j:
            raise InputError(f"{where}: {{x_{i}, x_{i}}} = 0 by antisymmetry, got {entry!r}")
        for key, val in (((i, j, k), float(v)), ((j, i, k), -float(v))):
            if key in given and given[key] != val:
                raise InputError(f"{where}: {entry!r} contradicts an earlier entry")
            given[key] = val
            C[key[0] - 1, key[1] - 1, key[2] - 1] = val
    return C


def parse_expression(text, n: int, where: str):
    """A sympy expression in x1..xn read by the safe reader (`rkhp.expressions`), with its
    symbols (InputError naming unknown symbols, bad syntax or anything outside the grammar)."""
    import sympy

    from ..expressions import parse_expression as read

    names = variable_names(n)
    expr = read(text, names, where=where)
    return expr, tuple(sympy.Symbol(name, real=True) for name in names)


def to_program(expr, symbols):
    """A program x -> tape Var computing the sympy expression (for `build_system`)."""
    index = {s: i for i, s in enumerate(symbols)}

    def conv(e, x):
        if not e.free_symbols:
            return float(e.evalf(20))
        if e.is_Symbol:
            return x[index[e]]
        args = [conv(a, x) for a in e.args]
        if e.is_Add:
            return reduce(lambda a, b: a + b, args)
        if e.is_Mul:
            return reduce(lambda a, b: a * b, args)
        if e.is_Pow:
            base, power = args
            if isinstance(base, float):
                return tp.exp(power * float(np.log(base)))
            return base ** power
        f = type(e).__name__
        (a,) = args
        if f in ("exp", "log", "sin", "cos"):
            return getattr(tp, f)(a)
        if f == "tan":
            return tp.sin(a) / tp.cos(a)
        ep, em = tp.exp(a), tp.exp(-a)
        return {"sinh": 0.5 * (ep - em), "cosh": 0.5 * (ep + em),
                "tanh": (ep - em) / (ep + em)}[f]

    def program(x):
        value = conv(expr, x)
        return value if isinstance(value, tp.Var) else x[0] * 0.0 + value

    program.expression = str(expr)
    return program


def _numeric(f):
    return lambda x: float(f(*x))


def load_spec(path, realisation: str = "symmetric") -> PoissonSystem:
    """A PoissonSystem from a spec file (see the module docstring for the keys)."""
    import sympy

    path = Path(path)
    data = _read(path)
    where = str(path)
    family = data.get("family")
    if family not in FAMILIES:
        raise InputError(f"{where}: family must be one of {', '.join(FAMILIES)}, got {family!r}")
    try:
        x0 = np.array(data["x0"], dtype=np.float64).reshape(-1)
    except KeyError:
        raise InputError(f"{where}: missing key x0") from None
    except (TypeError, ValueError):
        raise InputError(f"{where}: x0 must be a list of numbers") from None
    n = x0.size
    if n < 1 or not np.all(np.isfinite(x0)):
        raise InputError(f"{where}: x0 must be a non-empty list of finite numbers")
    if "hamiltonian" not in data:
        raise InputError(f"{where}: missing key hamiltonian")
    H = to_program(*parse_expression(data["hamiltonian"], n, f"{where}: hamiltonian"))
    casimirs, names = None, ()
    if "casimirs" in data:
        if not isinstance(data["casimirs"], list):
            raise InputError(f"{where}: casimirs must be a list of expressions")
        exprs = [parse_expression(c, n, f"{where}: casimirs")[0] for c in data["casimirs"]]
        symbols = tuple(sympy.Symbol(name, real=True) for name in variable_names(n))
        casimirs = tuple(_numeric(sympy.lambdify(symbols, e, "numpy")) for e in exprs)
        names = tuple(str(e) for e in exprs)
    t_final = data.get("t_final", 10.0)
    if not isinstance(t_final, int | float) or not np.isfinite(t_final) or t_final <= 0:
        raise InputError(f"{where}: t_final must be a positive number, got {t_final!r}")
    needed = {"lie-poisson": "structure_constants", "log-canonical": "lambda",
              "constant": "poisson"}[family]
    for key in ("structure_constants", "lambda", "poisson"):
        if key != needed and key in data:
            raise InputError(f"{where}: key {key} does not belong to family {family}")
    if needed not in data:
        raise InputError(f"{where}: family {family} needs key {needed}")
    common = dict(name=data.get("name", path.stem), x0=x0, t_final=float(t_final),
                  realisation=realisation, description=f"from {path.name}: H = {H.expression}")
    if family == "lie-poisson":
        C = _structure(data[needed], n, f"{where}: structure_constants")
        system = lie_poisson(C, H, casimirs=casimirs or (), casimir_names=names, **common)
    elif family == "log-canonical":
        L = _matrix(data[needed], n, f"{where}: lambda")
        system = log_canonical(L, H, casimirs=casimirs, casimir_names=names, **common)
    else:
        P = _matrix(data[needed], n, f"{where}: poisson")
        system = constant(P, H, casimirs=casimirs, casimir_names=names, **common)
    if not system.in_domain(x0):
        raise InputError(f"{where}: x0 = {x0.tolist()} is outside the domain ({system.domain})")
    return system
