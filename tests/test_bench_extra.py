"""The `bench` extra makes nodepy importable, so `make bench` compares with it."""

from __future__ import annotations

import importlib.metadata
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_bench_extra_brings_what_nodepy_imports():
    # nodepy's modules import `six` (nodepy/runge_kutta_method.py: `from six.moves import range`)
    # without declaring it, so the extra must
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["bench"]
    names = {re.split(r"[<>=!~ ]", req)[0].lower() for req in extra}
    assert {"nodepy", "six"} <= names


def test_nodepy_imports_where_installed():
    try:
        importlib.metadata.version("nodepy")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("nodepy is not installed (the bench extra)")
    import nodepy.rooted_trees  # noqa: F401
    import nodepy.runge_kutta_method  # noqa: F401
