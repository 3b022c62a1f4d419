"""The peers of `rkhp bench` and benchmarks/work_precision.py: their fields (rkhp.systems.field_code)
against the equations of the sources and rkhp's own field, their end states against the rigid
body's closed form, and the race on a tiny setting. The compiled peers (numbalsoda, diffrax) are
the optional extra `peers`: their tests skip, with the reason, where it is absent."""

from __future__ import annotations

import ctypes
import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy

from rkhp.base.errors import InputError
from rkhp.base.json_form import json_form
from rkhp.studies import bench as B
from rkhp.studies import peers as P
from rkhp.systems import get_system
from rkhp.systems.builtins import builtin_systems, rigid_body_exact
from rkhp.systems.field_code import code_of, compiled, field_code

ROOT = Path(__file__).resolve().parent.parent
VORTICES = ROOT / "benchmarks" / "data" / "vortices-8.toml"
SYSTEMS = (*builtin_systems(), "toda:12", str(VORTICES))


def _points(system, count=3, seed=1):
    """Seeded points near x0, inside the domain."""
    rng = np.random.default_rng(seed)
    x0 = np.asarray(system.x0, dtype=float)
    return [x0 * np.exp(0.1 * rng.standard_normal(x0.size)) if system.domain != "R^n"
            else x0 + 0.1 * rng.standard_normal(x0.size) for _ in range(count)]


def _plain(name):
    system = get_system(name)
    return system, P.plain_field(system)


# ----------------------------------------------------------------------------------------------
# the plain field against the sources' equations


def test_rigid_body_field_is_eulers_equations():
    system, f = _plain("rigid-body")
    a = 1 / np.array([2.0, 1.0, 2 / 3])  # 1/I
    for x in _points(system):
        x1, x2, x3 = x
        euler = [(a[2] - a[1]) * x2 * x3, (a[0] - a[2]) * x3 * x1, (a[1] - a[0]) * x1 * x2]
        np.testing.assert_allclose(f(0.0, x), euler, rtol=1e-14, atol=1e-15)


def test_lotka_volterra_field():
    # x_i' = x_i sum_j lambda_ij x_j (1 - 1/x_j): pi_ij = lambda_ij x_i x_j, H = sum (x - log x)
    system, f = _plain("lotka-volterra")
    L = np.array([[0, 1, 2], [-1, 0, 1], [-2, -1, 0]], dtype=float)
    for x in _points(system):
        np.testing.assert_allclose(f(0.0, x), x * (L @ (x - 1)), rtol=1e-13)


def test_charged_particle_field_is_the_drift():
    # GeometricProblems.jl: xdot = (E2, -E1) / B, E = -grad(cos x1 + sin x2), B = 1 + 2|x|^2
    system, f = _plain("charged-particle")
    for x1, x2 in _points(system):
        B = 1 + 2 * x1**2 + 2 * x2**2
        E1, E2 = math.sin(x1), -math.cos(x2)
        np.testing.assert_allclose(f(0.0, np.array([x1, x2])), [E2 / B, -E1 / B], rtol=1e-14)


def test_nambu_field_is_grad_c_cross_grad_h():
    system, f = _plain("nambu")
    for x in _points(system):
        grad_c = [x[0], x[1], x[2] ** 3]
        grad_h = [x[0] / 2, x[1], 1.5 * x[2]]
        np.testing.assert_allclose(f(0.0, x), np.cross(grad_c, grad_h), rtol=1e-14, atol=1e-15)


def test_toda_field_is_flaschkas_equations():
    # a_i' = a_i (b_(i+1) - b_i), b_i' = 2 (a_i^2 - a_(i-1)^2), indices mod N (Flaschka 1974)
    system, f = _plain("toda:12")
    for x in _points(system):
        a, b = x[:6], x[6:]
        want = np.concatenate([a * (np.roll(b, -1) - b), 2 * (a**2 - np.roll(a, 1) ** 2)])
        np.testing.assert_allclose(f(0.0, x), want, rtol=1e-13, atol=1e-15)


def test_vortices_spec_field_is_the_point_vortex_model():
    # four vortices of strength 1/2 (benchmarks/data/vortices-8.toml): q_k' = J grad_k H / (S2(q_k) / 2)
    system, f = _plain(str(VORTICES))
    H = sympy.sympify(system.extra["expressions"][1][0][1])
    symbols = system.extra["expressions"][0]
    grad = sympy.lambdify(symbols, [sympy.diff(H, s) for s in symbols], "math")
    for x in _points(system):
        g = grad(*x)
        want = []
        for k in range(4):
            s2 = 0.5 * (1 + 2 * x[2 * k] ** 2 + 2 * x[2 * k + 1] ** 2)
            want += [-g[2 * k + 1] / s2, g[2 * k] / s2]
        np.testing.assert_allclose(f(0.0, x), want, rtol=1e-12)


@pytest.mark.parametrize("name", SYSTEMS)
def test_plain_field_agrees_with_rkhps_field(name):
    system, f = _plain(name)
    for x in _points(system):
        want = system.vector_field(x)
        np.testing.assert_allclose(f(0.0, x), want, rtol=1e-12, atol=1e-14 * max(1.0, np.abs(want).max()))


def test_field_code_refuses_what_is_not_arithmetic():
    x = sympy.symbols("x1 x2", real=True)
    with pytest.raises(InputError, match="no plain-arithmetic form"):
        code_of(x, [sympy.Function("evil")(x[0]), x[1]], "numpy")
    with pytest.raises(InputError, match="unknown form"):
        field_code(get_system("pendulum"), "fortran")


def test_constants_beyond_int64_are_printed_as_their_floats():
    """A spec's 1e19 and 1e-19 are read exactly (10^19, 1/10^19), beyond the int64 literals
    numba types: they are printed as float64 literals, exact here, and the cfunc form compiles."""
    import numba

    x = sympy.symbols("x1 x2", real=True)
    exprs = [sympy.Integer(10**19) * x[1], sympy.Rational(1, 10**19) * x[0] + sympy.Rational(-3, 7)]
    code = code_of(x, exprs, "cfunc")
    assert "10000000000000000000" not in code.source and "1e+19" in code.source
    rhs = numba.cfunc("void(float64, CPointer(float64), CPointer(float64), CPointer(float64))")(compiled(code))
    pointer = ctypes.POINTER(ctypes.c_double)
    u, du, p = np.array([2.0, 3.0]), np.empty(2), np.zeros(1)
    rhs.ctypes(0.0, u.ctypes.data_as(pointer), du.ctypes.data_as(pointer), p.ctypes.data_as(pointer))
    assert du.tolist() == [3e19, 2e-19 - 3 / 7]
    with pytest.raises(InputError, match="beyond the float range"):
        code_of(x, [sympy.Integer(10) ** 400 * x[0], x[1]], "numpy")


# ----------------------------------------------------------------------------------------------
# the peers' end states against the rigid body's closed form (Jacobi elliptic functions)


def _missing(name):
    return P.absent(B.peer_of(B.resolve_peer(name)))


@pytest.mark.parametrize("name", ["scipy:dop853", *P.COMPILED_PEERS])
def test_peer_reaches_the_rigid_bodys_closed_form(name):
    if _missing(name):
        pytest.skip(_missing(name))
    system = get_system("rigid-body")
    exact = rigid_body_exact((2.0, 1.0, 2 / 3), system.x0)(np.array([10.0]))[0]
    prepared = P.prepare(B.peer_of(B.resolve_peer(name)), system, 10.0)
    errors = []
    for rtol in (1e-6, 1e-11):
        sol = prepared.solve(np.asarray(system.x0), rtol)
        assert sol.ok, sol.message
        errors.append(float(np.linalg.norm(sol.state - exact)))
    assert errors[1] < 1e-8 and errors[1] < 1e-2 * errors[0]


@pytest.mark.skipif(importlib.util.find_spec("numbalsoda") is None, reason=P.EXTRA + " (numbalsoda)")
@pytest.mark.parametrize("name", SYSTEMS)
def test_cfunc_field_agrees_with_the_plain_one(name):
    import numba
    from numbalsoda import lsoda_sig

    system, f = _plain(name)
    rhs = numba.cfunc(lsoda_sig)(compiled(P.cached_field_code(system, "cfunc")))
    pointer = ctypes.POINTER(ctypes.c_double)
    for x in _points(system):
        u, du, p = np.array(x), np.empty(x.size), np.zeros(1)
        rhs.ctypes(0.0, u.ctypes.data_as(pointer), du.ctypes.data_as(pointer), p.ctypes.data_as(pointer))
        np.testing.assert_allclose(du, f(0.0, x), rtol=1e-13, atol=1e-15)


@pytest.mark.skipif(importlib.util.find_spec("jax") is None, reason=P.EXTRA + " (jax)")
@pytest.mark.parametrize("name", SYSTEMS)
def test_jax_field_agrees_with_the_plain_one(name):
    P.enable_float64()
    import jax.numpy as jnp

    system, f = _plain(name)
    g = compiled(P.cached_field_code(system, "jax"))
    for x in _points(system):
        np.testing.assert_allclose(np.asarray(g(0.0, jnp.asarray(x), None)), f(0.0, x), rtol=1e-13, atol=1e-15)


# ----------------------------------------------------------------------------------------------
# rkhp bench with the peers


def test_bench_names_an_absent_peer_and_runs_the_others(monkeypatch):
    monkeypatch.setattr(B, "absent", lambda peer: "numbalsoda:dop853 is absent: numbalsoda not installed"
                        if peer.kind == "numbalsoda" else None)
    study = B.bench("rigid-body", ["kahan-li6"], peers=["numbalsoda:dop853", "scipy:dop853"], steps=(10, 20),
                    tolerances=(1e-5, 1e-8), repeats=1)
    assert study.absent_peers == (("numbalsoda:dop853", "numbalsoda:dop853 is absent: numbalsoda not installed"),)
    assert [c.method for c in study.curves] == ["kahan-li6", "scipy:dop853"]
    assert json_form(study)["absent_peers"][0]["peer"] == "numbalsoda:dop853"


def test_bench_races_the_compiled_peers():
    names = [n for n in P.COMPILED_PEERS if not _missing(n)]
    if not names:
        pytest.skip(_missing("numbalsoda:dop853"))
    study = B.bench("rigid-body", ["kahan-li8"], peers=names, steps=(10, 40), tolerances=(1e-5, 1e-10), repeats=1)
    assert study.reference.kind == "exact" and not study.absent_peers
    for curve in study.curves[1:]:
        assert curve.kind in ("numbalsoda", "diffrax")
        loose, tight = curve.points
        assert tight.measured_error < 1e-3 * loose.measured_error
        assert all(p.cpu_seconds > 0 and p.status == "ok" for p in curve.points)


def test_compiled_reference_agrees_with_scipys():
    if _missing("numbalsoda:dop853"):
        pytest.skip(_missing("numbalsoda:dop853"))
    from rkhp.studies.reference import dop853_reference

    system = get_system("nambu")
    compiled_ref, scipy_ref = P.compiled_reference(system, 10.0), dop853_reference(system, 10.0)
    assert compiled_ref.error_estimate < 1e-13
    assert np.linalg.norm(compiled_ref.state - scipy_ref.state) < 10 * scipy_ref.error_estimate


# ----------------------------------------------------------------------------------------------
# the benchmark on a tiny setting


def _benchmark():
    spec = importlib.util.spec_from_file_location("work_precision", ROOT / "benchmarks" / "work_precision.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_work_precision_benchmark_runs_tiny(tmp_path, capsys):
    page = tmp_path / "wp.md"
    _benchmark().main(["rigid-body", "--quick", "--targets", "1e-6", "--rounds", "1", "--write", str(page)])
    out = capsys.readouterr().out
    text = page.read_text()
    assert "| `rigid-body` | 1e-06 |" in text and "python benchmarks/work_precision.py rigid-body" in text
    for name in ("numbalsoda:dop853", "diffrax:dopri8"):
        reason = _missing(name)
        assert (reason in out and reason in text) if reason else f"{name} absent" not in out


def test_work_precision_over_processes_takes_each_time_at_its_minimum():
    """--processes: each contender's CPU and wall times are their minima over the processes'
    runs (apart), its setting and error the runs' own; a run that found another setting is
    refused, not merged."""
    bench = _benchmark()
    runs = [[{"system": "nambu", "target": 1e-8,
              "cells": {"bcm6-s13": ["19 steps", cpu, wall, 8.2e-9],
                        "scipy:dop853": ["rtol 1.8e-08", 2 * cpu, wall, 7.6e-9]}}]
            for cpu, wall in ((3e-4, 9e-4), (5e-4, 6e-4), (4e-4, 7e-4))]
    (row,) = bench.fastest(runs)
    assert (row.system, row.target) == ("nambu", 1e-8)
    assert row.cells == {"bcm6-s13": ("19 steps", 3e-4, 6e-4, 8.2e-9),
                         "scipy:dop853": ("rtol 1.8e-08", 6e-4, 6e-4, 7.6e-9)}
    runs[1][0]["cells"]["bcm6-s13"][0] = "23 steps"
    with pytest.raises(RuntimeError, match="bcm6-s13 found another setting"):
        bench.fastest(runs)


@pytest.mark.slow
def test_work_precision_benchmark_takes_a_spec_file(tmp_path):
    page = tmp_path / "wp.md"
    _benchmark().main([str(VORTICES), "--quick", "--targets", "1e-6", "--rounds", "1", "--write", str(page)])
    assert "| `vortices-8` | 1e-06 |" in page.read_text()


@pytest.mark.parametrize("script, args, says", [
    ("work_precision.py", ["--rounds", "0"], "--rounds"),
    ("work_precision.py", ["--targets", "1e-8,x"], "--targets"),
    ("work_precision.py", ["--processes", "0"], "--processes"),
    ("work_precision.py", ["no-such-system"], "unknown system 'no-such-system'"),
    ("long_runs.py", ["--t-final", "-1"], "--t-final"),
    ("long_runs.py", ["no-such-system"], "unknown system 'no-such-system'"),
])
def test_the_benchmarks_refuse_bad_arguments_in_one_line(script, args, says):
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert says in done.stderr.strip().splitlines()[-1]


@pytest.mark.parametrize("script", sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")))
def test_every_benchmark_refuses_an_unknown_flag_before_its_work(script):
    """An unknown flag is one line and exit 2 within seconds, not taken for an argument (a system
    name, a plot file) nor ignored while the benchmark runs for minutes."""
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--no-such-flag"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr and done.stdout == ""
    assert "--no-such-flag" in done.stderr.strip().splitlines()[-1]
