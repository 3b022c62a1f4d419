"""Certificates of impossibility: 1 = sum_i g_i f_i with exact rational cofactors g_i.

If polynomials g_i with rational coefficients satisfy sum_i g_i f_i = 1, where f_i are the
condition polynomials of a search problem (:mod:`.ideal`), or the generators of the ideal J in
which b_1 and b_2 are eliminated (each an explicit combination of two condition polynomials, so
J is contained in the ideal of the conditions), then no point, real or complex, makes
every f_i vanish (it would make 1 vanish): no tableau with that many stages meets the conditions
(the weak Nullstellensatz says such g_i exist exactly when there is no complex solution).

Checking a certificate needs nothing but exact polynomial arithmetic: :func:`check_certificate`
rebuilds the f_i from the order conditions of this package, eliminating the same variables (so
the certificate must be about the problem it names), reads the stored g_i, and expands
sum g_i f_i in QQ[variables] with sympy's sparse polynomials. The certificates shipped with
rkhp live in ``rkhp/data/certificates/`` and are checked by the test suite.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from ..base.errors import InputError
from ..base.json_form import json_form
from ..base.provenance import write_output
from .ideal import condition_ideal, parse_polynomial
from .system import ResidualSystem, check_problem

#: Format tag of a certificate file.
CERTIFICATE_FORMAT = "rkhp-impossibility-certificate-1"
#: Largest certificate file read (bytes).
MAX_CERTIFICATE_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class Certificate:
    """1 = sum_i cofactors[i] * generators[i] in QQ[variables], for the problem named.

    Attributes:
        stages, order, cls, implicit: the problem (rkhp.search.system.ResidualSystem.build).
        variables, substitution, generators: the condition ideal (:mod:`.ideal`).
        cofactors: one polynomial per generator, as text.
        produced_by: the program and computation that found the cofactors.
        eliminated: the variables eliminated from the generators (``ConditionIdeal.reduced``).
    """

    stages: int
    order: int
    cls: str
    implicit: bool
    variables: tuple[str, ...]
    substitution: str
    generators: tuple[str, ...]
    cofactors: tuple[str, ...]
    produced_by: str
    eliminated: tuple[str, ...] = ()

    format = CERTIFICATE_FORMAT
    identity = "sum_i cofactors[i] * generators[i] = 1"
    #: the certificate file (docs/search.md)
    json_keys = ("format", "statement", "problem", "variables", "substitution", "eliminated", "identity",
                 "generators", "cofactors", "produced_by")

    @property
    def problem(self) -> dict:
        """The problem the certificate is about, as its file names it."""
        return {"stages": self.stages, "order": self.order, "class": self.cls, "implicit": self.implicit}

    @property
    def statement(self) -> str:
        kind = "implicit" if self.implicit else "explicit"
        return (f"no {kind} tableau with {self.stages} stages, real or complex, meets the "
                f"{self.cls} order conditions up to order {self.order}")

    @classmethod
    def from_json(cls_, data) -> Certificate:
        """The certificate of a parsed JSON document (InputError on a malformed one)."""
        try:
            if data["format"] != CERTIFICATE_FORMAT:
                raise InputError(f"not a certificate of format {CERTIFICATE_FORMAT}")
            prob = data["problem"]
            stages, order, klass, implicit = (prob["stages"], prob["order"], prob["class"],
                                              prob["implicit"])
            check_problem(stages, order)
            fields = [tuple(str(v) for v in data[k]) for k in ("variables", "generators",
                                                                 "cofactors")]
            cert = cls_(stages, order, str(klass), bool(implicit), fields[0],
                        str(data["substitution"]), fields[1], fields[2], str(data["produced_by"]),
                        tuple(str(v) for v in data.get("eliminated", [])))
        except (KeyError, TypeError) as exc:
            raise InputError(f"malformed certificate: missing or wrong field {exc}") from None
        if len(cert.cofactors) != len(cert.generators):
            raise InputError("malformed certificate: one cofactor per generator is needed")
        return cert


@dataclass(frozen=True)
class CertificateCheck:
    """The outcome of :func:`check_certificate`.

    Attributes:
        valid: the generators are this package's conditions and sum g_i f_i expands to 1.
        reason: why not (empty when valid).
        terms: the number of terms of the cofactors; seconds: time of the check.
    """

    valid: bool
    reason: str
    terms: int
    seconds: float

    identity = "sum_i g_i f_i = 1"
    json_keys = ("identity", ("cofactor_terms", "terms"), ("checked", "valid"), ("check_seconds", "rounded_seconds"))

    @property
    def rounded_seconds(self) -> float:
        return round(self.seconds, 3)


def check_certificate(cert: Certificate) -> CertificateCheck:
    """Check ``cert`` exactly (module docstring)."""
    t0 = time.perf_counter()
    ideal = condition_ideal(ResidualSystem.build(cert.stages, cert.order, cert.cls, cert.implicit))
    if cert.eliminated:
        ideal = ideal.reduced(cert.eliminated)

    def refuse(reason: str, terms: int = 0) -> CertificateCheck:
        return CertificateCheck(False, reason, terms, time.perf_counter() - t0)

    if ideal.eliminated != cert.eliminated:
        return CertificateCheck(False, "these variables cannot be eliminated", 0,
                                time.perf_counter() - t0)
    if ideal.variables != cert.variables or ideal.substitution != cert.substitution:
        return refuse("the variables are not those of the problem's condition ideal")
    R = ideal.ring()
    expected = ideal.polynomials()
    stored = [parse_polynomial(t, R) for t in cert.generators]
    if stored != expected:
        return refuse("the generators are not the problem's order-condition polynomials")
    cofactors = [parse_polynomial(t, R) for t in cert.cofactors]
    terms = sum(len(g) for g in cofactors)
    total = R.zero
    for g, f in zip(cofactors, expected, strict=True):
        if g:
            total += g * f
    if total != R.one:
        return refuse("sum g_i f_i is not 1", terms)
    return CertificateCheck(True, "", terms, time.perf_counter() - t0)


def load_certificate(path) -> Certificate:
    """A certificate from a JSON file (InputError when unreadable or malformed)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_CERTIFICATE_BYTES:
            raise InputError(f"{path}: {size} bytes, above the limit {MAX_CERTIFICATE_BYTES}")
        data = json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not JSON ({exc.msg}, line {exc.lineno})") from None
    return Certificate.from_json(data)


def save_certificate(cert: Certificate, path, force: bool = False) -> None:
    """Write ``cert`` as JSON (one polynomial per list entry), atomically; an existing file only
    with ``force`` (`rkhp.base.files`)."""
    write_output(path, json.dumps(json_form(cert), indent=1) + "\n", "--certificate", force)


def shipped_certificates() -> list[Path]:
    """The certificate files shipped in ``rkhp/data/certificates/``, sorted by name."""
    folder = resources.files("rkhp.data") / "certificates"
    if not folder.is_dir():
        return []
    return sorted(Path(str(f)) for f in folder.iterdir() if f.name.endswith(".json"))
