"""Shared test helpers."""

from __future__ import annotations

import gc

import pytest


def pytest_configure(config):
    """The collector's thresholds of an `rkhp` process (`rkhp_cli.main.GC_THRESHOLDS`): the
    commands that tests run in this process run as in their own."""
    from rkhp_cli.main import GC_THRESHOLDS

    gc.set_threshold(*GC_THRESHOLDS)


def pytest_runtest_teardown(item, nextitem):
    """After a test file's last test, the objects alive then (imported modules, numba's loaded
    kernels, sympy's caches: millions in a test process) leave the garbage collector's
    generations (`gc.freeze`): its full collections then scan only what later tests made, not
    everything the earlier files left alive. What the tests run is unchanged; a cycle left for
    the collector at that moment is kept until the process ends."""
    if nextitem is None or nextitem.path != item.path:
        gc.freeze()


@pytest.fixture
def run_cli():
    """Run `rkhp ARGS`; return (exit status, stdout, stderr): in this process under
    PYTHONHASHSEED=0, else in a fresh one (tests/cli_run.py)."""
    from cli_run import rkhp

    def run(*args: str, timeout: float = 600):
        return tuple(rkhp(*args, timeout=timeout))

    return run


@pytest.fixture
def oscillator():
    """(coefficients {t: c(t)}, order) -> [k-th coefficient of sum_t h^(|t|-1) c(t) F(t) / H]:
    exact, on the harmonic oscillator H = |x|^2/2 in R^2 with pi = [[0, 1], [-1, 0]],
    alpha = x - pi p / 2, where every F(t) of T_0 is a rational multiple of H (docs/theory.md §11)."""
    from fractions import Fraction

    import numpy as np

    from rkhp.series.differentials import constant_matrix_jets, monomial_basis
    from rkhp.trees.rooted import trees_up_to

    def values(order):
        basis = monomial_basis(2, order - 1)
        K = np.full((basis.sizes[-1], 1), Fraction(0), dtype=object)
        for e, v in (((0, 0), Fraction(1, 2)), ((1, 0), Fraction(1)), ((2, 0), Fraction(1, 2)),
                     ((0, 2), Fraction(1, 2))):
            K[basis.index[e], 0] = v
        half = Fraction(1, 2)
        D = np.array([[[Fraction(0)], [-half]], [[half], [Fraction(0)]]], dtype=object)
        F = constant_matrix_jets(trees_up_to(order, True), order, K, D, None, basis)
        return {t: F[t][0] / half for t in trees_up_to(order, True)}

    def series(coefficients, order):
        ratios = values(order)
        out = [Fraction(0)] * order
        for t, c in coefficients.items():
            out[t.order - 1] += c * ratios[t]
        return out

    return series


@pytest.fixture(scope="session")
def rigid_body_spec(tmp_path_factory):
    """The rigid body (docs/theory.md §6) written as a spec file of the general family: the
    matrix of so(3)* as expressions, the built-in's H, x0 and Casimir."""
    path = tmp_path_factory.mktemp("spec") / "rigid-body-general.toml"
    path.write_text('name = "rigid-body-general"\n'
                    'family = "general"\n'
                    'poisson = [["0", "-x3", "x2"], ["x3", "0", "-x1"], ["-x2", "x1", "0"]]\n'
                    'hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"\n'
                    'x0 = [0.45359612142557731, 0.0, 0.89120736006143542]\n'
                    'casimirs = ["(x1^2 + x2^2 + x3^2)/2"]\n')
    return path
