"""Running the code blocks of documentation pages (README.md and docs/**/*.md).

The rules a page follows are in docs/CONTRIBUTING-DOCS.md. In short:

- a ```` ```console ```` block holds commands (lines starting with ``$ ``, a trailing ``\\``
  continues one) each followed by its output; the commands run with bash in the page's scratch
  folder, with the project's ``rkhp`` first on PATH, and the output (stdout and stderr together)
  must match what is shown;
- a ```` ```python ```` block runs in the page's namespace (shared by its blocks); a block that
  starts with ``>>>`` is a doctest and its outputs must match;
- an HTML comment ``<!-- docs: ... -->`` before a block changes what happens to it:
  ``file NAME`` writes the block to NAME in the scratch folder, ``no-compare`` runs it without
  comparing its output, ``slow`` runs it only in ``make test-all``, ``skip REASON`` shows it only;
- every other fenced block must carry ``file`` or ``skip`` (MyST directives such as
  ```` ```{toctree} ```` are not code and are left alone).

Comparison: trailing spaces and blank lines at both ends are ignored, the scratch folder's path
reads ``.``, durations (a number followed by s, ms or us) read ``<time>``, numbers below 1e-13
written with an exponent read ``<round-off>``, a line ``...`` matches
any number of lines and ``...`` inside a line matches any text; output whose lines do not match
still matches when it has the same words in the same order (rich wraps paragraphs, and a
round-off figure's width differs between machines). A command may exit with a
non-zero status only when the output shown ends with rkhp's one-line error (``rkhp: ...``).

Sybil (a maintained library for testing documentation examples) lexes the Markdown: fenced
blocks and HTML-comment markers, in document order, with their line numbers for failures.
"""

from __future__ import annotations

import doctest
import io
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from sybil import Document, Region
from sybil.parsers.markdown.lexers import DirectiveInHTMLCommentLexer, FencedCodeBlockLexer

RUN_LANGUAGES = ("console", "python")
MARKERS = ("file", "no-compare", "slow", "skip")
DURATION = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?:e[-+]?\d+)? ?(?:s|ms|us)\b")
# magnitudes at the float64 round-off level (Casimir errors, axiom deviations): their digits change
# with the machine's instruction set, so they compare as one token
ROUND_OFF = re.compile(r"(?<![\w.])-?\d(?:\.\d+)?e-(?:1[4-9]|[2-9]\d|\d{3})\b")
COMMAND_TIMEOUT = 600
DOCTEST_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


@dataclass
class Settings:
    """How a page runs: its scratch folder and whether the ``slow`` blocks run."""

    scratch: Path
    slow: bool = False
    compare: bool = True


def page_document(path: Path, settings: Settings) -> Document:
    """The page as a sybil Document whose examples are its markers and code blocks."""
    text = path.read_text(encoding="utf-8")
    document = Document(text, str(path))
    for region in markers(document):
        document.add(region)
    for region in code_blocks(document):
        document.add(region)
    document.namespace["__docs_settings__"] = settings
    document.namespace["__docs_pending__"] = None
    document.namespace["__name__"] = "__docs__"
    return document


def markers(document: Document):
    lexer = DirectiveInHTMLCommentLexer(directive="docs", arguments=r".+?")
    for lexed in lexer(document):
        words = lexed.lexemes["arguments"].split(None, 1)
        if not words or words[0] not in MARKERS:
            raise ValueError(f"{document.path}: unknown marker <!-- docs: {lexed.lexemes['arguments']} -->"
                             f" (known: {', '.join(MARKERS)})")
        yield Region(lexed.start, lexed.end, (words[0], words[1] if len(words) > 1 else ""), set_pending)


def code_blocks(document: Document):
    lexer = FencedCodeBlockLexer(language=r"[^\s`]*", mapping={"language": "language", "source": "source"})
    for lexed in lexer(document):
        language = lexed.lexemes["language"]
        if language.startswith("{"):  # a MyST directive, not code
            continue
        yield Region(lexed.start, lexed.end, (language, lexed.lexemes["source"]), run_block)


def set_pending(example) -> None:
    example.namespace["__docs_pending__"] = example.parsed


def run_block(example) -> str | None:
    """Evaluate one fenced block according to its language and the marker before it."""
    language, source = example.parsed
    settings: Settings = example.namespace["__docs_settings__"]
    marker, argument = example.namespace["__docs_pending__"] or ("", "")
    example.namespace["__docs_pending__"] = None
    if marker == "skip":
        return None
    if marker == "slow" and not settings.slow:
        return None
    if marker == "file":
        target = settings.scratch / argument.strip()
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(str(source), encoding="utf-8")
        return None
    if language not in RUN_LANGUAGES:
        return (f"a ```{language or '(no language)'} block must be preceded by <!-- docs: file NAME --> "
                f"or <!-- docs: skip REASON --> (only console and python blocks run)")
    compare = settings.compare and marker != "no-compare"
    if language == "console":
        return run_console(str(source), settings, compare)
    return run_python(example, str(source), compare)


def run_python(example, source: str, compare: bool) -> str | None:
    """A doctest (source starting with >>>) or a plain block, in the page's namespace."""
    if source.lstrip().startswith(">>>"):
        test = doctest.DocTestParser().get_doctest(source, example.namespace, example.path,
                                                   example.path, example.line)
        runner = (doctest.DocTestRunner if compare else _NoCompareRunner)(optionflags=DOCTEST_FLAGS)
        out = io.StringIO()
        runner.run(test, out=out.write, clear_globs=False)
        example.namespace.update(test.globs)  # DocTest works on a copy of the namespace
        return out.getvalue() or None
    code = compile("\n" * example.line + source, example.path, "exec")
    exec(code, example.namespace)
    return None


class _NoCompareRunner(doctest.DocTestRunner):
    """Runs doctest examples, failing on exceptions only."""

    def check_output(self, want, got, optionflags):  # noqa: D102 (doctest hook)
        return True


def commands(source: str) -> list[tuple[str, str]]:
    """(command, expected output) pairs of a console block."""
    pairs: list[tuple[str, list[str]]] = []
    lines = source.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            command = line[2:]
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command[:-1] + "\n" + lines[i]
            pairs.append((command, []))
        elif pairs:
            pairs[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"console block: text before the first '$ ' command: {line!r}")
        i += 1
    return [(command, "\n".join(out)) for command, out in pairs]


def normalise(text: str, scratch: Path) -> str:
    text = text.replace(str(scratch) + os.sep, "").replace(str(scratch), ".")
    text = DURATION.sub("<time>", text)
    text = ROUND_OFF.sub("<round-off>", text)
    return "\n".join(line.rstrip() for line in text.strip("\n").splitlines()).strip("\n")


def matches(expected: str, actual: str) -> bool:
    """Whether actual output matches the shown one (``...`` wildcards, see the module doc): line
    by line, or else as the same words in the same order (:func:`reflowed_match`)."""
    return line_match(expected, actual) or reflowed_match(expected, actual)


def line_match(expected: str, actual: str) -> bool:
    """Whether actual output matches the shown one line by line."""
    pattern = []
    for line in expected.splitlines():
        if line.strip() == "...":
            pattern.append(r"(?:[^\n]*\n)*?")
        else:
            pattern.append("[^\n]*?".join(re.escape(part) for part in line.split("...")) + r"\n")
    return re.fullmatch("".join(pattern), actual + "\n" if actual else "") is not None


def reflowed_match(expected: str, actual: str) -> bool:
    """Whether actual output has the shown words in the same order, whatever the line breaks: rich
    wraps a paragraph at word boundaries, so a number whose width differs between machines (the
    digits of a round-off figure, normalised only after wrapping) moves the breaks of the lines
    after it. A word ``...`` matches any words (or none), ``...`` inside a word any text."""
    words = expected.split()
    if not words:
        return not actual.split()
    pattern = ""
    for word in words:
        if word == "...":
            pattern += r"(?: .*?)?" if pattern else r"(?:.*? )?"
            continue
        body = ".*?".join(re.escape(part) for part in word.split("..."))
        pattern += body if not pattern or pattern.endswith("(?:.*? )?") else " " + body
    return re.fullmatch(pattern, " ".join(actual.split()), re.S) is not None


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env.update(COLUMNS="100", LINES="50", NO_COLOR="1", TERM="dumb", PYTHONHASHSEED="0")
    env.pop("FORCE_COLOR", None)
    return env


class Ran(NamedTuple):
    """What a command printed (stdout and stderr together) and its exit status."""

    output: str
    status: int


#: what bash would expand or treat as an operator, outside quotes; and inside double quotes
_SHELL_SYNTAX = re.compile(r"[|&;<>()$`*?~\[\]{}!\\#\n]")
_QUOTED = re.compile(r"'[^']*'|\"[^\"$`\\!]*\"")


def plain_rkhp(command: str) -> tuple[list[str], str] | None:
    """(arguments, rest) when ``command`` is ``rkhp ARGS`` or ``rkhp ARGS | REST`` with nothing in
    ARGS that bash would expand or redirect (the words as bash would pass them); else None."""
    head, bar, rest = command.partition("|")
    if bar and (rest.startswith("|") or _SHELL_SYNTAX.search(_QUOTED.sub("", head.rstrip()))):
        return None
    if not bar and _SHELL_SYNTAX.search(_QUOTED.sub("", command)):
        return None
    try:
        words = shlex.split(head)
    except ValueError:
        return None
    if not words or words[0] != "rkhp":
        return None
    return words[1:], rest


def in_process() -> bool:
    """Whether plain ``rkhp`` commands may run in this process: only under PYTHONHASHSEED=0, the
    hashing of the separate process they stand for (`make test` sets it)."""
    return sys.flags.hash_randomization == 0


def run_rkhp(args: list[str], rest: str, settings: Settings) -> Ran:
    """``rkhp ARGS [| REST]`` with rkhp run in this process by click's test runner, in the page's
    scratch folder (the current directory), with the environment of :func:`environment`: what a
    separate process would print, without its start-up. REST, if any, runs in bash on rkhp's
    stdout; rkhp's stderr comes first, as on a terminal where REST prints when its input ends."""
    import traceback

    from click.testing import CliRunner
    from rkhp_cli.main import rkhp

    env = {k: v for k, v in environment().items() if k not in ("PATH", "PYTHONHASHSEED")}
    env["FORCE_COLOR"] = None
    result = CliRunner(env=env).invoke(rkhp, args, prog_name="rkhp", catch_exceptions=True)
    status = result.exit_code
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        crash = "".join(traceback.format_exception(result.exception))
        return Ran(result.output + crash, 1)
    if not rest:
        return Ran(result.output, status)
    proc = subprocess.run(["bash", "-c", rest], cwd=settings.scratch, env=environment(), input=result.stdout,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=COMMAND_TIMEOUT)
    return Ran(result.stderr + proc.stdout, proc.returncode)


def run_command(command: str, settings: Settings) -> Ran:
    """One command of a console block: in this process when it is a plain ``rkhp`` command
    (:func:`plain_rkhp`, :func:`in_process`), else in bash."""
    plain = plain_rkhp(command) if in_process() else None
    if plain is not None:
        return run_rkhp(*plain, settings)
    proc = subprocess.run(["bash", "-c", command], cwd=settings.scratch, env=environment(),
                          stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=COMMAND_TIMEOUT)
    return Ran(proc.stdout, proc.returncode)


def run_console(source: str, settings: Settings, compare: bool) -> str | None:
    for command, shown in commands(source):
        ran = run_command(command, settings)
        actual = normalise(ran.output, settings.scratch)
        expected = normalise(shown, settings.scratch)
        last = expected.splitlines()[-1] if expected else ""
        if ran.status != 0 and not last.startswith("rkhp: "):
            return f"$ {command}\nexit status {ran.status}:\n{actual}"
        if compare and not matches(expected, actual):
            return f"$ {command}\n--- shown\n{expected}\n--- actual\n{actual}"
    return None


def run_page(path: Path, settings: Settings) -> None:
    """Evaluate every example of a page in order, in its scratch folder (raises on failure)."""
    settings.scratch.mkdir(parents=True, exist_ok=True)
    document = page_document(path, settings)
    cwd = os.getcwd()
    os.chdir(settings.scratch)
    try:
        for example in document.examples():
            example.evaluate()
    finally:
        os.chdir(cwd)


def has_slow_blocks(path: Path) -> bool:
    return "<!-- docs: slow" in path.read_text(encoding="utf-8")


# --- Sphinx: pages whose figures come from their own code -------------------------------------

def run_pages_for_figures(app) -> None:
    """builder-inited: run each page named in ``rkhp_run_at_build`` in _generated/<page>/, so that
    the figures it makes exist when the page is read (the page shows /_generated/<page>/NAME).
    The folder is emptied first: a page's commands write new files, as in a fresh scratch folder."""
    import shutil

    for name in app.config.rkhp_run_at_build:
        page = Path(app.srcdir) / f"{name}.md"
        scratch = Path(app.srcdir) / "_generated" / name
        shutil.rmtree(scratch, ignore_errors=True)
        run_page(page, Settings(scratch=scratch, slow=False, compare=False))


def setup(app):
    app.add_config_value("rkhp_run_at_build", [], "env")
    app.connect("builder-inited", run_pages_for_figures)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


# --- refreshing the outputs shown (python docs/_ext/doccode.py PAGE ...) ----------------------

def refresh_page(path: Path, scratch: Path) -> int:
    """Rewrite the output of every compared console block that no longer matches with the real
    output (blocks with ``...`` that still match are kept); returns how many blocks changed.
    Python doctests are left to the author."""
    scratch.mkdir(parents=True, exist_ok=True)
    settings = Settings(scratch=scratch, slow=True)
    document = page_document(path, settings)
    text = document.text
    edits: list[tuple[int, int, str]] = []
    cwd = os.getcwd()
    os.chdir(scratch)
    try:
        for example in document.examples():
            if example.region.evaluator is run_block and example.parsed[0] == "console":
                marker = example.namespace["__docs_pending__"] or ("", "")
                example.namespace["__docs_pending__"] = None
                if marker[0] in ("skip", "no-compare") or (marker[0] == "slow" and not settings.slow):
                    if marker[0] == "no-compare":
                        run_console(str(example.parsed[1]), settings, compare=False)
                    continue
                source = str(example.parsed[1])
                new = []
                for command, shown in commands(source):
                    proc = subprocess.run(["bash", "-c", command], cwd=scratch, env=environment(),
                                          stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                          stderr=subprocess.STDOUT, text=True, timeout=COMMAND_TIMEOUT)
                    actual = normalise(proc.stdout, scratch)
                    keep = matches(normalise(shown, scratch), actual)
                    output = shown.strip("\n") if keep else proc.stdout.replace(str(scratch) + os.sep, "").rstrip()
                    output = "\n".join(line.rstrip() for line in output.splitlines())
                    new.append("$ " + command.replace("\n", "\\\n") + ("\n" + output if output else ""))
                block = "\n".join(new) + "\n"
                if block != source:
                    start = text.index(source, example.start)
                    edits.append((start, start + len(source), block))
            else:
                try:
                    example.evaluate()
                except AssertionError as failure:  # reported; the author fixes doctests by hand
                    print(failure, file=sys.stderr)
    finally:
        os.chdir(cwd)
    for start, end, block in reversed(edits):
        text = text[:start] + block + text[end:]
    path.write_text(text, encoding="utf-8")
    return len(edits)


if __name__ == "__main__":
    import tempfile

    for name in sys.argv[1:]:
        with tempfile.TemporaryDirectory() as tmp:
            print(f"{name}: {refresh_page(Path(name).resolve(), Path(tmp))} block(s) refreshed")
