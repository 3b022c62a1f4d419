"""Poisson systems from spec files (TOML or JSON).

Keys (README "Spec files"):

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

Expressions are read by the safe reader `rkhp.expressions` (no code is ever executed) and recorded
on a tape (`rkhp.systems.tape`) that the compiled engine differentiates.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..expressions import variable_names
from .core import FAMILIES, PoissonSystem
from .families import constant, lie_poisson, log_canonical
from .program import numeric_function, to_program

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


def _expression_matrix(value, n: int, where: str) -> tuple:
    """An n x n matrix of expressions (strings, or numbers) read by the safe reader."""
    if not (isinstance(value, list) and len(value) == n
            and all(isinstance(row, list) and len(row) == n for row in value)):
        raise InputError(f"{where} must be a {n} x {n} matrix (the size of x0) of expression "
                         f"strings")
    entries = []
    for i, row in enumerate(value):
        out = []
        for j, entry in enumerate(row):
            if isinstance(entry, bool) or not isinstance(entry, str | int | float):
                raise InputError(f"{where}: entry ({i + 1}, {j + 1}) must be an expression string "
                                 f"or a number, got {entry!r}")
            text = entry if isinstance(entry, str) else repr(entry)
            out.append(parse_expression(text, n, f"{where} ({i + 1}, {j + 1})")[0])
        entries.append(tuple(out))
    return tuple(entries)


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
        casimirs = tuple(numeric_function(e, symbols) for e in exprs)
        names = tuple(str(e) for e in exprs)
    t_final = data.get("t_final", 10.0)
    if not isinstance(t_final, int | float) or not np.isfinite(t_final) or t_final <= 0:
        raise InputError(f"{where}: t_final must be a positive number, got {t_final!r}")
    needed = {"lie-poisson": "structure_constants", "log-canonical": "lambda",
              "constant": "poisson", "general": "poisson"}[family]
    for key in ("structure_constants", "lambda", "poisson"):
        if key != needed and key in data:
            raise InputError(f"{where}: key {key} does not belong to family {family}")
    if needed not in data:
        raise InputError(f"{where}: family {family} needs key {needed}")
    common = dict(name=data.get("name", path.stem), t_final=float(t_final),
                  realisation=realisation, description=f"from {path.name}: H = {H.expression}")
    if family == "general":
        from .general import general

        entries = _expression_matrix(data[needed], n, f"{where}: poisson")
        system = general(entries, H, casimirs=exprs if "casimirs" in data else (),
                         where=f"{where}: poisson", x0=x0, **common)
    elif family == "lie-poisson":
        C = _structure(data[needed], n, f"{where}: structure_constants")
        system = lie_poisson(C, H, casimirs=casimirs or (), casimir_names=names, x0=x0, **common)
    elif family == "log-canonical":
        L = _matrix(data[needed], n, f"{where}: lambda")
        system = log_canonical(L, H, casimirs=casimirs, casimir_names=names, x0=x0, **common)
    else:
        P = _matrix(data[needed], n, f"{where}: poisson")
        system = constant(P, H, casimirs=casimirs, casimir_names=names, x0=x0, **common)
    if not np.isfinite(system.hamiltonian(x0)):
        raise InputError(f"{where}: the hamiltonian is not finite at x0 = {x0.tolist()}")
    if not system.in_domain(x0):
        raise InputError(f"{where}: x0 = {x0.tolist()} is outside the domain ({system.domain})")
    return system
