"""Certificates of impossibility (rkhp.search.certificates) and the proof engines (rkhp.search.prove).

Outside facts used: a published tableau (RK4, general order 4 and not 5) must be a zero of the
condition polynomials of its problem and not of the next order's; the Nullstellensatz identity
1 = sum g_i f_i is checked by expanding it, so any change to a stored cofactor or generator must
make the check fail; problems with a known solution (the paper's three-stage method) must never be
called impossible.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from fractions import Fraction

import pytest

from rkhp.base.errors import InputError
from rkhp.base.json_form import json_form
from rkhp.search.certificates import Certificate, check_certificate, load_certificate, shipped_certificates
from rkhp.search.ideal import condition_ideal, eliminate_linear, parse_polynomial, polynomial_ring, polynomial_text
from rkhp.search.prove import prove_impossible
from rkhp.search.singular import singular_path
from rkhp.search.system import ResidualSystem
from rkhp.tableaux.files import load_tableau

SHIPPED = {p.name: p for p in shipped_certificates()}
HAS_SINGULAR = singular_path() is not None


# ----------------------------------------------------------------------------- the shipped ones


def test_the_open_rows_decided_are_shipped():
    # docs/tableau-search.md: symmetric order 6 needs 5 stages, proved by this certificate
    assert "symmetric-o6-s4.json" in SHIPPED


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_certificate_checks_exactly(name):
    cert = load_certificate(SHIPPED[name])
    t0 = time.perf_counter()
    check = check_certificate(cert)
    assert check.valid, check.reason
    assert check.terms > 0 and time.perf_counter() - t0 < 60
    stem = f"{cert.cls}-o{cert.order}-s{cert.stages}{'-implicit' if cert.implicit else ''}.json"
    assert name == stem


def _tampered(cert: Certificate, **changes) -> Certificate:
    data = json_form(cert)
    data.update(changes)
    return Certificate.from_json(data)


def test_a_changed_cofactor_or_generator_fails_the_check():
    cert = load_certificate(SHIPPED["symmetric-o6-s4.json"])
    R = condition_ideal(ResidualSystem.build(4, 6, "symmetric")).ring()
    k = next(i for i, g in enumerate(cert.cofactors) if g != "0")
    g = parse_polynomial(cert.cofactors[k], R)
    nudged = list(cert.cofactors)
    nudged[k] = polynomial_text(g + R.domain.convert(Fraction(1, 7)) * R.gens[0], cert.variables)
    bad = check_certificate(_tampered(cert, cofactors=nudged))
    assert not bad.valid and bad.reason == "sum g_i f_i is not 1"
    gens = list(cert.generators)
    gens[1] = gens[1].replace("- 1", "- 2")
    bad = check_certificate(_tampered(cert, generators=gens))
    assert not bad.valid and "generators" in bad.reason
    # a certificate of another problem is not one of this problem
    other = json_form(cert)
    other["problem"] = dict(other["problem"], order=5)
    assert not check_certificate(Certificate.from_json(other)).valid


def test_malformed_certificates_are_input_errors(tmp_path):
    path = tmp_path / "c.json"
    path.write_text("{}")
    with pytest.raises(InputError):
        load_certificate(path)
    data = json_form(load_certificate(SHIPPED["symmetric-o6-s4.json"]))
    data["cofactors"] = data["cofactors"][:-1]
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match="one cofactor per generator"):
        load_certificate(path)


# ----------------------------------------------------------------------------- the ideal


def _tableau_point(ideal, tableau):
    """The unknowns of ``ideal`` (c_i, a_ij for j >= 2, b_i) at an explicit tableau."""
    A, b = tableau.A, tableau.b
    c = [sum(row) for row in A]
    value = {}
    for name in ideal.variables:
        if name[0] == "c":
            value[name] = c[int(name[1:]) - 1]
        elif name[0] == "b":
            value[name] = b[int(name[1:]) - 1]
        else:
            value[name] = A[int(name[1]) - 1][int(name[2]) - 1]
    return [value[v] for v in ideal.variables]


def test_rk4_is_a_zero_of_its_order_4_ideal_and_not_of_order_5():
    rk4 = load_tableau("rk4")
    for order, zero in ((4, True), (5, False)):
        ideal = condition_ideal(ResidualSystem.build(4, order, "general"))
        point = [ideal.ring().domain.convert(Fraction(str(x))) for x in
                 _tableau_point(ideal, rk4)]
        values = [p(*point) for p in ideal.polynomials()]
        assert all(v == 0 for v in values) is zero


def test_polynomial_text_round_trips_and_rejects_code():
    ideal = condition_ideal(ResidualSystem.build(4, 6, "degenerate"))
    R = ideal.ring()
    for text in ideal.generators:
        assert polynomial_text(parse_polynomial(text, R), ideal.variables) == text
    assert parse_polynomial("375/2*c2^2*b4-3*b1+1/3", R) == (
        R.domain.convert(Fraction(375, 2)) * R.gens[0] ** 2 * R.gens[-1] - 3 * R.gens[-4]
        + R.domain.convert(Fraction(1, 3)))
    for bad in ("__import__('os')", "c2**2", "x1", "c2^999", "1/0", "c2 c3"):
        with pytest.raises(InputError):
            parse_polynomial(bad, R)


# ----------------------------------------------------------------------------- engines


@pytest.mark.parametrize("engine", ["sympy"] + (["singular"] if HAS_SINGULAR else []))
def test_engines_decide_small_problems(engine):
    proof = prove_impossible(ResidualSystem.build(2, 4, "degenerate"), 60, engine)
    assert proof.proved and proof.basis == ("1",) and proof.engine == engine
    # the paper's three-stage method exists: the ideal must be proper
    proof = prove_impossible(ResidualSystem.build(3, 4, "degenerate"), 60, engine)
    assert not proof.proved and proof.status == "solutions-over-C"
    if engine == "singular":
        assert proof.dimension == 2  # 8 unknowns minus 4 conditions minus 2 redundant


@pytest.mark.parametrize("engine", ["sympy"] + (["singular"] if HAS_SINGULAR else []))
def test_time_limit_is_respected(engine):
    # symmetric order 8 with 6 stages: 21 unknowns, 36 conditions, undecided (docs/tableau-search.md)
    steps = []
    t0 = time.monotonic()
    proof = prove_impossible(ResidualSystem.build(6, 8, "symmetric"), 2.0, engine,
                             on_progress=lambda step, done, limit: steps.append(step))
    assert time.monotonic() - t0 < 10
    assert proof.status == "timeout" and not proof.proved
    assert "not decided" in proof.result_text(6, 8, "symmetric")
    assert any(s.startswith("basis") for s in steps)


def test_linear_elimination_is_a_combination_of_two_generators():
    R = polynomial_ring(("x", "y", "z"))
    x, y, z = R.gens
    # (x z) (x y - 1) - (x y) (x z - 2) has x^2 terms; the gcd-reduced combination does not
    assert eliminate_linear([x * y - 1, x * z - 2, y - z], x) == [y - z, -z + 2 * y]
    assert eliminate_linear([x ** 2 - 1, x * y], x) is None
    ideal = condition_ideal(ResidualSystem.build(5, 6, "degenerate"))
    reduced = ideal.reduced(("b1", "b2", "b3"))
    assert reduced.eliminated == ("b1", "b2", "b3")
    assert all(not any(v in g for v in ("b1", "b2", "b3")) for g in reduced.generators)
    assert ideal.reduced(("b1", "b2", "b3", "b4", "b5", "b6")).eliminated[-1] == "b5"


@pytest.mark.skipif(not HAS_SINGULAR, reason="Singular is not installed")
def test_singular_decides_degenerate_order_6_with_5_stages():
    # docs/tableau-search.md: 5 stages cannot reach degenerate order 6 (basis [1] over Q, about 0.5 s
    # with the bases modulo p; the cofactors, which no minute finds, are tried for the time left)
    proof = prove_impossible(ResidualSystem.build(5, 6, "degenerate"), 4.0, "singular")
    assert proof.proved and proof.eliminated == ("b1", "b2", "b3")
    assert all(unit for _, unit in proof.modular)


@pytest.mark.skipif(not HAS_SINGULAR, reason="Singular is not installed")
def test_singular_certificate_of_degenerate_order_5_with_3_stages(tmp_path):
    out = subprocess.run([sys.executable, "-m", "rkhp", "search", "--stages", "3", "--order", "5",
                          "--degenerate", "--restarts", "2", "--prove", "--prove-engine",
                          "singular", "--certificate", str(tmp_path / "c.json")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 1 and "proved impossible" in out.stdout
    cert = load_certificate(tmp_path / "c.json")
    assert check_certificate(cert).valid and cert.order == 5 and cert.stages == 3
