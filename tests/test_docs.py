"""Every code block of README.md and docs/ runs, and shown outputs match (docs/CONTRIBUTING-DOCS.md).

One test per page (its blocks share a namespace and a scratch folder, in order); blocks marked
``<!-- docs: slow -->`` run only in the slow variant (`make test-all`). The site build test is in
tests/test_site.py.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
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


# What the manual must not carry (docs/index.md "About these docs"; measured figures live in the
# generated pages of docs/results/): a calendar date, a machine's load or core count as the
# condition of a measurement, a commit hash.
DATE = re.compile(r"(?<!\d)20\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])(?!\d)")
LOAD = re.compile(r"\bload(?: average)?(?: of| about| of about| near)? \d|\b\d+-core\b", re.I)
# a run of 7 to 40 hexadecimal digits standing alone: not inside a word, not digits of a decimal
# or exponent (0.1032192, 1.42247325e-16), not an address (0x...)
HEX = re.compile(r"(?<![\w.+-])[0-9a-f]{7,40}(?![\w]|\.\d)")
GENERATED = ROOT / "docs" / "results"
CORES = re.compile(r"\b\d+(?:-core| cores?| CPUs?)\b")


def is_commit(token: str) -> bool:
    """Whether `token` names a commit of this repository (False where git or the history is absent)."""
    try:
        done = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{token}^{{commit}}"],
                              capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def provenance_in(line: str) -> list[str]:
    """The dates, load figures and commit hashes of one line: a hexadecimal run is a hash when it
    mixes letters and digits (as a 7-character hash nearly always does), or when git knows it as a
    commit (a hash of digits only, such as 2575823); a number like 1000003 or a word like
    'deadbeef' is neither."""
    found = [m.group() for m in DATE.finditer(line)] + [m.group() for m in LOAD.finditer(line)]
    for m in HEX.finditer(line):
        token = m.group()
        if (re.search(r"[a-f]", token) and re.search(r"\d", token)) or (token.isdigit() and is_commit(token)):
            found.append(token)
    return found


def test_provenance_scan_finds_dates_loads_and_hashes_only():
    # from lines the manual carried
    assert provenance_in("Recorded 2026-11-23, at load average 1.1:") == ["2026-11-23", "load average 1"]
    assert provenance_in("(2 cores at load 0.7, CPU times)") == ["load 0"]
    assert provenance_in("on the shared 2-core machine") == ["2-core"]
    assert provenance_in("UTC, ISO 8601 (`2026-11-28T01:02:03Z`);") == ["2026-11-28"]
    assert provenance_in("against d96bc91 (the wrapper) in bfa3cb0.") == ["d96bc91", "bfa3cb0"]
    # a hash of digits only (the history has some, such as 2575823) is found by asking git
    history = subprocess.run(["git", "-C", str(ROOT), "rev-list", "--all"], capture_output=True, text=True).stdout
    for token in [h[:7] for h in history.split() if h[:7].isdigit()][:1]:
        assert provenance_in(f"the version before ({token})") == [token]
    # hexadecimal-looking text that is no hash: tableau and table digits, counts, primes, words
    for line in ["a[5,1] = 2.95259868922   a[5,2] = -11.5957933242",
                 "phase constant       -8.54276895943563e-05",
                 "| b[b] |              -5.555556e-02 | -1/18 |",
                 "none modulo 1000003 and 2147483629 in 24 s",
                 "`trees --order 18`: 2732470 trees; --refinements must be at most 30, got 1000000000",
                 "a payload of 0xdeadbeef, the word deadbeef, a colour #c0ffee, the id abcdef0 0x1a2b3c4d5e",
                 "the load of this machine; a loaded machine; 12 cores"]:
        found = provenance_in(line)
        assert found == (["abcdef0"] if "abcdef0" in line else []), (line, found)


def test_manual_carries_no_dates_loads_or_commit_hashes():
    """The manual says what is: every date, load figure and commit hash belongs to a measurement,
    whose record is in benchmarks/data/measurements.toml and on the generated page."""
    found = []
    for page in pages():
        if page.is_relative_to(GENERATED):
            continue
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            if hits := provenance_in(line):
                found.append(f"{page.relative_to(ROOT)}:{number}: {', '.join(hits)}")
    assert not found, "\n".join(found)


def test_results_page_is_what_the_records_give():
    """docs/results/index.md is generated by benchmarks/results_page.py from the records: every
    record has its provenance and serves a page of the manual, and that page links to it."""
    spec = importlib.util.spec_from_file_location("results_page", ROOT / "benchmarks" / "results_page.py")
    results_page = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(results_page)
    records = results_page.records()
    assert records and results_page.main(["--check"]) == 0
    for record in records:
        assert DATE.search(record.date) and CORES.search(record.machine), record.title
        text = (ROOT / "docs" / record.page).read_text(encoding="utf-8")
        assert f"results/index.md#{results_page.slug(record.title)}" in text, record.title
    # every commit a record names is said in words on the page
    named = results_page.versions()
    page = (GENERATED / "index.md").read_text(encoding="utf-8")
    hashes = {h for line in page.splitlines() for h in provenance_in(line)
              if not DATE.fullmatch(h) and not LOAD.fullmatch(h)}
    assert hashes and hashes <= set(named), sorted(hashes - set(named))
