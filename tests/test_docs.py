"""Every code block of README.md and docs/ runs, and shown outputs match (docs/CONTRIBUTING-DOCS.md).

One test per page (its blocks share a namespace and a scratch folder, in order); blocks marked
``<!-- docs: slow -->`` run only in the slow variant (`make test-all`). The site build test is in
tests/test_site.py.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

from doccode import Settings, has_slow_blocks, matches, normalise, run_page  # noqa: E402


def pages() -> list[Path]:
    """README.md and every Markdown page of docs/ (build outputs excluded)."""
    docs = [p for p in sorted((ROOT / "docs").rglob("*.md"))
            if not any(part.startswith("_") for part in p.relative_to(ROOT / "docs").parts)]
    return [ROOT / "README.md", *docs]


def page_id(path: Path) -> str:
    return str(path.relative_to(ROOT))


@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_page_examples(page, tmp_path):
    run_page(page, Settings(scratch=tmp_path))


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in pages() if has_slow_blocks(p)], ids=page_id)
def test_page_examples_with_slow_blocks(page, tmp_path):
    run_page(page, Settings(scratch=tmp_path, slow=True))


# the reference line of docs/studies.md as rich wraps it at 100 columns, with the DOP853 gap of
# two machines (8.9e-16 where the page was written, 1e-15 on another): the line breaks move
WRAPPED_HERE = """reference: exact, estimated error 2.2e-16 (closed-form solution, rounded once; round-off estimate
eps |x(T)|; agrees with DOP853 to 8.9e-16 (DOP853 error estimate 2.2e-15)); errors <= 2.2e-15 are
not reported as measurements
euler (rkhp)"""
WRAPPED_THERE = """reference: exact, estimated error 2.2e-16 (closed-form solution, rounded once; round-off estimate
eps |x(T)|; agrees with DOP853 to 1e-15 (DOP853 error estimate 2.2e-15)); errors <= 2.2e-15 are not
reported as measurements
euler (rkhp)"""


def test_wrapped_output_matches_whatever_the_width_of_a_round_off_figure(tmp_path):
    shown, other = normalise(WRAPPED_HERE, tmp_path), normalise(WRAPPED_THERE, tmp_path)
    assert matches(shown, other) and matches(other, shown)
    assert matches("a ... z\n...\nlast", normalise("a b c z\nx\ny\nlast", tmp_path))
    assert matches("a ...\nz", "a z")
    # a word changed, missing or moved is still a difference
    assert not matches(shown, other.replace("reported", "repotred"))
    assert not matches(shown, other.replace("euler (rkhp)", ""))
    assert not matches(shown, other.replace("not\nreported", "reported not"))
    assert not matches(shown, other.replace("agrees with DOP853", "agrees with RK45"))


LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_readme_links_reach_files():
    """README is not part of the site (whose links the site test checks): its relative links must
    name files of the repository, and their anchors headings of those pages."""
    broken = []
    for target in LINK.findall((ROOT / "README.md").read_text(encoding="utf-8")):
        if "://" in target or target.startswith("mailto:"):
            continue
        path, _, anchor = target.partition("#")
        file = ROOT / path
        if not file.exists():
            broken.append(target)
        elif anchor and anchor not in heading_slugs(file):
            broken.append(target)
    assert not broken, broken


def heading_slugs(page: Path) -> set[str]:
    """GitHub/MyST-style anchors of a page's headings (lowercase, punctuation dropped, spaces -> -)."""
    slugs = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            text = line.lstrip("#").strip().lower()
            slugs.add(re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", text)))
    return slugs


TOCTREE = re.compile(r"```\{toctree\}\n(.*?)```", re.S)
KINDS = ["Tutorials", "How-to guides", "Reference", "Explanation", "Contributing"]


def test_index_lists_every_page_once_by_kind():
    """docs/index.md has one explicit toctree per kind of page (no glob), and every page of docs/
    stands in exactly one of them."""
    trees = TOCTREE.findall((ROOT / "docs" / "index.md").read_text(encoding="utf-8"))
    options = [[line for line in tree.splitlines() if line.startswith(":")] for tree in trees]
    assert [o for opts in options for o in opts if o.startswith(":caption:")] == [f":caption: {k}" for k in KINDS]
    assert not any(o.startswith(":glob:") for opts in options for o in opts)
    listed = [line.strip() for tree in trees for line in tree.splitlines()
              if line.strip() and not line.startswith(":")]
    pages_ = sorted(str(p.relative_to(ROOT / "docs").with_suffix("")) for p in pages()[1:])
    assert sorted(listed) == [p for p in pages_ if p != "index"]
