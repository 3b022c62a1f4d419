"""Impossibility certificates: a Groebner basis of the order-condition ideal equal to [1].

The order conditions up to order N for S stages are polynomial equations with rational
coefficients in the unknowns a_ij, b_i (c_i = sum_j a_ij substituted). By Hilbert's
Nullstellensatz they have no complex solution, hence no tableau exists, exactly when the ideal they
generate in QQ[a, b] is the whole ring, i.e. when its reduced Groebner basis is [1]. A proper
ideal (basis not [1]) proves that complex solutions exist; real ones may or may not. The basis is
computed by sympy (grevlex) in a child process, stopped at the time limit.
"""

from __future__ import annotations

import multiprocessing
import time
from dataclasses import dataclass

import numpy as np

from .system import ResidualSystem


@dataclass(frozen=True)
class Proof:
    """Outcome of a proof attempt.

    Attributes:
        proved: True when the Groebner basis is [1] (no tableau exists, even over C).
        status: "proved", "solutions-over-C" (basis not [1]) or "timeout".
        method: how (library, ordering, field).
        polynomials: the generators, as strings (the unknowns named a_ij, b_i, 1-based).
        basis: the reduced Groebner basis as strings ([] on timeout; ["1"] when proved).
        seconds: time spent; time_limit: the limit given.
    """

    proved: bool
    status: str
    method: str
    polynomials: tuple[str, ...]
    basis: tuple[str, ...]
    seconds: float
    time_limit: float

    def result_text(self, stages: int, order: int, cls: str) -> str:
        """One sentence stating what was (or was not) proved."""
        what = f"{cls} order {order} with {stages} stages"
        if self.proved:
            return (f"proved impossible: the Groebner basis of the {len(self.polynomials)} "
                    f"order-condition polynomials is [1] ({self.seconds:.2f} s)")
        if self.status == "solutions-over-C":
            return (f"not proved: the ideal of {what} is proper (basis of {len(self.basis)} "
                    f"polynomials), so complex solutions exist ({self.seconds:.2f} s)")
        return f"not proved: no Groebner basis for {what} within {self.time_limit:g} s"


def unknown_symbols(system: ResidualSystem):
    """sympy symbols a_ij (1-based, by rows) and b_i, in the order of the unknowns."""
    import sympy

    names = [f"a{i + 1}{j + 1}" if system.stages < 10 else f"a{i + 1}_{j + 1}"
             for i, j in system.pattern] + [f"b{i + 1}" for i in range(system.stages)]
    return sympy.symbols(names)


def condition_polynomials(system: ResidualSystem):
    """The residual polynomials sum_k w_k (gamma(t_k) a(t_k) - 1), expanded, and the symbols."""
    import sympy

    symbols = unknown_symbols(system)
    x = np.array(symbols, dtype=object)
    r, _ = system.residuals(x, jacobian=False)
    polys = [sympy.expand(v) for v in r]
    return [p for p in polys if p != 0], symbols


def _groebner_worker(polys, symbols, conn) -> None:
    import sympy

    basis = sympy.groebner(polys, *symbols, order="grevlex", domain=sympy.QQ)
    conn.send([str(g) for g in basis.exprs])
    conn.close()


def prove_impossible(system: ResidualSystem, time_limit: float = 60.0) -> Proof:
    """Try to prove that the system has no solution (Groebner basis [1]) within ``time_limit`` s."""
    t0 = time.perf_counter()
    polys, symbols = condition_polynomials(system)
    method = "Groebner basis over QQ (sympy, grevlex): basis [1] means no complex solution"
    text = tuple(str(p) for p in polys)
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_groebner_worker, args=(polys, symbols, send), daemon=True)
    proc.start()
    send.close()
    remaining = max(0.0, time_limit - (time.perf_counter() - t0))
    basis = None
    try:
        if receive.poll(remaining):
            basis = tuple(receive.recv())
    except EOFError:
        basis = None
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()
    seconds = time.perf_counter() - t0
    if basis is None:
        return Proof(False, "timeout", method, text, (), seconds, time_limit)
    proved = basis == ("1",)
    return Proof(proved, "proved" if proved else "solutions-over-C", method, text, basis, seconds,
                 time_limit)
