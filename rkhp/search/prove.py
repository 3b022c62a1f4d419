"""Deciding whether a search problem has a solution: Groebner bases of the order-condition ideal.

The order conditions up to order N for S stages are polynomial equations with rational
coefficients (:mod:`.ideal`: for explicit tableaux in the unknowns c_i, a_ij (j >= 2), b_i). By
Hilbert's Nullstellensatz they have no complex solution, hence no tableau exists, exactly when the
ideal they generate in QQ[unknowns] is the whole ring, i.e. when its reduced Groebner basis is [1].
A proper ideal (basis not [1]) proves that complex solutions exist; real ones may or may not.

Engines, chosen by measurement (docs/tableau-search.md, "Certificates of impossibility"):

- ``singular`` (when the optional program is installed, :mod:`rkhp.search.singular`): first a Groebner
  basis modulo the primes of :data:`EVIDENCE_PRIMES` (a quarter of the time limit at most; fast,
  and evidence only), then the reduced Groebner basis over Q (``slimgb``, degree reverse
  lexicographic), which decides; when it is [1], the cofactors of 1 = sum g_i f_i (``liftstd``),
  checked here in exact arithmetic (:mod:`.certificates`) before the problem is called proved
  with a certificate;
- ``sympy`` (always available): ``sympy.groebner`` (grevlex, over QQ) in a child process; a basis
  [1] proves impossibility but gives no cofactors.

Each computation stops at the time limit; ``on_progress(step, elapsed, limit)`` is called about
four times a second while one runs.
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from dataclasses import dataclass
from typing import NamedTuple

from ..base.errors import CheckFailed, InputError
from ..base.interrupts import INTERRUPT_SIGNALS
from .certificates import Certificate, CertificateCheck, check_certificate
from .ideal import (
    CERTIFICATE_ELIMINATION,
    DECISION_ELIMINATION,
    ConditionIdeal,
    condition_ideal,
    parse_polynomial,
    polynomial_text,
)
from .singular import singular_basis, singular_cofactors, singular_path
from .system import ResidualSystem

#: Engines accepted by :func:`prove_impossible`.
ENGINES = ("auto", "singular", "sympy")
#: Primes of the modular evidence (below 2^15, where Singular's arithmetic is fastest).
EVIDENCE_PRIMES = (32003, 31991, 32749)
#: Share of the time limit given to the modular evidence.
EVIDENCE_SHARE = 0.25


class ModularBasis(NamedTuple):
    """Whether the Groebner basis modulo ``prime`` is [1] (``unit``): evidence, not a proof."""

    prime: int
    unit: bool


@dataclass(frozen=True)
class Proof:
    """Outcome of a proof attempt.

    Attributes:
        proved: True when 1 is in the ideal (no tableau exists, even over C).
        status: "proved", "solutions-over-C" (basis not [1]) or "timeout".
        method: how (engine, ordering, field, what the result means).
        polynomials: the generators f_i, as text in ``variables``.
        basis: the reduced Groebner basis as text ([] on timeout; ["1"] when proved).
        seconds: time spent; time_limit: the limit given.
        engine: "singular" or "sympy"; variables, substitution: the unknowns (:mod:`.ideal`).
        dimension: Krull dimension of the ideal (-1 when proved; None when unknown).
        complex_solutions: number of complex solutions with multiplicity when finitely many.
        certificate: the checked cofactors (None without: sympy, or the time limit ran out).
        check: the exact check of the certificate.
        modular: (prime, basis is [1]) for each prime whose basis was computed in time.
        eliminated: the variables eliminated before the basis that decided (:mod:`.ideal`).
    """

    proved: bool
    status: str
    method: str
    polynomials: tuple[str, ...]
    basis: tuple[str, ...]
    seconds: float
    time_limit: float
    engine: str = "sympy"
    variables: tuple[str, ...] = ()
    substitution: str = ""
    dimension: int | None = None
    complex_solutions: int | None = None
    certificate: Certificate | None = None
    check: CertificateCheck | None = None
    modular: tuple[tuple[int, bool], ...] = ()
    eliminated: tuple[str, ...] = ()

    #: docs/json.md "rkhp search" ``proof_detail`` (after the order, which the search gives)
    json_keys = ("status", ("seconds", "rounded_seconds"), "time_limit", "polynomials", "basis", "engine", "variables",
                 "dimension", "complex_solutions", ("modular", "modular_bases"), ("certificate", "check"))

    @property
    def rounded_seconds(self) -> float:
        return round(self.seconds, 3)

    @property
    def modular_bases(self) -> tuple[ModularBasis, ...]:
        return tuple(ModularBasis(p, unit) for p, unit in self.modular)

    def modular_text(self) -> str:
        """The modular evidence in words (empty when none)."""
        if not self.modular:
            return ""
        units = [p for p, unit in self.modular if unit]
        proper = [p for p, unit in self.modular if not unit]
        parts = []
        if units:
            parts.append(f"the basis modulo {', '.join(map(str, units))} is [1] (no solution over "
                         "the algebraic closure of F_p: evidence of impossibility, not a proof)")
        if proper:
            parts.append(f"the ideal modulo {', '.join(map(str, proper))} is proper (evidence "
                         "that complex solutions exist, not a proof)")
        return "; ".join(parts)

    def result_text(self, stages: int, order: int, cls: str) -> str:
        """One sentence stating exactly what was (or was not) decided."""
        what = f"{cls} order {order} with {stages} stages"
        if self.proved and self.certificate is not None:
            return (f"proved impossible: 1 = sum g_i f_i with exact rational cofactors "
                    f"({self.check.terms} terms), checked; no tableau for {what}, real or complex "
                    f"({self.seconds:.2f} s)")
        if self.proved and self.engine == "singular":
            return (f"computed impossible, not proved: Singular's Groebner basis of the {len(self.polynomials)} "
                    f"order-condition polynomials is [1], so no tableau for {what}, real or complex, by "
                    f"Singular's output alone (cofactors not computed within the time limit: no certificate "
                    f"an independent tool can check; {self.seconds:.2f} s)")
        if self.proved:
            why = "no cofactors"
            return (f"proved impossible: the Groebner basis of the {len(self.polynomials)} "
                    f"order-condition polynomials is [1]; no tableau for {what}, real or complex "
                    f"({why}; {self.seconds:.2f} s)")
        if self.status == "solutions-over-C":
            size = (f", {self.complex_solutions} complex solutions with multiplicity"
                    if self.complex_solutions is not None else
                    f", dimension {self.dimension}" if self.dimension is not None else "")
            return (f"not proved: the ideal of {what} is proper (basis of {len(self.basis)} "
                    f"polynomials{size}), so complex solutions exist; real ones were not "
                    f"examined ({self.seconds:.2f} s)")
        evidence = self.modular_text()
        return (f"not decided: no Groebner basis over Q for {what} within {self.time_limit:g} s "
                f"({self.engine})" + (f"; {evidence}" if evidence else ""))


# ----------------------------------------------------------------------------- sympy


WORKER_EXIT_SECONDS = 1.0
"""How long a Groebner worker that has sent its basis is given to end by itself."""


def _groebner_worker(exprs, names, conn) -> None:
    """The basis sent back through `conn`. A forked child: it leaves the interrupt signals to
    their default action (the parent's handlers, a command's, would turn the SIGTERM that ends a
    child still running into a traceback on the shared stderr)."""
    import sympy

    for signum in INTERRUPT_SIGNALS:
        signal.signal(signum, signal.SIG_DFL)
    symbols = sympy.symbols(names)
    basis = sympy.groebner(exprs, *symbols, order="grevlex", domain=sympy.QQ)
    conn.send([str(g) for g in basis.exprs])
    conn.close()


def _sympy_basis(ideal: ConditionIdeal, deadline: float, on_wait) -> tuple[str, ...] | None:
    """The reduced basis by sympy in a child process, or None at the deadline."""
    exprs = [p.as_expr() for p in ideal.polynomials()]
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_groebner_worker, args=(exprs, list(ideal.variables), send),
                       daemon=True)
    proc.start()
    send.close()
    basis = None
    try:
        while basis is None and time.monotonic() < deadline:
            if receive.poll(min(0.25, max(0.0, deadline - time.monotonic()))):
                basis = tuple(receive.recv())
            elif not proc.is_alive():
                break
            elif on_wait is not None:
                on_wait()
    except EOFError:
        basis = None
    finally:
        if basis is not None:
            proc.join(WORKER_EXIT_SECONDS)  # it has sent its answer: let it end by itself
        if proc.is_alive():
            proc.terminate()
        proc.join()
    return basis


# ----------------------------------------------------------------------------- singular


def _certificate(ideal: ConditionIdeal, lines, produced_by: str) -> Certificate | None:
    """The certificate of Singular's ``UNIT`` output for the generators of ``ideal``."""
    if not lines or lines[0] != "UNIT":
        return None
    R = ideal.ring()
    cofactors = tuple(polynomial_text(parse_polynomial(line.removeprefix("POLY "), R),
                                      ideal.variables) for line in lines[1:])
    return Certificate(ideal.stages, ideal.order, ideal.cls, ideal.implicit, ideal.variables,
                       ideal.substitution, ideal.generators, cofactors, produced_by,
                       ideal.eliminated)


def _parse_basis(run) -> tuple[tuple[str, ...], int, int]:
    """(basis, dim, vdim) of a finished :func:`rkhp.search.singular.singular_basis` run."""
    head = run.lines[0].split()
    size, dim, vdim = int(head[1]), int(head[2]), int(head[3])
    return tuple(line.removeprefix("POLY ").strip() for line in run.lines[1:1 + size]), dim, vdim


def _singular_proof(path, full: ConditionIdeal, deadline, waiting, t0, time_limit) -> Proof:
    """Modular evidence, then the basis of J over Q, its cofactors when [1], else the basis of I."""
    ideal = full.reduced(DECISION_ELIMINATION)
    method = ("Singular: slimgb over QQ, degrevlex, on the conditions with "
              + (", ".join(ideal.eliminated) + " eliminated" if ideal.eliminated else "nothing "
                 "eliminated") + " (after bases modulo small primes, evidence only); liftstd for "
              "the cofactors, checked exactly")
    modular = []
    for p in EVIDENCE_PRIMES:
        short = min(deadline, t0 + EVIDENCE_SHARE * time_limit)
        run = singular_basis(path, ideal.variables, ideal.generators, short,
                             waiting(f"basis modulo {p}"), p)
        if not run.finished:
            break
        unit = run.lines[1:] == ("POLY 1",)
        if unit or ideal is full:  # J proper modulo p says nothing about I
            modular.append((p, unit))
    common = dict(method=method, polynomials=full.generators, time_limit=time_limit,
                  engine="singular", variables=full.variables, substitution=full.substitution,
                  modular=tuple(modular), eliminated=ideal.eliminated)
    run = singular_basis(path, ideal.variables, ideal.generators, deadline,
                         waiting("basis over Q"))
    if not run.finished:
        return Proof(False, "timeout", basis=(), seconds=time.monotonic() - t0, **common)
    basis, dim, vdim = _parse_basis(run)
    if basis != ("1",):
        if ideal is not full:  # J proper says nothing about I: decide I itself
            run = singular_basis(path, full.variables, full.generators, deadline,
                                 waiting("basis over Q, full ideal"))
            if not run.finished:
                return Proof(False, "timeout", basis=(), seconds=time.monotonic() - t0, **common)
            basis, dim, vdim = _parse_basis(run)
        common["eliminated"] = ()
        if basis != ("1",):
            return Proof(False, "solutions-over-C", basis=basis, seconds=time.monotonic() - t0,
                         dimension=dim, complex_solutions=vdim if dim == 0 else None, **common)
    ideal = full.reduced(CERTIFICATE_ELIMINATION) if ideal is not full else full
    lift = singular_cofactors(path, ideal.variables, ideal.generators, deadline,
                              waiting("cofactors over Q"))
    cert = check = None
    if lift.finished:
        cert = _certificate(ideal, lift.lines, f"{run.version}: liftstd over QQ, dp ordering")
    if cert is not None:
        waiting("checking cofactors")()
        check = check_certificate(cert)
        if not check.valid:
            raise CheckFailed(f"Singular's cofactors do not check: {check.reason}")
    return Proof(True, "proved", basis=("1",), seconds=time.monotonic() - t0, dimension=-1,
                 certificate=cert, check=check, **common)


# ----------------------------------------------------------------------------- entry point


def choose_engine(engine: str = "auto") -> tuple[str, str | None]:
    """(engine, Singular's path or None): ``auto`` is Singular when installed, else sympy."""
    if engine not in ENGINES:
        raise InputError(f"unknown proof engine {engine!r}; expected one of {', '.join(ENGINES)}")
    path = singular_path() if engine in ("auto", "singular") else None
    if engine == "singular" and path is None:
        raise InputError("the proof engine 'singular' needs the Singular program on PATH "
                         "(e.g. apt-get install singular)")
    return ("singular", path) if path is not None else ("sympy", None)


def prove_impossible(system: ResidualSystem, time_limit: float = 60.0, engine: str = "auto",
                     on_progress=None) -> Proof:
    """Try to prove that the system has no solution (1 in its ideal) within ``time_limit`` s."""
    t0 = time.monotonic()
    deadline = t0 + time_limit
    name, path = choose_engine(engine)

    def waiting(step: str):
        if on_progress is None:
            return lambda: None
        return lambda: on_progress(step, time.monotonic() - t0, time_limit)

    waiting("order-condition polynomials")()
    ideal = condition_ideal(system)
    if name == "singular":
        return _singular_proof(path, ideal, deadline, waiting, t0, time_limit)
    method = "sympy: groebner over QQ, grevlex (no cofactors)"
    reduced = ideal.reduced(DECISION_ELIMINATION)
    basis = _sympy_basis(reduced, deadline, waiting("basis over Q (sympy)"))
    eliminated = reduced.eliminated
    if basis is not None and basis != ("1",) and reduced is not ideal:
        basis = _sympy_basis(ideal, deadline, waiting("basis over Q, full ideal (sympy)"))
        eliminated = ()
    seconds = time.monotonic() - t0
    common = dict(method=method, polynomials=ideal.generators, seconds=seconds,
                  time_limit=time_limit, engine="sympy", variables=ideal.variables,
                  substitution=ideal.substitution, eliminated=eliminated)
    if basis is None:
        return Proof(False, "timeout", basis=(), **common)
    proved = basis == ("1",)
    return Proof(proved, "proved" if proved else "solutions-over-C", basis=basis,
                 dimension=-1 if proved else None, **common)
