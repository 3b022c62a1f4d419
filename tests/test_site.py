"""The documentation site builds (Sphinx, nitpicky, warnings as errors), every page has its
title, and no internal link or anchor is broken (checked on the built HTML, offline).

Slow (a full build runs the autodoc imports and the figure-making pages): `make test-all`.
"""

from __future__ import annotations

import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parent.parent
SKIP_PAGES = {"genindex.html", "search.html", "py-modindex.html"}


class Page(HTMLParser):
    """The title, the ids and the links of one HTML page."""

    def __init__(self):
        super().__init__()
        self.ids: set[str] = set()
        self.links: list[str] = []
        self.h1 = ""
        self._in_h1 = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids.add(attrs["id"])
        if tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])
        if tag in ("img", "script", "link") and (attrs.get("src") or attrs.get("href")):
            self.links.append(attrs.get("src") or attrs.get("href"))
        if tag == "h1":
            self._in_h1 = True

    def handle_endtag(self, tag):
        if tag == "h1":
            self._in_h1 = False

    def handle_data(self, data):
        if self._in_h1:
            self.h1 += data


def parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("sphinx", reason="the docs extra (make test-all installs it)")
    out = tmp_path_factory.mktemp("html")
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-n", "-q",
                           "-b", "html", str(ROOT / "docs"), str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.mark.slow
def test_every_source_page_is_built_with_its_title(site):
    sources = [p for p in (ROOT / "docs").rglob("*.md")
               if not any(part.startswith("_") for part in p.relative_to(ROOT / "docs").parts)]
    assert sources
    for source in sources:
        html = site / source.relative_to(ROOT / "docs").with_suffix(".html")
        assert html.exists(), f"{source} was not built"
        first = next(line for line in source.read_text(encoding="utf-8").splitlines() if line.strip())
        assert first.startswith("# "), f"{source}: the first line is not a '# Title'"
        page = parse(html)
        title = re.sub(r"\s+", " ", page.h1.replace("¶", "")).strip()
        assert title, f"{html} has no <h1>"
        assert re.search(r"<title>[^<]*\S[^<]*</title>", html.read_text(encoding="utf-8"))


@pytest.mark.slow
def test_no_broken_internal_link(site):
    pages = {p: parse(p) for p in site.rglob("*.html") if p.name not in SKIP_PAGES}
    broken = []
    for path, page in pages.items():
        for link in page.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith("mailto:"):
                continue
            target = (path.parent / unquote(parts.path)).resolve() if parts.path else path
            if not target.exists():
                broken.append(f"{path.relative_to(site)}: {link} (no such file)")
            elif parts.fragment and target.suffix == ".html":
                ids = pages[target].ids if target in pages else parse(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{path.relative_to(site)}: {link} (no such anchor)")
    assert not broken, "\n".join(broken)


@pytest.mark.slow
def test_cli_reference_documents_every_command(site):
    from rkhp_cli.main import COMMANDS

    ids = parse(site / "reference" / "cli.html").ids
    missing = [name for name in COMMANDS if f"rkhp-{name}" not in ids]
    assert not missing, f"commands missing from the CLI reference: {missing}"


@pytest.mark.slow
def test_formulas_are_rendered_offline(site):
    """Every formula is MathML written at build time (docs/_ext/mathml.py): the theory page shows
    rendered mathematics, and no page loads a script from elsewhere (MathJax from a CDN) or keeps
    raw LaTeX delimiters."""
    theory = (site / "theory.html").read_text(encoding="utf-8")
    assert theory.count("<math") > 100
    for path in site.rglob("*.html"):
        page = parse(path)
        remote = [link for link in page.links if urlsplit(link).scheme in ("http", "https")
                  and link.endswith(".js")]
        assert not remote, f"{path.relative_to(site)} loads {remote}"
        assert not [link for link in page.links if "mathjax" in link.lower()], f"{path.relative_to(site)} loads MathJax"
        text = path.read_text(encoding="utf-8")
        assert '<span class="math' not in text, f"{path.relative_to(site)} keeps raw LaTeX for a script"


def test_every_formula_of_the_pages_converts():
    """The converter of the build reads every $...$ and $$...$$ formula of the pages (fast: no build)."""
    converter = pytest.importorskip("latex2mathml.converter", reason="the docs extra")
    formulas = []
    for path in sorted((ROOT / "docs").rglob("*.md")):
        text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
        text = re.sub(r"`[^`\n]*`", "", text)
        formulas += [(path.name, m.group(1) or m.group(2)) for m in
                     re.finditer(r"\$\$(.+?)\$\$|(?<![\\$])\$([^$\n]+?)\$", text, flags=re.S)]
    assert len(formulas) > 1000
    bad = [(name, tex[:60]) for name, tex in formulas if "<math" not in converter.convert(tex)]
    assert not bad, bad
