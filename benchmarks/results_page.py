"""The user's manual's one page of measured figures, docs/results/index.md, generated from the
measurement records in benchmarks/data/measurements.toml.

Run: python benchmarks/results_page.py [--check]
     python benchmarks/results_page.py record --page PAGE --title TITLE -- COMMAND [ARG...]

The manual (docs/) says what is and how to measure it; every figure a run measured (times, loads,
counts of a timed run, the versions compared) is a record here, with its provenance: the command
that printed it, the date, the machine (CPU model, cores, load average) and the figures as the
command printed or tabulated them. Each record names the manual page it serves; the page groups
the records by that page, in the order of the file, and each manual page links to its section.
The commits that records compare are listed once, by what each version is (`[versions]`).

- without arguments: writes docs/results/index.md from the records;
- --check: exits 1 if docs/results/index.md is not what the records give (a test runs this);
- record: runs COMMAND in the repository root, and appends its standard output as a new record,
  with the date (UTC) and this machine's CPU model, cores and load average at the start, then
  writes the page again. A command that fails adds nothing (exit 1).

docs/results/work-precision.md and docs/results/long-runs.md are generated pages of their own
(benchmarks/work_precision.py --write, benchmarks/long_runs.py --write), linked from this one.
"""

from __future__ import annotations

import json
import os
import platform
import posixpath
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent
RECORDS = ROOT / "benchmarks" / "data" / "measurements.toml"
PAGE = ROOT / "docs" / "results" / "index.md"
DOCS = ROOT / "docs"


class Record(NamedTuple):
    """One measurement: the manual page it serves (a path under docs/), its title (the heading the
    page links to), the command, date and machine it was measured with, and its figures (Markdown)."""

    page: str
    title: str
    command: str
    date: str
    machine: str
    figures: str


def records(path: Path = RECORDS) -> list[Record]:
    """The records of `path`, in order; a record missing a field is an error naming it."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    out = []
    for i, entry in enumerate(data.get("record", [])):
        missing = [f for f in Record._fields if not str(entry.get(f, "")).strip()]
        if missing:
            raise ValueError(f"{path.name}: record {i + 1} has no {', '.join(missing)}")
        out.append(Record(**{f: str(entry[f]).strip("\n") for f in Record._fields}))
    return out


def versions(path: Path = RECORDS) -> dict[str, str]:
    """The commits the records name (abbreviated hash: what that version is), from `[versions]`."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    return {str(k): str(v) for k, v in data.get("versions", {}).items()}


def slug(title: str) -> str:
    """The anchor MyST gives a heading (myst_heading_anchors): what the manual's links point at."""
    return re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")


def page_title(page: str) -> str:
    """The first heading of the manual page `page` (a path under docs/)."""
    for line in (DOCS / page).read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return page


LINK = re.compile(r"\]\(([^)\s]+)\)")


def from_results(figures: str, page: str) -> str:
    """`figures` with its relative links, written from the manual page `page`, made relative to
    docs/results/ (where the generated page is)."""
    def moved(match: re.Match) -> str:
        target = match.group(1)
        if "://" in target or target.startswith(("/", "mailto:")):
            return match.group(0)
        path, _, anchor = target.partition("#")
        path = posixpath.normpath(posixpath.join(posixpath.dirname(page), path or posixpath.basename(page)))
        return f"](../{path}{'#' + anchor if anchor else ''})"
    return LINK.sub(moved, figures)


SKIP = "<!-- docs: skip the output of a measurement, not run by the docs tests -->"


def marked(figures: str) -> str:
    """`figures` with each code block marked as shown output, which the docs tests do not run
    (docs/CONTRIBUTING-DOCS.md)."""
    out, inside = [], False
    for line in figures.split("\n"):
        if line.startswith("```"):
            if not inside and not (out and out[-1].startswith("<!-- docs:")):
                out.append(SKIP)
            inside = not inside
        out.append(line)
    return "\n".join(out)


def render(entries: list[Record], named: dict[str, str]) -> str:
    """The text of docs/results/index.md: the records grouped by the manual page they serve, then
    the versions they compare, by what each is (`named`)."""
    titles = [r.title for r in entries]
    repeated = sorted({t for t in titles if titles.count(t) > 1})
    if repeated:
        raise ValueError(f"record titles must be unique (they are the anchors): {', '.join(repeated)}")
    text = [
        "# Measured figures (generated)",
        "",
        "Generated by `python benchmarks/results_page.py` from `benchmarks/data/measurements.toml`; do not "
        "edit by hand. Every figure below was measured by the command shown, on the date and machine "
        "shown; the manual pages say what is, and link here for the figures. A new measurement is "
        "recorded with `python benchmarks/results_page.py record --page PAGE --title TITLE -- COMMAND`.",
        "",
        "Times on a shared machine depend on its load: compare figures of one record (measured in "
        "one run, interleaved), not figures of different records. Commit hashes name the versions "
        "a run compared, as the run named them; the last section says what each version is.",
        "",
        "Work-precision against compiled peers, and long runs against them at equal CPU time, are "
        "generated pages of their own: [work-precision](work-precision.md), [long runs](long-runs.md).",
        "",
    ]
    pages = list(dict.fromkeys(r.page for r in entries))
    for page in pages:
        text += [f"## {page_title(page)}", "", f"Figures of [{page_title(page)}](../{page}).", ""]
        for r in (r for r in entries if r.page == page):
            text += [f"### {r.title}", "", f"- command: {r.command}", f"- date: {r.date}",
                     f"- machine: {r.machine}", "", marked(from_results(r.figures, r.page)), ""]
    if named:
        text += ["## Versions named in the records", "", "| commit | what it is |", "|---|---|",
                 *(f"| {commit} | {what} |" for commit, what in named.items()), ""]
    return "\n".join(text)


def machine() -> str:
    """This machine: CPU model, cores and load average (1, 5 and 15 minutes) now."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "unknown"
    return f"{model}, {os.cpu_count()} cores, load average {load} at the start"


def toml_string(text: str) -> str:
    """`text` as a TOML string: a multi-line literal string for text of several lines (TOML drops
    the newline after its opening quotes), else a basic string (JSON's escapes are TOML's)."""
    if "\n" in text and "'''" not in text and not text.endswith("'"):
        return "'''\n" + text + "\n'''"
    return json.dumps(text, ensure_ascii=False)


def record_text(r: Record) -> str:
    """One [[record]] table of measurements.toml."""
    fields = [f"{field} = {toml_string(getattr(r, field))}" for field in Record._fields]
    return "\n".join(["", "[[record]]", *fields, ""])


def record(page: str, title: str, command: list[str]) -> Record:
    """Runs `command` in the repository root and returns its output as a record."""
    if not (DOCS / page).is_file():
        raise ValueError(f"--page {page}: no such page under docs/")
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    where = machine()
    done = subprocess.run(command, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited with status {done.returncode}; nothing recorded")
    figures = "```text\n" + done.stdout.rstrip("\n") + "\n```"
    return Record(page, title, "`" + " ".join(command) + "`", date, where, figures)


def _option(argv: list[str], flag: str) -> str:
    if flag not in argv or argv.index(flag) + 1 >= len(argv):
        raise ValueError(f"record needs {flag}")
    return argv[argv.index(flag) + 1]


def main(argv: list[str]) -> int:
    if argv in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    try:
        if argv[:1] == ["record"]:
            if "--" not in argv or argv.index("--") == len(argv) - 1:
                raise ValueError("record needs -- COMMAND")
            head, command = argv[:argv.index("--")], argv[argv.index("--") + 1:]
            new = record(_option(head, "--page"), _option(head, "--title"), command)
            render([*records(), new], versions())
            with RECORDS.open("a", encoding="utf-8") as f:
                f.write(record_text(new))
            PAGE.write_text(render(records(), versions()), encoding="utf-8")
            print(f"recorded: {new.title} ({new.date}); written: {PAGE.relative_to(ROOT)}")
            return 0
        if argv not in ([], ["--check"]):
            raise ValueError(f"unknown arguments: {' '.join(argv)}")
        text = render(records(), versions())
        if argv == ["--check"]:
            if not PAGE.exists() or PAGE.read_text(encoding="utf-8") != text:
                print(f"{PAGE.relative_to(ROOT)} is not what the records give: "
                      "run python benchmarks/results_page.py", file=sys.stderr)
                return 1
            return 0
        PAGE.write_text(text, encoding="utf-8")
        print(f"written: {PAGE.relative_to(ROOT)}")
        return 0
    except ValueError as error:
        print(f"results_page: {error}", file=sys.stderr)
        return 2
    except RuntimeError as error:
        print(f"results_page: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
