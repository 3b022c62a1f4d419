"""Messages that name the cause: a spec file's x0 against its matrix, a run stopped by a singular
structure, a composition file without `kind`, and what a Groebner basis from Singular alone proves."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_an_x0_shorter_than_the_matrix_names_both_sizes(run_cli, tmp_path):
    """x0 of 7 entries for an 8 x 8 pi: the message says x0 has 7 entries and pi is 8 x 8 (it used
    to blame the matrix for not being 7 x 7)."""
    rows = [["0"] * 8 for _ in range(8)]
    for i in range(0, 8, 2):
        rows[i][i + 1], rows[i + 1][i] = "1", "-1"
    matrix = "[" + ", ".join("[" + ", ".join(f'"{v}"' for v in row) + "]" for row in rows) + "]"
    path = tmp_path / "lattice.toml"
    path.write_text(f'family = "constant"\npoisson = {matrix}\nhamiltonian = "x1^2"\nx0 = {[0.1] * 7}\n')
    code, _, err = run_cli("check", str(path))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "x0 has 7 entries but poisson is 8 x 8" in err


def test_four_structure_constants_are_entries_not_a_matrix(run_cli, tmp_path):
    """Four entries [i, j, k, value] are not a 4 x 4 matrix: x1 acting on span(x2, x3) by
    [[1, 1], [1, 2]] is a 3-dimensional Lie algebra, and a fifth entry contradicting the first is
    named as such."""
    entries = [[1, 2, 2, 1], [1, 3, 3, 1], [1, 3, 2, 1], [1, 2, 3, 2]]
    text = 'family = "lie-poisson"\nhamiltonian = "x1^2/2 + x2^2/2 + x3^2/2"\nx0 = [0.3, 0.2, 0.1]\n'
    path = tmp_path / "four.toml"
    path.write_text(text + f"structure_constants = {entries}\n")
    code, _, err = run_cli("check", str(path), "--samples", "3")
    assert code == 0, err
    path.write_text(text + f"structure_constants = {entries[:3] + [[1, 2, 2, 5]]}\n")
    code, _, err = run_cli("check", str(path), "--samples", "3")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "[1, 2, 2, 5] contradicts an earlier entry" in err


def test_a_run_into_a_singular_structure_says_where_pi_blows_up(run_cli, tmp_path):
    """pi = [[0, 1/x1], [-1/x1, 0]], H = -x2 from x0 = (1, 0): x1' = -1/x1, so x1^2 = 1 - 2t and pi
    blows up at t = 1/2 (the exact solution). A step of 0.1 fails on the step that reaches it, and
    the message names the structure blowing up there, not only Newton's failure."""
    path = tmp_path / "singular.toml"
    path.write_text('family = "general"\npoisson = [["0", "1/x1"], ["-1/x1", "0"]]\nhamiltonian = "-x2"\n'
                    'x0 = [1.0, 0.0]\nt_final = 1.0\n')
    code, _, err = run_cli("integrate", str(path), "--method", "paper-three-stage", "--steps", "10")
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert "t = 0.4 -> 0.5" in err and "the structure pi blows up" in err


def test_a_regular_flow_adds_nothing_to_a_failure():
    """Where the exact flow continues over the step (the rigid body), there is no cause to add."""
    from rkhp.systems import get_system
    from rkhp.systems.singular import flow_stop

    system = get_system("rigid-body")
    assert flow_stop(system, system.x0, 2.0) is None


def test_a_field_not_finite_at_the_start_ends_the_probe():
    """The pendulum at (0, 1e308): grad H overflows and the field is (inf, nan) there, so scipy's
    first step size is NaN, whose tries never end; the probe stops on it and names grad H."""
    import numpy as np

    from rkhp.systems import get_system
    from rkhp.systems.singular import flow_stop

    stop = flow_stop(get_system("pendulum"), np.array([0.0, 1e308]), 1.0)
    assert stop is not None and "grad H blows up" in stop


def test_a_composition_file_without_kind_is_read_as_a_composition(run_cli, tmp_path):
    """`gamma` without `A` and without `kind`: the triple jump of Euler (Yoshida 1990, order 4)."""
    g = "1/(2 - 2^(1/3))"
    path = tmp_path / "jump.toml"
    path.write_text(f'name = "jump"\nbase = "euler"\norder = 4\ngamma = ["{g}", "1 - 2*{g}", "{g}"]\n')
    code, out, err = run_cli("verify", str(path))
    assert code == 0, err
    assert "claimed order 4: confirmed" in out


def test_a_basis_from_singular_alone_is_called_computed_not_proved():
    """A Groebner basis [1] without cofactors from Singular is reported as computed, not proved; the
    same from sympy (which rkhp runs itself) or with a checked certificate stays "proved"."""
    from rkhp.search.prove import prove_impossible
    from rkhp.search.system import ResidualSystem

    proof = prove_impossible(ResidualSystem.build(2, 4, "degenerate"), 60.0, "sympy")
    assert proof.proved and proof.result_text(2, 4, "degenerate").startswith("proved impossible")
    singular = dataclasses.replace(proof, engine="singular", certificate=None)
    text = singular.result_text(2, 4, "degenerate")
    assert text.startswith("computed impossible, not proved") and "no certificate" in text


def test_the_manual_lists_singular_only_rows_apart_from_the_proved_ones():
    """docs/tableau-search.md: degenerate orders 6 and 7 (Singular's output, no certificate) are not
    in the "Proved minimal" table but in the "Computed minimal, not proved" one."""
    page = (ROOT / "docs" / "tableau-search.md").read_text()
    proved = page.split("**Proved minimal**")[1].split("**Computed minimal, not proved**")[0]
    computed = page.split("**Computed minimal, not proved**")[1].split("**Upper bounds only**")[0]
    assert "no stored certificate" not in proved
    assert "| degenerate | 6 | 6 |" in computed and "| degenerate | 7 | 7 |" in computed


@pytest.mark.parametrize("name", ["euler", "rk4"])
def test_a_tableau_file_is_still_a_tableau(name):
    from rkhp.tableaux.compositions import is_composition_name

    assert not is_composition_name(str(ROOT / "tables" / f"{name}.toml"))
