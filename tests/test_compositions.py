"""Compositions of the symmetric RKHP Euler step (docs/compositions.md, docs/theory.md §12):
orders against the published ones, symmetry of RKHP methods, backward steps, the composed loop."""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.integrators.methods import integrate
from rkhp.tableaux.compositions import (
    Composition,
    builtin_compositions,
    composition_from_dict,
    composition_order,
    is_composition_name,
    letters,
    load_composition,
    verify_composition,
    words_of_weight,
)
from rkhp.tableaux.files import load_tableau
from rkhp.tableaux.symmetry import rkhp_symmetry
from rkhp.trees.relations import symmetric_condition_rows

YOSHIDA6 = "tests/data/yoshida6.toml"
#: published orders (Yoshida 1990; Suzuki 1990; Kahan & Li 1997; Sofroniou & Spaletta 2005)
PUBLISHED = {"tj4": (4, 3), "suzuki4": (4, 5), "tj6": (6, 9), "kahan-li6": (6, 9), "tj8": (8, 27),
             "kahan-li8": (8, 17), "sofroniou-spaletta10": (10, 35)}
#: processed compositions (Blanes, Casas & Murua 2006): effective order, kernel substeps, processor
#: substeps; their kernels alone are of order 4
PROCESSED = {"bcm6-s11": (6, 11, 12), "bcm6-s13": (6, 13, 12), "bcm8-s13": (8, 13, 20)}


def test_the_built_in_compositions_are_the_published_ones():
    assert sorted(builtin_compositions()) == sorted([*PUBLISHED, *PROCESSED])
    for name, (order, substeps) in PUBLISHED.items():
        comp = load_composition(name)
        result = composition_order(comp)
        assert (result.order, comp.substeps, comp.symmetric) == (order, substeps, True), name
        assert result.largest_failing > 1e-8, name  # the next order fails, not by round-off
        assert sum(comp.gamma_float) == pytest.approx(1.0, abs=1e-15)


def test_a_composition_from_the_literature_not_shipped_has_its_published_order():
    comp = load_composition(YOSHIDA6)
    assert (comp.name, comp.substeps, composition_order(comp).order) == ("yoshida6", 7, 6)


@pytest.mark.parametrize("p", [2, 4, 6])
def test_the_triple_jump_raises_the_order_by_two(p):
    """gamma = (g, 1 - 2g, g), g = 1/(2 - 2^(1/(p+1))) (HLW §II.4) on a symmetric base of order p;
    with p = 2, 4, 6 the rational approximations of g at 30 digits give order p + 2 to those
    digits, and the exact Fractions 1/2 + 1/2 give order 2 only."""
    import mpmath

    with mpmath.workdps(40):
        g = 1 / (2 - mpmath.mpf(2) ** (mpmath.mpf(1) / (p + 1)))
        text = [mpmath.nstr(x, 30) for x in (g, 1 - 2 * g, g)]
    comp = composition_from_dict({"gamma": text}, "jump", "test")
    assert composition_order(comp, base_order=p).order == p + 2
    half = Composition("halves", "euler", (Fraction(1, 2), Fraction(1, 2)))
    assert composition_order(half).order == 2


def test_the_words_of_the_conditions_count_the_compositions_into_odd_parts():
    """Words over the letters F_1, F_3, F_5, ... of weight n: compositions of n into odd parts,
    the Fibonacci numbers (OEIS A000045)."""
    fib = [1, 1, 1, 2, 3, 5, 8, 13, 21, 34, 55]
    for n in range(1, 11):
        assert len(words_of_weight(letters(2, True, 10), n)) == fib[n]


def test_a_non_symmetric_base_gets_every_power_of_h():
    """A symmetric gamma with a base of order 4 that is not symmetric gains nothing beyond the base's
    order from the odd powers (its h^5 and h^6 terms both count)."""
    assert letters(4, False, 8) == (1, 5, 6, 7, 8)
    comp = load_composition("tj4")
    assert composition_order(comp, 4, False).order >= 4
    assert composition_order(load_composition("kahan-li8"), 4, False).order < 8


def test_euler_is_the_symmetric_rkhp_method_and_others_are_not():
    """docs/theory.md §12 reports |Phi_{-h}(Phi_h(x)) - x| = 5.7e-18 for Euler, 1.7e-5, 1.4e-8, 2.6e-8 for
    paper-two-stage, paper-three-stage, gauss2: the first even order whose part of S_h is not zero
    is 4 for paper-two-stage and 6 for the others."""
    assert rkhp_symmetry(load_tableau("euler")).symmetric
    fails = {n: rkhp_symmetry(load_tableau(n)).fails_at for n in
             ("paper-two-stage", "paper-three-stage", "gauss2", "rk4")}
    assert fails == {"paper-two-stage": 4, "paper-three-stage": 6, "gauss2": 6, "rk4": 6}


def test_a_symmetric_rkhp_method_of_order_4_with_three_stages():
    """tables/symmetric-nodes-o4-s3: A = [[0], [g], [-g]], b = (1 - 2B, B, B), g = 1/2, B = 2/3
    (docs/compositions.md): every even-order row of S_h vanishes for any g and B, and 6 B g^2 = 1
    gives symmetric order 4. Checked exactly (orders, symmetry to order 8), numerically (40 steps
    of h = 0.25 forward and 40 back on the charged particle, a non-affine pi: back to x0 to
    round-off, where paper-three-stage misses by 3e-10), and as a composition base: the triple
    jump of a symmetric order-4 base has order 6 (Yoshida 1990)."""
    import dataclasses

    from rkhp.systems import get_system
    from rkhp.tableaux.compositions import class_composition_orders
    from rkhp.tableaux.verification import verify

    tab = load_tableau("symmetric-nodes-o4-s3")
    result = verify(tab, precision="exact")
    assert (result.orders["symmetric"], result.orders["degenerate"], result.orders["general"]) == (4, 3, 1)
    assert rkhp_symmetry(tab).symmetric and rkhp_symmetry(tab).checked_up_to == 8
    system = get_system("charged-particle")
    gaps = {}
    for name in ("symmetric-nodes-o4-s3", "paper-three-stage"):
        forward = integrate(system, name, 0.25, 40).states[-1]
        back = integrate(dataclasses.replace(system, x0=forward), name, -0.25, 40).states[-1]
        gaps[name] = float(np.abs(back - system.x0).max())
    assert gaps["symmetric-nodes-o4-s3"] < 1e-13 < 1e-11 < gaps["paper-three-stage"]
    g = "1/(2 - 2^(1/5))"
    jump = composition_from_dict({"gamma": [g, f"1 - 2*{g}", g], "base": "symmetric-nodes-o4-s3"}, "jump", "test")
    assert class_composition_orders(jump, tab)["symmetric"].order == 6


def test_the_exact_flow_is_symmetric_in_the_relations():
    """The exact flow's S_h is odd in h: its even-order parts are relations, i.e. every symmetric
    condition of even order has weights summing to zero (e(t) gamma(t) = 1)."""
    for n in range(2, 9, 2):
        assert all(sum(w) == 0 for _, w in symmetric_condition_rows(n))


def test_the_composed_loop_is_the_sequence_of_euler_substeps():
    comp = load_composition("suzuki4")
    h = 0.2
    from rkhp.systems import get_system

    y = np.array(get_system("rigid-body").x0, dtype=float)
    for g in comp.gamma_float:
        y = integrate("rigid-body", "euler", g * h, 1, x0=y).final_state
    composed = integrate("rigid-body", "suzuki4", h, 1).final_state
    assert np.abs(composed - y).max() < 1e-15


@pytest.mark.parametrize("system", ["charged-particle", "rigid-body"])
def test_forward_then_backward_returns_for_symmetric_methods(system):
    """100 steps forward, 100 back (negative h): kahan-li8 and euler return to x0 within 1e-13;
    paper-three-stage (not symmetric) does not."""
    for method, symmetric in (("euler", True), ("kahan-li8", True), ("paper-three-stage", False)):
        forward = integrate(system, method, 0.1, 100).raise_if_failed()
        back = integrate(system, method, -0.1, 100, x0=forward.final_state).raise_if_failed()
        gap = np.abs(back.final_state - forward.states[0]).max()
        assert (gap < 1e-13) == symmetric, (method, gap)


def _casimir_drift(method: str, steps: int) -> float:
    from rkhp.systems import get_system

    nambu = get_system("nambu")
    tr = integrate(nambu, method, 0.1, steps).raise_if_failed()
    c0 = nambu.casimir_values(tr.states[0])
    return max(float(np.abs(nambu.casimir_values(x) - c0).max()) for x in tr.states[:: max(1, steps // 1000)]
               ) / max(1.0, float(np.abs(c0).max()))


def test_compositions_keep_casimirs_on_nambu():
    assert _casimir_drift("kahan-li6", 200) < 1e-13


@pytest.mark.slow
@pytest.mark.parametrize("method", sorted(PUBLISHED))
def test_every_built_in_composition_keeps_the_casimir_over_1e5_steps(method):
    """Each substep keeps the Casimir to round-off (alpha(x, p) = y solved to an ulp, docs/theory.md
    §4): over N substeps the drift is a random walk of N ulps, about sqrt(N) eps; 1e-13 holds up to
    about 10^6 substeps (tj4 .. kahan-li6), the longer compositions stay within 4 sqrt(N) eps."""
    substeps = 100_000 * PUBLISHED[method][1]
    assert _casimir_drift(method, 100_000) < max(1e-13, 4.0 * np.sqrt(substeps) * np.finfo(float).eps)


def test_converge_confirms_the_orders_on_the_rigid_body(run_cli):
    code, out, err = run_cli("converge", "rigid-body", "--method", f"tj4,kahan-li6,{YOSHIDA6}", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    verdicts = {m["method"]: (m["expected_order"], m["verdict"]) for m in doc["methods"]}
    assert verdicts == {"tj4": (4, "confirmed"), "kahan-li6": (6, "confirmed"), YOSHIDA6: (6, "confirmed")}


#: the commands of docs/compositions.md "Convergence" that confirm the published orders (the steps
#: chosen where each composition's asymptotic range lies above the reference's accuracy; order 10
#: on nambu and the charged particle is not confirmed in double precision, the docs say why)
CONFIRMING = [
    ("rigid-body", "tj4,suzuki4,tj6,kahan-li6,tj8", ["--steps", "20", "--refinements", "3"]),
    ("rigid-body", "kahan-li8", ["--steps", "10", "--refinements", "3"]),
    ("charged-particle", "tj4,suzuki4,tj6,kahan-li6", ["--steps", "30", "--refinements", "3"]),
    # tj8's substeps reach 2.56 h forwards and 2.83 h backwards: at h = 1/3 their Newton fails here
    ("charged-particle", "tj8", ["--steps", "125,150,180,216,260"]),
    ("nambu", "tj4,suzuki4,tj6,kahan-li6", ["--steps", "20", "--refinements", "3"]),
    ("nambu", "kahan-li8", ["--steps", "12,15,18,21,25,30"]),
    ("nambu", "tj8", ["--steps", "80,100,125,160"]),
    # kahan-li8's 8 below DOP853's accuracy: the mpmath reference (docs/compositions.md)
    ("charged-particle", "kahan-li8", ["--reference", "mpmath", "--t-final", "3",
                                       "--steps", "16,19,23,27,32,38"]),
]

#: order 10, where double precision leaves no asymptotic range for the fit: the local orders
#: between the pre-asymptotic rows and the round-off floor (docs/compositions.md); on the rigid body
#: they still fall towards 10 (p + O(h^2)) where the errors reach round-off
ORDER_TEN = [
    ("rigid-body", ["--steps", "14,16,19,23,27"]),
    ("nambu", ["--reference", "mpmath", "--steps", "12,14,16,19,23"]),
    ("charged-particle", ["--reference", "mpmath", "--t-final", "3", "--steps", "8,9,10,11,12"]),
]


@pytest.mark.slow
@pytest.mark.parametrize("system,methods,steps", CONFIRMING)
def test_converge_confirms_the_published_orders(run_cli, system, methods, steps):
    code, out, err = run_cli("converge", system, "--method", methods, *steps, "--format", "json")
    assert code == 0, err
    verdicts = {m["method"]: (m["expected_order"], m["verdict"]) for m in json.loads(out)["methods"]}
    assert verdicts == {m: (PUBLISHED[m][0], "confirmed") for m in methods.split(",")}


@pytest.mark.slow
@pytest.mark.parametrize("system,steps", ORDER_TEN)
def test_order_ten_shows_in_the_local_orders(run_cli, system, steps):
    """sofroniou-spaletta10's published order 10 on the rigid body and a general pi: four
    successive local orders within 0.6 of 10 (an order-8 method shows 8); the fit's verdict is not asserted, the window
    above the round-off floor being too short for its asymptotic test."""
    code, out, err = run_cli("converge", system, "--method", "sofroniou-spaletta10", *steps, "--format", "json")
    assert code == 0, err
    (method,) = json.loads(out)["methods"]
    local = [row["local_order"] for row in method["rows"][1:]]
    assert method["expected_order"] == PUBLISHED["sofroniou-spaletta10"][0]
    assert len(local) == 4 and all(abs(p - 10) <= 0.6 for p in local), local


def test_converge_confirms_order_8_on_a_non_affine_pi(run_cli):
    code, out, err = run_cli("converge", "nambu", "--method", "kahan-li8", "--steps", "12,15,18,21,25,30",
                             "--format", "json")
    assert code == 0, err
    (method,) = json.loads(out)["methods"]
    assert (method["expected_order"], method["verdict"]) == (8, "confirmed")
    assert abs(method["observed_order"] - 8) < 0.2


def test_verify_and_show_a_composition(run_cli):
    code, out, _ = run_cli("verify", YOSHIDA6, "--format", "json")
    doc = json.loads(out)
    assert code == 0 and (doc["order"], doc["symmetric"], doc["base_symmetric"], doc["claim"]) == (6, True, True,
                                                                                                 "confirmed")
    assert doc["orders"]["symmetric"]["order"] == 6 and doc["orders"]["general"]["order"] == 1
    code, out, _ = run_cli("show", "kahan-li8", "--format", "json")
    doc = json.loads(out)
    assert code == 0 and (doc["kind"], doc["base"], doc["substeps"], doc["order"]) == ("composition", "euler", 17, 8)


def test_an_overstated_claim_fails_and_bad_files_are_refused(run_cli, tmp_path):
    over = tmp_path / "over.toml"
    over.write_text('kind = "composition"\norder = 6\ngamma = ["1/(2 - 2^(1/3))", "1 - 2/(2 - 2^(1/3))", '
                    '"1/(2 - 2^(1/3))"]\n')
    code, _, err = run_cli("verify", str(over))
    assert code == 1 and "overstated" in err and len(err.strip().splitlines()) == 1
    bad = {"sum.toml": 'kind = "composition"\ngamma = ["0.5", "0.6"]\n',
           "keys.toml": 'kind = "composition"\ngamma = ["1"]\nfoo = 1\n',
           "empty.toml": 'kind = "composition"\ngamma = []\n',
           "code.toml": 'kind = "composition"\ngamma = ["__import__(\'os\')"]\n',
           "many.toml": 'kind = "composition"\ngamma = [' + ", ".join(['"0.001"'] * 101) + "]\n"}
    for name, text in bad.items():
        path = tmp_path / name
        path.write_text(text)
        code, out, err = run_cli("integrate", "rigid-body", "--method", str(path), "--steps", "2")
        assert code == 2 and err.startswith("rkhp: error:") and len(err.strip().splitlines()) == 1, (name, err)


@pytest.mark.parametrize("args", [["compose", "x" * 300 + ",rk4"], ["compose", "x" * 300 + ".toml,rk4"],
                                  ["verify", "x" * 300 + ".json"]], ids=["name", "toml", "json"])
def test_a_name_no_file_can_have_is_one_line(run_cli, args):
    code, _, err = run_cli(*args)
    assert code == 2 and err.startswith("rkhp: error:") and len(err.strip().splitlines()) == 1, err


def test_negative_steps_in_the_cli(run_cli):
    code, out, _ = run_cli("integrate", "rigid-body", "--method", "tj4", "--h", "-0.1", "--format", "json")
    assert code == 0 and json.loads(out)["t_final"] == pytest.approx(-10.0)
    code, _, err = run_cli("integrate", "rigid-body", "--method", "tj4", "--h", "-0.1", "--t-final", "1")
    assert code == 2 and "opposite signs" in err
    code, _, err = run_cli("integrate", "rigid-body", "--method", "euler", "--h", "0")
    assert code == 2


def test_the_library_refuses_a_zero_step():
    with pytest.raises(InputError):
        integrate("rigid-body", "tj4", 0.0, 10)


def test_the_phase_of_a_composition_has_its_order(run_cli):
    """On the oscillator a composition of order p turns by theta(z) = z + O(z^(p+1)) (its phase is
    the sum over the substeps, docs/stability.md); decimal coefficients count to their digits."""
    code, out, err = run_cli("stability", "tj4,kahan-li6,sofroniou-spaletta10", "--order", "12", "--format", "json")
    assert code == 0, err
    orders = {m["method"]: (m["kind"], m["phase_order"]) for m in json.loads(out)["methods"]}
    assert orders == {"tj4": ("composition", 4), "kahan-li6": ("composition", 6),
                      "sofroniou-spaletta10": ("composition", 10)}


def test_verify_csv_and_tables_json_list_the_compositions(run_cli):
    # the triple jump (Yoshida 1990) is of order 4 with a symmetric base of order 2 and no better
    # than its base otherwise: order 1 with Euler on a general realisation
    code, out, _ = run_cli("verify", "tj4", "--format", "csv")
    assert code == 0 and out.startswith("# provenance: ")
    import csv

    rows = {r["case"]: r for r in csv.DictReader(out.splitlines()[1:])}
    assert rows["symmetric, order 2 (for claims)"]["order"] == "4"
    assert rows["euler on a general realisation"]["order"] == "1"
    code, out, _ = run_cli("tables", "--format", "json")
    assert code == 0
    doc = json.loads(out)
    assert sorted(doc) == ["compositions", "provenance", "tables"]
    orders = {c["name"]: c["order"] for c in doc["compositions"]}
    assert orders["tj4"] == 4 and orders["tj6"] == 6 and orders["kahan-li8"] == 8
    assert all(c["kind"] == "composition" and "provenance" not in c for c in doc["compositions"])


def test_verify_checks_a_claim_against_the_base_s_own_symmetric_order(run_cli, tmp_path):
    """Yoshida's triple jump g = 1/(2 - 2^(1/5)) of a symmetric base of order 4 has order 6 (Yoshida,
    Phys. Lett. A 150, 1990): `rkhp verify` confirms the file's `order = 6` with the base
    symmetric-nodes-o4-s3 (symmetric order 4), and refuses a claim of 8 naming that base order."""
    g = "1/(2 - 2^(1/5))"
    for claimed, code in ((6, 0), (8, 1)):
        path = tmp_path / f"jump{claimed}.toml"
        path.write_text(f'name = "jump"\nkind = "composition"\nbase = "symmetric-nodes-o4-s3"\norder = {claimed}\n'
                        f'gamma = ["{g}", "1 - 2*{g}", "{g}"]\n')
        status, out, err = run_cli("verify", str(path))
        assert status == code, (out, err)
        if code == 0:
            assert f"claimed order {claimed}: confirmed" in out
            doc = json.loads(run_cli("verify", str(path), "--format", "json")[1])
            assert (doc["own"]["order"], doc["own"]["base_order"], doc["claim"]) == (6, 4, "confirmed")
        else:
            assert "hold to order 6 with symmetric-nodes-o4-s3 of symmetric order 4" in err
    status, out, _ = run_cli("show", str(tmp_path / "jump6.toml"), "--format", "json")
    assert status == 0 and json.loads(out)["order"] == 6


# ----------------------------------------------------------------------------- processed compositions


@pytest.mark.parametrize("name", sorted(PROCESSED))
def test_a_processed_composition_has_its_published_effective_order(name):
    """The substeps of one processed step, P, K, P^-1, meet the conditions of the published
    effective order and fail the next by far more than the coefficients' digits allow; the kernel
    alone is of order 4 and symmetric, the processor's coefficients sum to 0."""
    order, kernel, processor = PROCESSED[name]
    comp = load_composition(name)
    result = composition_order(comp)
    assert (result.order, comp.substeps, len(comp.processor), comp.symmetric) == (order, kernel, processor, True)
    assert result.largest_failing > 1e-5
    alone = composition_order(Composition(name, "euler", comp.gamma))
    assert alone.order == 4 and alone.largest_failing > 1e-5
    assert sum(comp.gamma_float) == pytest.approx(1.0, abs=1e-15)
    assert sum(comp.processor_float) == pytest.approx(0.0, abs=1e-15)
    assert verify_composition(comp).kernel_order == 4


@pytest.mark.parametrize("name,steps", [("bcm6-s11", (40, 80)), ("bcm6-s13", (40, 80)), ("bcm8-s13", (20, 40))])
def test_a_processed_composition_converges_at_its_effective_order(name, steps):
    """The end-point error on the rigid body at T = 10 against its closed form (Jacobi elliptic
    functions) falls as h^p, p the published effective order; the kernel alone, without the
    processor, falls as h^4."""
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.reference import reference
    from rkhp.systems import get_system

    system = get_system("rigid-body")
    exact = reference(system, 10.0)
    assert exact.kind == "exact"
    method = resolve_method(name)
    errors = [np.linalg.norm(method.integrate(system, 10.0 / n, n, keep_all=False).final_state - exact.state)
              for n in steps]
    assert np.log2(errors[0] / errors[1]) == pytest.approx(PROCESSED[name][0], abs=0.5)
    kernel = Composition(name, "euler", method.composition.gamma)
    plain = [np.linalg.norm(integrate(system, resolve_method_of(kernel), 10.0 / n, n).final_state - exact.state)
             for n in steps]
    assert np.log2(plain[0] / plain[1]) == pytest.approx(4.0, abs=0.5)


def resolve_method_of(comp):
    from rkhp.integrators.methods import Method

    return Method(comp.name, "composition", load_tableau("euler"), composition=comp)


def test_the_processor_runs_once_and_its_inverse_at_the_output_only():
    """A processed run of n steps is the Euler substeps c_i |h| of the processor, n times the
    kernel's gamma_i h, and the inverse processor's -c_(m+1-i) |h|, in that order: the same state
    whether every state is kept (the inverse processor applied to each) or the last only."""
    from rkhp.tableaux.compositions import one_step

    comp = load_composition("bcm8-s13")
    h, n = 0.25, 6
    y = np.array(integrate("rigid-body", "euler", 1.0, 1).states[0], dtype=float)
    m = len(comp.processor)
    substeps = one_step(comp, float)
    for g in substeps[:m]:
        y = integrate("rigid-body", "euler", g * h, 1, x0=y).final_state
    for _ in range(n):
        for g in substeps[m:-m]:
            y = integrate("rigid-body", "euler", g * h, 1, x0=y).final_state
    for g in substeps[-m:]:
        y = integrate("rigid-body", "euler", g * h, 1, x0=y).final_state
    last = integrate("rigid-body", "bcm8-s13", h, n, keep_all=False)
    every = integrate("rigid-body", "bcm8-s13", h, n)
    assert np.abs(last.final_state - y).max() < 1e-14
    assert np.abs(every.final_state - last.final_state).max() < 1e-15
    assert len(every.states) == n + 1 and np.array_equal(every.states[0], last.states[0])
    # every kept state is the output of the run of that many steps
    third = integrate("rigid-body", "bcm8-s13", h, 3, keep_all=False)
    assert np.abs(every.states[3] - third.final_state).max() < 1e-15


def test_the_inverse_processor_starts_from_its_solutions_at_the_states_before():
    """With every state kept, P^-1 runs from each of the 50 states; each of its substeps starts
    from its own solutions at the states before, as a kernel substep starts from the steps before,
    so on toda (a chord form) the matrices of its 20 substeps are built fewer times than the states
    it runs from, and the run reports the matrices of all its substeps (the kernel's too)."""
    _, kernel, processor = PROCESSED["bcm8-s13"]
    every = integrate("toda", "bcm8-s13", 0.2, 50).raise_if_failed()
    built = np.array(every.extra["refreshes"])
    assert built.size == kernel + 2 * processor
    assert built[-processor:].sum() < 50
    assert np.all(built[processor:-processor] >= 1)


@pytest.mark.parametrize("system", ["charged-particle", "rigid-body"])
def test_a_processed_composition_retraces_itself(system):
    """The processor is taken at |h|: a run back with -h is the inverse of the run forward (the
    kernel is symmetric), 100 steps of h = 0.1 each way come back to x0 to round-off."""
    for method in sorted(PROCESSED):
        forward = integrate(system, method, 0.1, 100).raise_if_failed()
        back = integrate(system, method, -0.1, 100, x0=forward.final_state).raise_if_failed()
        assert np.abs(back.final_state - forward.states[0]).max() < 1e-13, method


def test_a_processed_composition_keeps_the_casimirs_on_nambu():
    """Processor, kernel and inverse processor are RKHP Euler substeps, each a Poisson map: the
    Casimir stays at round-off over the run, at every kept state."""
    assert _casimir_drift("bcm8-s13", 200) < 1e-13
    assert _casimir_drift("bcm6-s11", 200) < 1e-13


def test_a_processor_must_sum_to_zero_and_fit(run_cli, tmp_path):
    good = load_composition("bcm6-s11")
    base = {"gamma": good.gamma_text()}
    bad_sum = tmp_path / "bad.toml"
    bad_sum.write_text(_toml({**base, "processor": ["0.5", "-0.25"]}))
    with pytest.raises(InputError, match="processor's coefficients sum to 0.25"):
        load_composition(str(bad_sum))
    code, _, err = run_cli("verify", str(bad_sum))
    assert code == 2 and "not 0" in err and "Traceback" not in err
    long = tmp_path / "long.toml"
    long.write_text(_toml({**base, "processor": ["0.5", "-0.5"] * 25}))
    with pytest.raises(InputError, match="more than 100"):
        load_composition(str(long))
    word = tmp_path / "word.toml"
    word.write_text('gamma = ["1"]\nprocessor = "0.5"\n')
    with pytest.raises(InputError, match="processor must be a list"):
        load_composition(str(word))


def test_coefficients_beyond_the_float_range_have_exact_orders():
    """gamma_1 = -gamma_2 = 1e300: F_3's coefficient 1e900 - 1e900 + 1 is exact, the residual of the
    general class's order 2 (F_1 F_1 and F_2, of size 1e600) is beyond the float range."""
    huge = composition_from_dict({"gamma": ["1e300", "-1e300", "1"]}, "huge", "test")
    symmetric, general = composition_order(huge, 2, True), composition_order(huge, 1, False)
    assert (symmetric.order, symmetric.largest_failing) == (2, 1.0)
    assert (general.order, general.largest_failing) == (1, float("inf"))
    processed = composition_from_dict({"gamma": ["1"], "processor": ["1e308", "-1e308"]}, "processed", "test")
    assert composition_order(processed, 1, False).largest_failing == float("inf")


@pytest.mark.parametrize("data, message", [
    ({"gamma": ["1e400", "1"]}, "coefficients sum to 1.0e[+]400, not 1"),
    ({"gamma": ["1"], "processor": ["1e400", "1"]}, "processor's coefficients sum to 1.0e[+]400, not 0"),
])
def test_sums_beyond_the_float_range_are_named(data, message):
    with pytest.raises(InputError, match=message):
        composition_from_dict(data, "huge", "test")


def test_a_json_composition_file_is_a_composition(run_cli, tmp_path):
    path = tmp_path / "halves.json"
    path.write_text(json.dumps({"kind": "composition", "gamma": ["1/2", "1/2"]}))
    assert is_composition_name(str(path)) and load_composition(str(path)).gamma == (Fraction(1, 2),) * 2
    code, out, _ = run_cli("show", str(path), "--format", "json")
    assert code == 0 and json.loads(out)["kind"] == "composition"
    bad = tmp_path / "bad.json"
    bad.write_text('{"kind": "composition", "gamma": ["1"],}')
    with pytest.raises(InputError, match=f"{bad}: JSON syntax error"):
        load_composition(str(bad))


def _toml(data: dict) -> str:
    return "".join(f"{k} = [{', '.join(repr(v) for v in vs)}]\n" for k, vs in data.items())


def test_verify_reports_the_processor_and_the_kernel_s_order(run_cli):
    code, out, _ = run_cli("verify", "bcm8-s13", "--format", "json")
    assert code == 0
    doc = json.loads(out)
    assert (doc["order"], doc["kernel_order"], doc["claim"], doc["substeps"]) == (8, 4, "confirmed", 13)
    assert len(doc["processor"]) == len(doc["processor_float"]) == 20
    code, out, _ = run_cli("verify", "kahan-li8", "--format", "json")
    doc = json.loads(out)
    assert (doc["processor"], doc["kernel_order"]) == ([], 8)
