"""The field's reference problems (rkhp.systems.problems).

Values from outside the code: the vector fields as the sources write them (GeometricProblems.jl
v0.8.2: MasslessChargedParticle, PointVortices, LotkaVolterra4d; Flaschka's equations of the Toda
lattice; the Volterra lattice u_i' = u_i (u_(i+1) - u_(i-1)); the heavy top's Euler–Poisson
equations; Nambu's xdot = grad C x grad H), the reference values GeometricProblems.jl publishes,
and a solution computed with mpmath's Taylor-series ODE solver.
"""

from __future__ import annotations

import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.integrators import integrate_rkhp
from rkhp.studies.reference import reference
from rkhp.systems import builtin_systems, get_system
from rkhp.systems.problems import PROBLEMS, expressions, problem_data
from rkhp.systems.structure import check_structure

#: GeometricProblems.jl v0.8.2, src/point_vortices.jl and src/lotka_volterra_4d.jl:
#: `reference_solution` at t = dt * nt = 10 from the default q0
PUBLISHED = {
    "point-vortices": (0.18722529318641928, 0.38967432450068706, 0.38125332930294187,
                       0.4258020604293123),
    "lotka-volterra-4d": (0.5988695239096916, 2.068567531039674, 0.2804351458645534,
                          1.258449091830993),
}
#: mpmath.odefun (Taylor series) at 20 and at 30 digits (they agree to 20 digits), x(10) of the
#: charged particle from x0 = (1, 1): see test_charged_particle_mpmath_reference
CHARGED_PARTICLE_MPMATH = ("-1.1760476489103914646", "1.4959067160003578921")

SIZES = ["charged-particle", "point-vortices", "nambu", "heavy-top", "toda", "toda:12",
         "volterra-lattice", "volterra-lattice:6", "lotka-volterra-4d", "lv5-integrable",
         "lv5-nonintegrable"]


def system(name):
    return get_system(name)


@pytest.mark.parametrize("name", SIZES)
def test_structure_is_poisson_with_its_casimirs(name):
    data = problem_data(name)
    entries, _, casimirs = expressions(data)
    check = check_structure(entries, casimirs=casimirs, x0=data.x0)
    assert check.method == "symbolic"
    s = system(name)
    assert s.dim == data.dim and len(s.casimirs) == len(data.casimirs)


def test_builtin_list():
    names = builtin_systems()
    assert all(name in names for name in PROBLEMS)
    assert {problem_data(name).family for name in PROBLEMS} == {"general", "lie-poisson",
                                                                "log-canonical"}


def _source_fields():
    """The vector fields as the sources write them (numpy, independent of rkhp's tapes)."""
    def charged(q):  # E x B drift: v = (E2, -E1) / B, E = (sin q1, -cos q2)
        B = 1 + 2 * q[0] ** 2 + 2 * q[1] ** 2
        return np.array([-np.cos(q[1]), -np.sin(q[0])]) / B

    def vortices(q):
        g = 0.5
        S = lambda x, y: 1 + x * x + y * y
        S2 = lambda x, y: 1 + 2 * x * x + 2 * y * y
        d = (q[0] - q[2]) ** 2 + (q[1] - q[3]) ** 2
        L, c = np.log(d), g * g / (2 * np.pi)
        s12, s34 = S(q[0], q[1]), S(q[2], q[3])
        H1 = c * 2 * q[0] * s34 * L + c * s12 * s34 * 2 * (q[0] - q[2]) / d
        H2 = c * 2 * q[1] * s34 * L + c * s12 * s34 * 2 * (q[1] - q[3]) / d
        H3 = c * 2 * q[2] * s12 * L - c * s12 * s34 * 2 * (q[0] - q[2]) / d
        H4 = c * 2 * q[3] * s12 * L - c * s12 * s34 * 2 * (q[1] - q[3]) / d
        d1, d2 = 1 / (g * S2(q[0], q[1])), 1 / (g * S2(q[2], q[3]))
        return np.array([-H2 * d1, H1 * d1, -H4 * d2, H3 * d2])

    def nambu(x):
        gC = np.array([x[0], x[1], x[2] ** 3])
        gH = np.array([x[0] / 2, x[1], 1.5 * x[2]])
        return np.cross(gC, gH)

    def heavy_top(x):
        M, G = x[:3], x[3:]
        Omega = M / np.array([2.0, 1.0, 2.0 / 3.0])
        return np.concatenate([np.cross(M, Omega) + np.cross(G, [0.0, 0.0, 1.0]),
                               np.cross(G, Omega)])

    def flaschka(x):
        N = x.size // 2
        a, b = x[:N], x[N:]
        return np.concatenate([a * (np.roll(b, -1) - b), 2 * (a**2 - np.roll(a, 1) ** 2)])

    def volterra(u):
        return u * (np.roll(u, -1) - np.roll(u, 1))

    def lv4d(q):  # GeometricProblems.jl v1..v4, a = 1, b = (-1, -2, -1, -1)
        a, b = np.ones(4), np.array([-1.0, -2.0, -1.0, -1.0])
        return np.array([q[0] * (a[1] * q[1] + a[2] * q[2] + a[3] * q[3] + b[1] + b[2] + b[3]),
                         q[1] * (-a[0] * q[0] + a[2] * q[2] + a[3] * q[3] - b[0] + b[2] + b[3]),
                         q[2] * (-a[0] * q[0] - a[1] * q[1] + a[3] * q[3] - b[0] - b[1] + b[3]),
                         q[3] * (-a[0] * q[0] - a[1] * q[1] - a[2] * q[2] - b[0] - b[1] - b[2])])

    def lv5d_sign(x):  # Christodoulidi, Hone & Kouloukas: x_i' = x_i sum_j sign(j - i) (x_j - 1)
        return x * np.array([sum(np.sign(j - i) * (x[j] - 1) for j in range(5)) for i in range(5)])

    return {"lv5-integrable": volterra, "lv5-nonintegrable": lv5d_sign,
            "charged-particle": charged, "point-vortices": vortices, "nambu": nambu,
            "heavy-top": heavy_top, "toda": flaschka, "toda:12": flaschka,
            "volterra-lattice": volterra, "volterra-lattice:6": volterra,
            "lotka-volterra-4d": lv4d}


@pytest.mark.parametrize("name", SIZES)
def test_vector_field_is_the_sources(name):
    s = system(name)
    field = _source_fields()[name]
    rng = np.random.default_rng(4)
    for _ in range(5):
        x = np.asarray(s.x0) * rng.uniform(0.7, 1.3, s.dim) + 0.05 * rng.uniform(size=s.dim)
        assert np.allclose(s.vector_field(x), field(x), rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_reference_agrees_with_the_published_value(name):
    """rkhp's reference (DOP853, error estimated by a second solve) against GeometricProblems."""
    s = system(name)
    ref = reference(s, 10.0)
    gap = np.abs(ref.state - np.array(PUBLISHED[name])).max()
    assert ref.error_estimate < 1e-10
    assert gap < 1e-10, gap


def test_charged_particle_reference_against_mpmath():
    s = system("charged-particle")
    ref = reference(s, 10.0)
    exact = np.array([float(v) for v in CHARGED_PARTICLE_MPMATH])
    assert np.abs(ref.state - exact).max() <= max(10 * ref.error_estimate, 1e-14)


@pytest.mark.slow
def test_charged_particle_mpmath_reference():
    """Recompute CHARGED_PARTICLE_MPMATH: mpmath.odefun at 20 digits (about 15 s)."""
    import mpmath
    import sympy

    data = problem_data("charged-particle")
    P, H, _ = expressions(data)
    X = sorted(H.free_symbols, key=str)
    g = [sympy.diff(H, x) for x in X]
    F = sympy.lambdify(X, [sum(P[i][j] * g[j] for j in range(2)) for i in range(2)], "mpmath")
    with mpmath.workdps(20):
        y = mpmath.odefun(lambda t, v: F(*v), 0, [mpmath.mpf(v) for v in data.x0])(10)
        assert all(abs(y[i] - mpmath.mpf(CHARGED_PARTICLE_MPMATH[i])) < 1e-18 for i in range(2))


@pytest.mark.parametrize("name, steps, tolerance", [
    ("heavy-top", 200, 2e-5), ("toda", 200, 1e-6), ("volterra-lattice", 200, 2e-6),
    ("lotka-volterra-4d", 200, 5e-6), ("charged-particle", 200, 1e-9),
    ("point-vortices", 800, 1e-5), ("nambu", 200, 1e-8), ("lv5-integrable", 200, 2e-6),
    ("lv5-nonintegrable", 400, 1e-5)])
def test_rkhp_integration_against_reference(name, steps, tolerance):
    """paper-three-stage to T = 10 (h = 0.05; the point vortices, pre-asymptotic there, from
    h = 0.0125): the error against the reference falls by about 2^4 when h is halved, and the
    Casimirs are kept to round-off (closed forms, and the spray realisation evaluated to
    round-off)."""
    s = system(name)
    ref = reference(s, s.t_final)
    errors = []
    for n in (steps, 2 * steps):
        traj = integrate_rkhp(s, "paper-three-stage", s.t_final / n, n)
        assert traj.ok
        errors.append(np.abs(traj.final_state - ref.state).max())
    assert errors[0] < tolerance
    assert 2**3.5 < errors[0] / errors[1] < 2**4.5
    if s.casimirs:
        drift = np.abs(np.array([s.casimir_values(x) for x in traj.states])
                       - s.casimir_values(s.x0)).max()
        assert drift < 1e-13


def test_lotka_volterra_5d_integrals():
    """The integrable 5-d system keeps sum x_i and sum (x_i^2/2 + x_i x_(i+1)) (the Volterra
    lattice's integrals in involution, Suris 2003): both are orthogonal to its vector field, and
    {I1, I2} = 0 for its pi. The non-integrable one keeps H: grad H . f = 0."""
    s = system("lv5-integrable")
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = rng.uniform(0.3, 3.0, 5)
        grad1, grad2 = np.ones(5), x + np.roll(x, -1) + np.roll(x, 1)
        f = s.vector_field(x)
        assert abs(grad1 @ f) < 1e-13 and abs(grad2 @ f) < 1e-12
        assert abs(grad1 @ s.poisson(x) @ grad2) < 1e-12
        g = system("lv5-nonintegrable")
        assert abs((1 - 1 / x) @ g.vector_field(x)) < 1e-12


@pytest.mark.parametrize("name", ["lv5-integrable", "lv5-nonintegrable"])
def test_lotka_volterra_5d_euler_keeps_energy_and_casimir(name):
    """RKHP Euler (h = 0.01, 5000 steps to t = 50): the Casimir kept to round-off, the energy error
    bounded at O(h) (the first-order modified Hamiltonian, docs/theory.md §11): it does not grow
    from the first to the second half of the run."""
    s = system(name)
    traj = integrate_rkhp(s, "euler", 0.01, 5000)
    assert traj.ok
    casimir = np.array([s.casimir_values(x) for x in traj.states]) - s.casimir_values(s.x0)
    assert np.abs(casimir).max() < 1e-12
    energy = np.abs(np.array([s.hamiltonian(x) for x in traj.states]) - s.hamiltonian(np.asarray(s.x0)))
    first, second = energy[:2500].max(), energy[2500:].max()
    assert first < 0.05 and second < 1.5 * first


@pytest.mark.parametrize("name, message", [
    ("toda:7", "even integer n >= 6"), ("toda:4", "even integer n >= 6"),
    ("volterra-lattice:4", "integer n >= 5"), ("heavy-top:3", "no size parameter"),
    ("toda:x", "must be an integer")])
def test_bad_sizes(name, message):
    with pytest.raises(InputError, match=message):
        get_system(name)


def test_sizes_for_the_benchmark():
    for n in (6, 12, 24):
        s = get_system(f"toda:{n}")
        assert s.dim == n and s.family == "lie-poisson"
        assert abs(s.casimir_values(s.x0)[0]) < 1e-15  # sum b_i = 0 at x0
