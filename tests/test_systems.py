"""Poisson systems, birealisations, spec files and `rkhp systems` / `rkhp check`."""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.base.errors import InputError
from rkhp.systems import builtin_systems, get_system
from rkhp.systems.check import check_birealisation

BUILTINS = ("rigid-body", "lotka-volterra", "pendulum", "charged-particle", "point-vortices",
            "nambu", "heavy-top", "toda", "volterra-lattice", "lotka-volterra-4d", "lv5-integrable",
            "lv5-nonintegrable")
SPEC_RIGID_BODY = """
name = "rigid-body-spec"
family = "lie-poisson"
structure_constants = [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
x0 = [0.45359612142557731, 0.0, 0.89120736006143542]
casimirs = ["(x1^2 + x2^2 + x3^2)/2"]
"""
SPEC_LV = ('{"family": "log-canonical", "lambda": [[0,1,2],[-1,0,1],[-2,-1,0]], '
           '"hamiltonian": "x1 + x2 + x3 - log(x1) - log(x2) - log(x3)", "x0": [0.5, 1, 2]}')
SPEC_PENDULUM = """
family = "constant"
poisson = [[0, 1], [-1, 0]]
hamiltonian = "x2^2/2 - cos(x1)"
x0 = [1.5, 0.0]
"""


def test_builtin_names():
    assert builtin_systems() == BUILTINS


@pytest.mark.parametrize("realisation", ["symmetric", "shifted"])
@pytest.mark.parametrize("name", BUILTINS)
def test_birealisation_axioms(name, realisation):
    """rkhp check passes (deviations <= 1e-12); degenerate exactly for the symmetric kind."""
    result = check_birealisation(get_system(name, realisation), samples=40, seed=3)
    assert result.ok, result.deviations
    assert max(result.deviations.values()) <= 1e-12
    assert result.degenerate == (realisation == "symmetric")


def _rigid_alpha_mp(x, p):
    x = [mpmath.mpf(float(v)) for v in x]
    p = [mpmath.mpf(float(v)) for v in p]

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    r = mpmath.sqrt(sum(v * v for v in p))
    c = (1 - (r / 2) * mpmath.cot(r / 2)) / r**2
    px = cross(p, x)
    ppx = cross(p, px)
    return [x[i] + px[i] / 2 + c * ppx[i] for i in range(3)]


def test_rigid_body_alpha_against_mpmath():
    """Relative error <= 1e-15 for |p| from 1e-12 to 6 (docs/theory.md §4; the closed form alone loses
    every digit for small |p|)."""
    mpmath.mp.dps = 40
    system = get_system("rigid-body")
    rng = np.random.default_rng(7)
    worst = 0.0
    for r in np.concatenate([np.logspace(-12, math.log10(6.0), 40), [2.0, 6.0]]):
        for _ in range(3):
            x = rng.normal(size=3)
            d = rng.normal(size=3)
            p = r * d / np.linalg.norm(d)
            exact = _rigid_alpha_mp(x, p)
            got = system.alpha(x, p)
            err = max(abs(mpmath.mpf(float(got[i])) - exact[i]) for i in range(3))
            worst = max(worst, float(err / max(abs(v) for v in exact)))
    assert worst <= 1e-15


def test_rigid_body_c_taylor_coefficients():
    """The Taylor coefficients of c(u) (series below u = 20, pole and rest above) against mpmath."""
    from rkhp.taylor.elementary import crb_coef

    mpmath.mp.dps = 40

    def c(u):
        r = mpmath.sqrt(u)
        return (1 - (r / 2) * mpmath.cot(r / 2)) / u

    for u0 in (1e-6, 0.5, 3.9, 4.1, 10.0, 19.9, 20.1, 30.0, 36.0):
        coef = np.zeros(5)
        crb_coef(u0, 0.0, 4, coef)
        for m in range(5):
            exact = mpmath.diff(c, mpmath.mpf(u0), m) / mpmath.factorial(m)
            assert abs(coef[m] - float(exact)) <= 1e-13 * abs(float(exact)), (u0, m)


def test_rigid_body_c_near_the_pole():
    """c's Taylor coefficients up to degree 8 between u = 20 and the pole u = (2 pi)^2 (the pole's
    part plus the rest's series) to a few units of round-off against mpmath at 50 digits, with u
    given as a double-double u0 + u_lo; NaN at and beyond the pole and for u <= -20."""
    from rkhp.taylor.elementary import crb_coef

    mpmath.mp.dps = 50

    def c(u):
        r = mpmath.sqrt(u)
        return (1 - (r / 2) * mpmath.cot(r / 2)) / u

    D = 8
    coef = np.zeros(D + 1)
    for u0 in (20.0, 25.0, 30.0, 35.0, 39.0, 39.4, 39.47, 39.478):
        for u_lo in (0.0, 3e-15):
            crb_coef(u0, u_lo, D, coef)
            exact = mpmath.taylor(c, mpmath.mpf(u0) + mpmath.mpf(u_lo), D)
            for m in range(D + 1):
                assert abs(coef[m] - exact[m]) <= 2e-15 * abs(exact[m]), (u0, u_lo, m)
    pole = 4 * mpmath.pi ** 2
    pole_hi = float(pole)
    for u0, u_lo in ((pole_hi, float(pole - pole_hi)), (40.0, 0.0), (-20.0, 0.0), (-30.0, 0.0)):
        crb_coef(u0, u_lo, D, coef)
        assert np.isnan(coef).all(), u0


def test_rigid_body_exact_solution_against_dop853():
    from scipy.integrate import solve_ivp

    system = get_system("rigid-body")
    ts = np.linspace(0.0, 10.0, 11)
    sol = solve_ivp(lambda t, x: system.poisson(x) @ (x / np.array([2.0, 1.0, 2.0 / 3.0])),
                    (0, 10), system.x0, method="DOP853", rtol=1e-13, atol=1e-13, t_eval=ts)
    assert np.abs(system.exact_solution(ts) - sol.y.T).max() < 1e-11


def test_numpy_callables():
    s = get_system("lotka-volterra")
    x = np.array([0.7, 1.3, 0.4])
    assert s.hamiltonian(x) == pytest.approx(np.sum(x - np.log(x)), rel=1e-15)
    assert np.allclose(s.grad_hamiltonian(x), 1 - 1 / x, rtol=1e-15, atol=0)
    lam = np.array([[0, 1, 2], [-1, 0, 1], [-2, -1, 0]], dtype=float)
    assert np.allclose(s.vector_field(x), (lam * np.outer(x, x)) @ (1 - 1 / x), atol=1e-15)
    p = np.array([0.1, -0.2, 0.05])
    assert np.allclose(s.alpha(x, p), x * np.exp(-0.5 * lam @ (x * p)), rtol=1e-15)
    assert np.allclose(s.beta(x, p), x * np.exp(0.5 * lam @ (x * p)), rtol=1e-15)


def test_shifted_realisation_is_documented_composition():
    from rkhp.systems import shift_matrix

    sym, shifted = get_system("pendulum"), get_system("pendulum", "shifted")
    x, p = np.array([0.3, -0.2]), np.array([0.4, 0.1])
    Q = shift_matrix(2)
    assert np.allclose(Q, Q.T)
    assert np.allclose(shifted.alpha(x, p), sym.alpha(x + Q @ p, p), atol=1e-16)
    assert np.allclose(shifted.beta(x, p), sym.beta(x + Q @ p, p), atol=1e-16)


@pytest.mark.parametrize("text,suffix,builtin", [(SPEC_RIGID_BODY, ".toml", "rigid-body"),
                                                 (SPEC_LV, ".json", "lotka-volterra"),
                                                 (SPEC_PENDULUM, ".toml", "pendulum")])
def test_spec_file_reproduces_builtin(tmp_path, text, suffix, builtin):
    path = tmp_path / f"system{suffix}"
    path.write_text(text)
    rng = np.random.default_rng(0)
    for realisation in ("symmetric", "shifted"):
        spec, ref = get_system(path, realisation), get_system(builtin, realisation)
        assert (spec.family, spec.dim, spec.degenerate) == (ref.family, ref.dim, ref.degenerate)
        for _ in range(5):
            x = ref.x0 * rng.uniform(0.6, 1.4, ref.dim) + 0.1
            p = rng.uniform(-0.7, 0.7, ref.dim)
            assert spec.hamiltonian(x) == pytest.approx(ref.hamiltonian(x), rel=1e-14)
            assert np.allclose(spec.alpha(x, p), ref.alpha(x, p), rtol=1e-14, atol=1e-15)
            assert np.allclose(spec.beta(x, p), ref.beta(x, p), rtol=1e-14, atol=1e-15)
            assert np.allclose(spec.poisson(x), ref.poisson(x), atol=1e-15)
        assert check_birealisation(spec, samples=20).ok


@pytest.mark.parametrize("text,message", [
    ('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "y^2"\nx0 = [1, 0]',
     "unknown symbol"),
    ('family = "constant"\npoisson = [[0, 1], [1, 0]]\nhamiltonian = "x1^2"\nx0 = [1, 0]',
     "not antisymmetric"),
    ('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "x1^2"\nx0 = [1, 0, 2]',
     "x0 has 3 entries but poisson is 2 x 2"),
    ('family = "lie-poisson"\nstructure_constants = [[1, 4, 2, 1]]\nhamiltonian = "x1"\n'
     'x0 = [1, 0, 2]', "indices"),
    ('family = "banana"\nhamiltonian = "x1"\nx0 = [1]', "family must be"),
    ('family = "log-canonical"\nlambda = [[0, 1], [-1, 0]]\nhamiltonian = "x1"\nx0 = [1, -1]',
     "outside the domain"),
    ('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "x1 +"\nx0 = [1, 0]',
     "syntax error"),
    ('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nx0 = [1, 0]', "missing key"),
    ('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "gamma(x1)"\n'
     'x0 = [1, 0]', "call of gamma"),
    ('family = "log-canonical"\nlambda = [[0, 1e308], [-1e308, 0]]\nhamiltonian = "x1 + x2"\nx0 = [1, 2]',
     r"the structure pi of bad is not finite at x0 = \[1.0, 2.0\]: entry \(1, 2\) is inf"),
])
def test_spec_file_errors(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        get_system(path)


@pytest.mark.parametrize("name", ["x" * 300 + ".toml", "/".join(["x" * 200] * 30) + ".json"], ids=["name", "path"])
def test_a_spec_file_name_no_file_can_have_is_not_found(name):
    with pytest.raises(InputError, match="not found"):
        get_system(name)


def test_unknown_system_suggests():
    with pytest.raises(InputError, match="did you mean rigid-body"):
        get_system("rigid-bod")


def test_cli_systems_and_check_json():
    runner = CliRunner()
    res = runner.invoke(rkhp, ["systems", "--format", "json"])
    assert res.exit_code == 0
    assert [r["name"] for r in json.loads(res.output)["systems"]] == list(BUILTINS)
    res = runner.invoke(rkhp, ["check", "lotka-volterra", "--realisation", "shifted",
                               "--samples", "10", "--format", "json"])
    assert res.exit_code == 0
    doc = json.loads(res.output)
    keys = ["system", "realisation", "degenerate", "samples", "deviations", "ok"]
    assert [k for k in doc if k in keys] == keys  # the documented keys, in order (others may follow)
    assert list(doc["deviations"]) == ["identity", "poisson", "anti_poisson", "commute"]
    assert doc["ok"] is True and doc["degenerate"] is False and doc["samples"] == 10


def test_cli_check_bad_input(tmp_path):
    runner = CliRunner()
    res = runner.invoke(rkhp, ["check", "nosuch"])
    assert res.exit_code == 2
    res = runner.invoke(rkhp, ["check", "pendulum", "--samples", "0"])
    assert res.exit_code == 2


def test_check_json_holds_every_deviation_of_its_table(run_cli):
    rc, out, err = run_cli("check", "rigid-body", "--samples", "5", "--format", "json")
    doc = json.loads(out)
    assert rc == 0 and doc["seed"] == 0 and doc["tolerance"] == 1e-12
    # the symmetric realisation (docs/theory.md §4): d_p alpha(x, 0) = -pi(x) / 2 is
    # antisymmetric and beta(x, p) = alpha(x, -p), both to round-off
    assert doc["degeneracy"] < 1e-14 and doc["symmetry"] < 1e-14
    rc, table, err = run_cli("check", "rigid-body", "--samples", "5")
    assert f"{doc['degeneracy']:.2e}" in table and f"{doc['symmetry']:.2e}" in table


@pytest.mark.parametrize("given", [
    [math.cos(1.1), 0.0, math.sin(1.1)], (math.cos(1.1), 0, math.sin(1.1)),
    np.array([math.cos(1.1), 0.0, math.sin(1.1)]), np.array([math.cos(1.1), 0.0, math.sin(1.1)], np.float32)])
def test_a_start_is_checked_the_same_as_a_list_or_an_array(given):
    """`start` and `with_x0` take a start as a list, a tuple or an array of reals alike: a new
    float64 vector, the system's own object left as it is."""
    system = get_system("rigid-body")
    start = system.start(given)
    assert start.dtype == np.float64 and start.shape == (3,)
    assert np.array_equal(start, np.asarray(given, dtype=np.float64))
    assert start is not given and np.array_equal(system.with_x0(given).x0, start)
    start[0] = 5.0
    assert system.x0[0] != 5.0


@pytest.mark.parametrize("name, given, message", [
    ("rigid-body", np.array([0.4, np.nan, 0.9]), r"x0\[1\] must be finite"),
    ("rigid-body", np.array([0.4, 0.0, np.inf]), r"x0\[2\] must be finite"),
    ("rigid-body", np.array([True, False, True]), r"x0\[0\] must be a real number, got bool"),
    ("rigid-body", np.array([[0.4, 0.0, 0.9]]), "array of shape"),
    ("rigid-body", np.array([0.4, 0.0]), "x0 has 2 components; rigid-body has dimension 3"),
    ("rigid-body", np.array(["0.4", "0", "0.9"]), r"x0\[0\] must be a real number, got str_"),
    ("lotka-volterra", np.array([1.0, -0.5, 2.0]), r"outside the domain \(positive orthant\)"),
])
def test_a_bad_start_is_refused_naming_what_is_wrong(name, given, message):
    """An array start is refused as a list is: the component that is not a finite real, the
    size, the domain (InputError, which the commands turn into exit 2)."""
    system = get_system(name)
    for check in (system.start, system.with_x0):
        with pytest.raises(InputError, match=message):
            check(given)


@pytest.mark.parametrize("name, given, message", [
    ("pendulum", [0.0, 1e308], r"x0: hamiltonian of pendulum is not finite at x0 = \[0.0, 1e\+308\]: its value is inf"),
    ("rigid-body", [1e154, 1e154, 1e154], "x0: casimir 1 of rigid-body is not finite"),
    ("lotka-volterra", [1e200, 1e200, 1e200], r"x0: the structure pi of lotka-volterra is not finite"),
])
def test_a_start_where_the_system_overflows_is_refused(name, given, message):
    """A start in the domain where H, grad H, a Casimir or pi is not a float64 number: no step can
    be taken from it (and scipy's probe of the failed step would get a step size that is NaN)."""
    from rkhp.integrators.methods import resolve_system

    with pytest.raises(InputError, match=message) as info:
        resolve_system(name, x0=given)
    assert "\n" not in str(info.value)

