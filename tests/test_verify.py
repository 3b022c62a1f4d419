"""Order verification against the literature, the paper, perturbations, claims and the CLI."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest

from rkhp.base.errors import InputError
from rkhp.base.json_form import json_form
from rkhp.tableaux.files import load_tableau
from rkhp.tableaux.tableau import Tableau
from rkhp.tableaux.verification import verify
from rkhp.trees.rooted import count_trees

HNW = "Hairer, Norsett & Wanner, Solving ODEs I (1993)"
HW = "Hairer & Wanner, Solving ODEs II (1996)"

# General (classical) orders from the literature; the reference is in each tables/*.toml too.
LITERATURE = [
    ("euler", 1, "paper §5.2: Euler is a first-order RKHP method"),
    ("midpoint", 2, f"Runge (1895); {HNW} §II.1"),
    ("heun", 2, f"Heun (1900); {HNW} §II.1"),
    ("ralston", 2, "Ralston (1962), Math. Comp. 16"),
    ("kutta3", 3, f"Kutta (1901); {HNW} Table II.1.1"),
    ("ssprk3", 3, "Shu & Osher (1988), J. Comput. Phys. 77"),
    ("rk4", 4, f"Kutta (1901); {HNW} Table II.1.2"),
    ("rk38", 4, f"Kutta (1901) 3/8 rule; {HNW} Table II.1.2"),
    ("butcher5", 5, "Butcher (1964), J. Austral. Math. Soc. 4"),
    ("dopri5", 5, f"Dormand & Prince (1980); {HNW} Table II.5.2"),
    ("gauss2", 4, f"Butcher (1964), Math. Comp. 18; {HW} Table IV.5.1: Gauss s stages, order 2s"),
    ("gauss3", 6, f"Butcher (1964); {HW} Table IV.5.2"),
    ("radau-iia3", 5, f"Ehle (1969); {HW} Table IV.5.6: Radau IIA s stages, order 2s-1"),
    ("lobatto-iiia3", 4, f"Ehle (1969); {HW} Table IV.5.7: Lobatto s stages, order 2s-2"),
    ("lobatto-iiic3", 4, f"Chipman (1971); {HW} Table IV.5.11"),
    ("feagin10", 10, "Feagin (2012), RK10(8)"),
    ("feagin12", 12, "Feagin (2012), RK12(10)"),
    ("curtis10", 10, "Curtis (1975), RK10(8)"),
    ("ono12", 12, "Ono (2006), RK12(9)"),
]

# Degenerate orders (over T_0) that follow from the literature:
# - the paper (§5.2): Euler 2, two stages 3, three stages 4, one implicit stage 3;
# - the bushy trees b[b^k] (k >= 2) lie in T_0 and their conditions are the quadrature
#   conditions sum b_i c_i^k = 1/(k+1); so a method whose quadrature order equals its classical
#   order p has degenerate order p: Gauss (quadrature order 2s), Radau IIA (2s-1), Lobatto (2s-2),
#   and RK4, whose quadrature is Simpson's rule (order 4); the midpoint rule and the trapezoidal
#   rule (order 2) give the explicit midpoint and Heun methods degenerate order 2.
DEGENERATE = [
    ("euler", 2), ("paper-two-stage", 3), ("paper-three-stage", 4), ("paper-implicit", 3),
    ("rk4", 4), ("gauss2", 4), ("gauss3", 6), ("radau-iia3", 5), ("lobatto-iiia3", 4),
    ("lobatto-iiic3", 4), ("midpoint", 2), ("heun", 2),
]


@pytest.mark.parametrize("name, order, source", LITERATURE)
def test_literature_orders(name, order, source):
    v = verify(name)
    assert v.order == order, source
    assert v.degenerate_order >= v.order  # T_0 is a subset of T
    assert v.claim_ok
    assert v.checked_up_to >= v.degenerate_order + 1  # every tree up to the order found + 1


@pytest.mark.parametrize("name, order", DEGENERATE)
def test_degenerate_orders(name, order):
    v = verify(name)
    assert v.degenerate_order == order
    assert len(v.failing["degenerate"]) > 0


def test_paper_methods_exactly():
    for name, general, degenerate in [("euler", 1, 2), ("paper-two-stage", 1, 3),
                                      ("paper-three-stage", 1, 4), ("paper-implicit", 1, 3)]:
        v = verify(name)
        assert (v.order, v.degenerate_order) == (general, degenerate)
        assert v.precision == "exact" and v.tolerance == 0.0
    v = verify("paper-three-stage")
    # order 5 over T_0: sum_i b_i c_i^4 = 11/27*0 + 16/27*(3/4)^4 = 3/16, so the residual is -1/80
    bushy = {f.label: e for f, e in zip(v.failing["degenerate"], v.failing_exact["degenerate"],
                                        strict=True)}
    assert bushy["b[b,b,b,b]"] == "-1/80"


def test_rk4_and_dop853():
    v = verify("rk4")
    assert (v.order, v.degenerate_order) == (4, 4)
    v = verify("dop853")  # Hairer, Norsett & Wanner §II.10: order 8 with 12 stages
    assert v.order == 8 and v.stages == 12 and v.precision == "29 digits"
    assert verify("dop853", precision="float").order == 8


def test_feagin14_float_checks_every_tree():
    # Feagin (2009): order 14. All 53,272 trees of order <= 14 pass, and order 15 is checked.
    v = verify("feagin14", precision="float")
    assert v.order == 14 and v.checked_up_to == 15
    assert sum(count_trees(n) for n in range(1, 15)) == 53272
    assert v.conditions_checked["general"] == 53272 + count_trees(15)
    assert v.conditions_checked["degenerate"] == sum(count_trees(n, True) for n in range(1, 16))


@pytest.mark.slow
def test_feagin14_sixty_digits():
    v = verify("feagin14")
    assert v.precision == "60 digits" and v.order == 14
    assert v.conditions_checked["general"] == 53272 + count_trees(15)
    # at 60 digits every tree of order 15 fails (the smallest residual is about 1e-20)
    assert len(v.failing["general"]) == count_trees(15)


def _perturbed(name, where, delta=Fraction(1, 10 ** 8)):
    t = load_tableau(name)
    A = [list(row) for row in t.A]
    b = list(t.b)
    if where[0] == "b":
        b[where[1]] = b[where[1]] + delta if isinstance(b[where[1]], Fraction) else \
            str(b[where[1]].as_fraction() + delta)
    else:
        i, j = where[1:]
        A[i][j] = A[i][j] + delta if isinstance(A[i][j], Fraction) else \
            str(A[i][j].as_fraction() + delta)
    return Tableau.from_arrays(A, b, name=f"{name}-perturbed")


@pytest.mark.parametrize("name, where, precision", [
    ("rk4", ("A", 2, 1), None), ("rk4", ("A", 2, 1), "float"), ("gauss2", ("b", 0), "float"),
    ("dop853", ("A", 5, 3), None), ("feagin14", ("A", 20, 0), "float"),
])
def test_a_perturbation_of_1e_8_loses_the_order(name, where, precision):
    original = verify(name, precision=precision)
    perturbed = verify(_perturbed(name, where), precision=precision)
    assert perturbed.order < original.order


def test_sixty_digits_see_what_float64_cannot():
    # a perturbation of 1e-30 is far below float64 rounding but far above the 60-digit tolerance
    perturbed = _perturbed("feagin10", ("b", 0), Fraction(1, 10 ** 30))
    assert verify(perturbed, precision="float").order == 10
    sixty = verify(perturbed)
    assert sixty.precision == "60 digits" and sixty.order == 0
    assert sixty.failing["general"][0].residual == pytest.approx(1e-30)


def test_claims_over_and_under_stated():
    t = load_tableau("rk4")
    over = Tableau.from_arrays(t.A, t.b, name="over", claimed_order=5, claimed_degenerate_order=4)
    v = verify(over)
    assert not v.claim_ok and v.claims == {"general": "overstated", "degenerate": "ok"}
    under = Tableau.from_arrays(t.A, t.b, name="under", claimed_order=3)
    assert verify(under).claims == {"general": "understated"}
    short = verify("rk4", max_order=3)
    assert short.order == 3 and short.is_lower_bound("general") and not short.claim_ok


@pytest.mark.parametrize("name", ["gauss3", "radau-iia3", "paper-three-stage", "rk4", "dopri5",
                                  "kutta3", "lobatto-iiic3", "dop853", "feagin10"])
def test_every_precision_agrees(name):
    exact = verify(name)
    for precision in ("float", 30, 80):
        other = verify(name, precision=precision)
        assert other.orders == exact.orders
        assert other.principal_error["general"] == pytest.approx(exact.principal_error["general"])


def test_precision_modes_and_tolerances():
    assert verify("rk4").precision == "exact"
    floats = Tableau.from_arrays([[0, 0], [2 / 3, 0]], [0.25, 0.75])  # 2/3 as a float
    v = verify(floats)
    assert v.precision == "float" and v.order == 2 and 0 < v.tolerance < 1e-11
    assert verify("rk4", precision=40).precision == "40 digits"
    with pytest.raises(InputError, match="exact precision needs exact entries"):
        verify("feagin10", precision="exact")
    with pytest.raises(InputError, match="precision"):
        verify("rk4", precision="fast")


def test_json_keys():
    doc = json_form(verify("paper-two-stage"))
    for key in ("name", "stages", "kind", "order", "degenerate_order", "checked_up_to",
                "precision", "tolerance", "principal_error", "failing", "claimed", "claim_ok"):
        assert key in doc
    assert set(doc["principal_error"]) >= {"general", "degenerate"}
    assert doc["failing"]["general"] == [{"tree": "b[b]", "residual": pytest.approx(0.0773502691896),
                                          "exact": "-1/2 + sqrt(3)/3"}]
    assert doc["claimed"] == {"order": None, "degenerate_order": 3, "symmetric_order": None}


def test_principal_error_is_the_weighted_norm():
    # Euler at order 2 over T: a(b[b]) = 0, residual -1/2, sigma = 1.
    v = verify("euler")
    assert v.principal_error["general"] == pytest.approx(0.5)
    # over T_0 at order 3: only b[b,b], residual -1/3, sigma 2
    assert v.principal_error["degenerate"] == pytest.approx(1 / 6)


def test_cli_verify_json_and_table(run_cli):
    rc, out, err = run_cli("verify", "paper-three-stage", "--format", "json")
    assert rc == 0, err
    doc = json.loads(out)
    assert (doc["order"]["order"], doc["degenerate_order"]["order"], doc["precision"]) == (1, 4, "exact")
    rc, out, err = run_cli("verify", "rk4", "--precision", "float")
    assert rc == 0 and "general (T)" in out and "b[b[b[b[b]]]]" in out


def test_cli_tables(run_cli):
    rc, out, err = run_cli("tables", "--format", "json")
    assert rc == 0, err
    rows = {r["name"]: r for r in json.loads(out)["tables"]}
    assert rows["feagin14"]["order"]["order"] == 14 and rows["paper-implicit"]["degenerate_order"]["order"] == 3
    assert all(r["claim_ok"] for r in rows.values())


@pytest.mark.parametrize("args, message", [
    (["verify", "feagn14"], "did you mean feagin12, feagin14?"),
    (["verify", "rk4", "--precision", "fast"], "precision must be"),
    (["verify", "rk4", "--max-order", "0"], "max order must be at least 1"),
])
def test_cli_bad_input_is_one_line(run_cli, args, message):
    rc, out, err = run_cli(*args)
    assert rc == 2 and out == "" and err.count("\n") == 1 and message in err


def test_cli_bad_file_names_the_file(run_cli, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('A = [["0", "0"], ["1"]]\nb = ["1", "0"]\n')
    rc, out, err = run_cli("verify", str(path))
    assert rc == 2 and err.count("\n") == 1 and str(path) in err and "not square" in err


def test_json_says_which_orders_are_lower_bounds(run_cli):
    # dop853 has order 8 (Hairer, Norsett & Wanner I, II.10); the symmetric relations ship up to
    # order 8, so its symmetric order is only known to be at least 8: the table says ">= 8"
    rc, out, err = run_cli("verify", "dop853", "--format", "json")
    doc = json.loads(out)
    assert doc["order"] == {"order": 8, "lower_bound": False}
    assert doc["symmetric_order"] == {"order": 8, "lower_bound": True}
    assert doc["orders"]["symmetric"] == doc["symmetric_order"]
    rc, out, err = run_cli("verify", "dop853")
    assert ">= 8" in out


# ----------------------------------------------------------------------------- nodepy's tableaux

DATA = Path(__file__).resolve().parent / "data"


def test_sdirk34_with_cos_pi_18_verifies_exactly_as_order_4():
    # Norsett's SDIRK34 (nodepy's coefficients, tests/data): order 4 (Norsett 1974; HW II, IV.6)
    v = verify(str(DATA / "nodepy-sdirk34.toml"))
    assert v.precision == "exact" and "cos(pi/18)" in v.tolerance_rule
    assert v.orders["general"] == 4 and v.claim_ok and v.approximate_orders is None


def test_rk58_rational_approximations_reach_order_5_at_their_precision(run_cli):
    # Kennedy, Carpenter & Lewis's RK5(4)8[3R+]C has order 5; nodepy's 13-digit rationals miss
    # sum b_i = 1 by 3.8e-27, far below what denominators of 13 digits pin down
    path = str(DATA / "nodepy-rk58-3r-c.toml")
    v = verify(path)
    assert v.orders["general"] == 0 and v.failing["general"][0].residual == pytest.approx(3.8e-27, rel=0.01)
    assert v.approximate_orders == {"general": 5, "degenerate": 5, "symmetric": 5}
    assert v.approximate.precision == "24 digits" and v.claims == {"general": "ok"}
    rc, out, err = run_cli("verify", path, "--format", "json")
    doc = json.loads(out)
    assert rc == 0 and doc["approximate_orders"]["general"] == {"order": 5, "lower_bound": False}
    rc, out, err = run_cli("verify", path)
    assert rc == 0 and "look like rational approximations" in out


def _nodepys_own(name: str):
    if name == "sdirk34":
        return pytest.importorskip("nodepy.runge_kutta_method").loadRKM("SDIRK34")
    return pytest.importorskip("nodepy.low_storage_rk").load_low_storage("RK58[3R]C")


@pytest.mark.parametrize("name", ["sdirk34", "rk58-3r-c"])
def test_the_copied_nodepy_tableaux_are_nodepys(name):
    # tests/data holds nodepy's coefficients so that the tests above run without nodepy; where the
    # bench extra installs it, the copies are compared with nodepy's own entries, exactly
    import sympy

    from rkhp.tableaux.tableau import as_sympy

    theirs = _nodepys_own(name)
    ours = load_tableau(str(DATA / f"nodepy-{name}.toml"))
    assert ours.stages == len(theirs.b)
    pairs = [*zip([x for row in ours.A for x in row], [x for row in theirs.A for x in row]), *zip(ours.b, theirs.b)]
    for mine, their in pairs:
        assert sympy.simplify(as_sympy(mine) - sympy.S(their)) == 0, (mine, their)


def test_entries_beyond_a_reachable_number_field_are_verified_at_digits(run_cli, tmp_path):
    # cos(pi/97)^2 + sin(pi/97)^2 = 1: Euler's weight written in a field of huge degree
    path = tmp_path / "big.toml"
    path.write_text('A = [["0"]]\nb = ["cos(pi/97)**2 + sin(pi/97)**2"]\n')
    v = verify(str(path))
    assert v.precision == "50 digits" and "no exact number field" in v.tolerance_rule
    assert v.orders["general"] == 1  # Euler
    rc, out, err = run_cli("verify", str(path), "--precision", "exact")
    assert rc == 2 and "no exact verification" in err and err.count("\n") == 1
