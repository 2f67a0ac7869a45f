"""The command lines README.md and docs/*.md show are commands that work.

Every ``railpilot ...``, ``python benchmarks/x.py ...``, ``python -m railpilot...`` and
``make <target>`` line of a fenced code block, and every inline code span starting so, is
checked without running anything:

- ``railpilot``: parsed by the real CLI's parser (``railpilot.cli.build_parser``); a line in
  usage notation (``[--json]``, ``--hex | --raw``, ``up|down``) is expanded and each form
  parsed; a line with placeholders (rule below) has its subcommands, option names and
  option choices checked instead of a full parse;
- ``python benchmarks/x.py``, ``python -m railpilot.x``: the file is there and every option
  given is one of its ``add_argument`` calls (read from its source, not imported);
- ``make``: the Makefile has the target;
- every argument that looks like a repository path (``examples/...``, ``x.toml``...) exists,
  except the values of options that name what a command writes or the user's own files.

A failure names the doc file, the line and the command.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import functools
import io
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeAlias

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: What a command line starts with -> its kind. A leading ``$ `` prompt and ``.venv/bin/``
#: (how some docs call the venv's python) are dropped first.
PREFIXES = {
    "railpilot ": "railpilot",
    "python benchmarks/": "benchmark",
    "python -m railpilot": "python -m",
    "make ": "make",
}
_LEAD = re.compile(r"^(?:\$\s+)?(?:\.venv/bin/)?")
_FENCE = re.compile(r"^\s*(`{3,}|~{3,})")
_SPAN = re.compile(r"(`+)(?!`)(.+?)(?<!`)\1(?!`)", re.DOTALL)

# Placeholders. A token is a placeholder (not a literal value) when it contains
#   - "..." or "…" (elided: `railpilot ground tsr set ...`),
#   - "<" or ">" once redirections are cut off (`<file>`),
#   - "path/to/" (`--controller path/to/file.py:Name`),
#   - an upper-case metavariable: a word of capital letters and underscores only, with no
#     digit or lower-case letter (SCENARIO.toml, DIR, PATH, ID, N, S, HOST:PORT, LINE_RUN,
#     the N of N-1). Words with a digit or a lower-case letter are literals: K1234,
#     SS4-0001, Datong.
# A command with a placeholder is not parsed whole; its subcommands, option names and the
# choices of its literal option values are still checked.
_METAVAR = re.compile(r"(?<![A-Za-z0-9_])[A-Z][A-Z_]*(?![A-Za-z0-9_])")

#: Redirections and command separators: the command ends before them (`| tail`, `> f`).
_END = re.compile(r"^(\||\|\||&&|;|&|\d*>>?.*|\d*<.*|&>.*)$")

#: Options whose value is written by the command (``--out`` folders, the live run's and the
#: load test's ``--screenshot``, the ground's ``--db`` store), or is the user's own file
#: (``--keys``: keys are never shipped): their values need not exist in the repository.
OUTPUT_OR_USER_OPTIONS = frozenset({"--out", "--screenshot", "--db", "--keys"})
_REPO_SUFFIXES = (".toml", ".py", ".csv", ".json", ".md")
_REPO_DIRS = ("examples/", "benchmarks/", "docs/", "src/", "tests/", "tools/")


@dataclass(frozen=True)
class DocCommand:
    doc: str  #: relative to the repository root
    line: int
    text: str  #: as in the doc, continuations joined
    kind: str  #: a value of PREFIXES
    inline: bool  #: an inline code span (may name a command or an option, not run it)

    @property
    def where(self) -> str:
        return f"{self.doc}:{self.line}: `{self.text}`"


# --- extraction -------------------------------------------------------------------------------


def _command(doc: str, line: int, text: str, inline: bool) -> DocCommand | None:
    text = _LEAD.sub("", text.strip())
    for prefix, kind in PREFIXES.items():
        if text.startswith(prefix):
            return DocCommand(doc, line, text, kind, inline)
    return None


def _fenced_lines(lines: list[tuple[int, str]]) -> Iterator[tuple[int, str]]:
    """The logical lines of a fenced block: a line ending in ``\\`` continues on the next."""
    start = 0
    parts: list[str] = []
    for number, line in lines:
        if not parts:
            start = number
        stripped = line.rstrip()
        if stripped.endswith("\\"):
            parts.append(stripped[:-1])
            continue
        parts.append(line)
        yield start, " ".join(p.strip() for p in parts)
        parts = []
    if parts:
        yield start, " ".join(p.strip() for p in parts)


def _spans(paragraph: list[tuple[int, str]]) -> Iterator[tuple[int, str]]:
    """Inline code spans of a paragraph; a span may run on over a line break."""
    first = paragraph[0][0]
    text = "\n".join(line for _, line in paragraph)
    for match in _SPAN.finditer(text):
        content = match.group(2).replace("\n", " ").replace("\\|", "|").strip()
        yield first + text.count("\n", 0, match.start()), content


def extract_commands(markdown: str, doc: str) -> list[DocCommand]:
    """Every command line of a markdown text, in order."""
    found: list[DocCommand] = []
    fence: str | None = None
    block: list[tuple[int, str]] = []
    paragraph: list[tuple[int, str]] = []

    def end_paragraph() -> None:
        for number, content in _spans(paragraph) if paragraph else ():
            if (command := _command(doc, number, content, inline=True)) is not None:
                found.append(command)
        paragraph.clear()

    for number, line in enumerate(markdown.splitlines(), start=1):
        opening = _FENCE.match(line)
        if fence is None and opening:
            end_paragraph()
            fence = opening.group(1)
            continue
        if fence is not None:
            if line.strip().startswith(fence[0] * len(fence)) and not line.strip().strip(fence[0]):
                for start, logical in _fenced_lines(block):
                    if (command := _command(doc, start, logical, inline=False)) is not None:
                        found.append(command)
                fence, block = None, []
            else:
                block.append((number, line))
            continue
        if line.strip():
            paragraph.append((number, line))
        else:
            end_paragraph()
    end_paragraph()
    return found


# --- tokens -----------------------------------------------------------------------------------


def is_placeholder(token: str) -> bool:
    return (
        "..." in token
        or "…" in token
        or "<" in token
        or ">" in token
        or "path/to/" in token
        or _METAVAR.search(token) is not None
    )


def tokens(text: str) -> list[str]:
    """Shell words, the trailing ``# comment`` and anything after a pipe or redirection
    gone, usage brackets split off as their own ``[`` and ``]`` words."""
    words = shlex.split(text, comments=True)
    out: list[str] = []
    depth = 0
    for word in words:
        if depth == 0 and _END.match(word) and not re.fullmatch(r"<[^<>]+>", word):
            break
        while len(word) > 1 and word.startswith("["):
            out.append("[")
            depth += 1
            word = word[1:]
        closing = len(word) - len(word.rstrip("]"))
        core = word.rstrip("]")
        if core:
            out.append(core)
        out.extend("]" * closing)
        depth -= closing
    return out


#: A word, or a bracket group: its alternatives, each a list of items.
Item: TypeAlias = "str | list[list[Item]]"


def _alternatives(word: str) -> list[str]:
    """``up|down`` -> [up, down]; anything else is itself."""
    if "|" in word and "://" not in word:
        parts = word.split("|")
        if all(parts):
            return parts
    return [word]


def _group(words: list[str]) -> list[Item]:
    """Usage brackets as a tree: a bracket group is a list of alternatives (split on a
    ``|`` word), each a list of items."""
    stack: list[list[list[Item]]] = [[[]]]
    for word in words:
        if word == "[":
            stack.append([[]])
        elif word == "]" and len(stack) > 1:
            group = stack.pop()
            stack[-1][-1].append(group)
        elif word == "|" and len(stack) > 1:
            stack[-1].append([])
        else:
            stack[-1][-1].append(word)
    while len(stack) > 1:  # an unclosed bracket: take it as closed
        group = stack.pop()
        stack[-1][-1].append(group)
    return stack[0][0]


def expand(words: list[str]) -> list[list[str]]:
    """The forms a usage line stands for: without its optional parts, then with each
    optional part (each alternative) in its place; each ``a|b`` word once per alternative."""
    return _expand(_group(words))


def _expand(items: list[Item]) -> list[list[str]]:
    base = [item for item in items if isinstance(item, str)]
    forms: list[list[str]] = []
    for i, word in enumerate(base):  # each alternative of a word once, the others' first
        for alternative in _alternatives(word)[1:]:
            forms.append([*base[:i], alternative, *base[i + 1 :]])
    forms.insert(0, [_alternatives(word)[0] for word in base])
    for g, item in enumerate(items):
        if isinstance(item, str):
            continue
        before = [_alternatives(w)[0] for w in items[:g] if isinstance(w, str)]
        after = [_alternatives(w)[0] for w in items[g + 1 :] if isinstance(w, str)]
        for option in item:
            forms.extend([*before, *sub, *after] for sub in _expand(option))
    unique: list[list[str]] = []
    for form in forms:
        if form not in unique:
            unique.append(form)
    return unique


def _flat(words: list[str]) -> list[str]:
    """Every word of a usage line, brackets and ``|`` words dropped, alternatives split."""
    return [alt for w in words if w not in ("[", "]", "|") for alt in _alternatives(w)]


def repo_path_problems(words: list[str]) -> list[str]:
    """Arguments that look like repository paths and are not there."""
    problems = []
    previous = ""
    for word in _flat(words):
        option, _, value = word.partition("=") if word.startswith("--") else ("", "", word)
        if option and not value:
            previous = option
            continue
        is_output = (option or previous) in OUTPUT_OR_USER_OPTIONS
        previous = ""
        value = re.sub(r"(\.py):[A-Za-z_]\w*$", r"\1", value)  # path/to/file.py:Name
        if (
            is_output
            or is_placeholder(value)
            or "://" in value
            or value.startswith("/")
            or not (value.endswith(_REPO_SUFFIXES) or value.startswith(_REPO_DIRS))
        ):
            continue
        if not (ROOT / value).exists():
            problems.append(f"{value} is not in the repository")
    return problems


# --- railpilot --------------------------------------------------------------------------------


@functools.cache
def cli_parser() -> argparse.ArgumentParser:
    from railpilot.cli import build_parser

    return build_parser()


def parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace | str | None:
    """What ``argv`` parses to, argparse's error if it does not, None for ``--help`` and
    ``--version``. Nothing is run."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            return parser.parse_args(argv)
        except SystemExit as exc:
            if exc.code in (0, None):
                return None
            lines = err.getvalue().strip().splitlines()
            return lines[-1] if lines else f"exit {exc.code}"


def value_problems(args: argparse.Namespace) -> list[str]:
    """Values the parser takes as text and a command reads itself before it runs:
    ``drive``'s ``--tsr`` and ``--target``."""
    from railpilot.commands.drive import parse_target, parse_tsr
    from railpilot.errors import RailpilotError

    found = []
    if args.command == "drive":
        for read, values in ((parse_tsr, args.tsr), (parse_target, args.target)):
            for value in values:
                try:
                    read(value)
                except RailpilotError as exc:
                    found.append(str(exc))
    return found


def name_problems(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """For a command with placeholders or one a sentence only names: each subcommand
    exists, each option exists for its subcommand, each literal value of an option or
    positional with choices is one of them. Missing arguments are not looked for."""
    problems: list[str] = []
    path = ["railpilot"]
    positionals = [a for a in parser._actions if not a.option_strings]
    i = 0
    while i < len(argv):
        word = argv[i]
        i += 1
        if word.startswith("-") and word != "-" and not re.fullmatch(r"-[\d.]+", word):
            name = word.split("=", 1)[0]
            action = parser._option_string_actions.get(name)
            if action is None:
                problems.append(f"`{' '.join(path)}` has no option {name}")
                continue
            if action.nargs == 0 or "=" in word:
                continue
            if i < len(argv) and not argv[i].startswith("--"):
                value = argv[i]
                i += 1
                if action.choices and not is_placeholder(value) and value not in action.choices:
                    problems.append(f"{name} {value}: not one of {sorted(action.choices)}")
            continue
        if not positionals:
            continue  # more words than arguments: not looked at
        action = positionals[0]
        if action.nargs not in ("*", "+", argparse.REMAINDER):
            positionals.pop(0)
        if is_placeholder(word):
            if isinstance(action, argparse._SubParsersAction):
                break  # which subcommand is not known: nothing further can be checked
            continue
        if isinstance(action, argparse._SubParsersAction):
            if word not in action.choices:
                problems.append(f"`{' '.join(path)}` has no subcommand {word!r}")
                break
            parser = action.choices[word]
            path.append(word)
            positionals = [a for a in parser._actions if not a.option_strings]
        elif action.choices and word not in action.choices:
            problems.append(f"{word!r} is not one of {sorted(action.choices)}")
    return problems


_INCOMPLETE = ("the following arguments are required", "expected one argument")


def railpilot_problems(command: DocCommand) -> list[str]:
    words = tokens(command.text)
    parser = cli_parser()
    problems: list[str] = []
    for form in expand(words):
        argv = form[1:]
        # exact names always (argparse would take `--seed` for a `--seeds` it was renamed to)
        problems.extend(p for p in name_problems(parser, argv) if p not in problems)
        if any(is_placeholder(w) for w in argv):
            continue
        parsed = parse(parser, argv)
        if isinstance(parsed, argparse.Namespace):
            problems.extend(value_problems(parsed))
        elif parsed is not None and not (command.inline and any(s in parsed for s in _INCOMPLETE)):
            # (a sentence may name a command or an option without all its arguments:
            # `railpilot drive`, `railpilot ground serve --http-port`)
            problems.append(f"`railpilot {shlex.join(argv)}`: {parsed}")
    return problems + repo_path_problems(words)


# --- python benchmarks/x.py, python -m railpilot.x --------------------------------------------


@functools.cache
def declared_options(source_file: Path) -> frozenset[str]:
    """The option strings of every ``add_argument`` call in a file."""
    tree = ast.parse(source_file.read_text(encoding="utf-8"))
    return frozenset(
        arg.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == "add_argument"
        for arg in node.args
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and arg.value[:1] == "-"
    )


def _option_problems(source_file: Path, words: list[str]) -> list[str]:
    declared = declared_options(source_file)
    problems = []
    for word in _flat(words):
        if word.startswith("-") and word != "-" and not re.fullmatch(r"-[\d.]+", word):
            name = word.split("=", 1)[0]
            if name not in declared and name not in ("-h", "--help"):
                rel = source_file.relative_to(ROOT)
                problems.append(f"{rel} has no option {name} (it has {sorted(declared)})")
    return problems


def benchmark_problems(command: DocCommand) -> list[str]:
    words = tokens(command.text)
    script = ROOT / words[1]
    if not script.is_file():
        return [f"{words[1]} is not in the repository"]
    return _option_problems(script, words[2:]) + repo_path_problems(words[2:])


def python_m_problems(command: DocCommand) -> list[str]:
    words = tokens(command.text)
    module = words[2]
    base = ROOT / "src" / Path(*module.split("."))
    if module == "railpilot":  # `python -m railpilot ARGS` is the CLI
        if not (base / "__main__.py").is_file():
            return ["src/railpilot/__main__.py is not there: `python -m railpilot` does not run"]
        return railpilot_problems(
            DocCommand(command.doc, command.line, shlex.join(["railpilot", *words[3:]]), "", False)
        )
    for source in (base.with_suffix(".py"), base / "__main__.py"):
        if source.is_file():
            return _option_problems(source, words[3:]) + repo_path_problems(words[3:])
    return [f"no module {module} in src/ (neither {module.replace('.', '/')}.py nor __main__.py)"]


# --- make -------------------------------------------------------------------------------------


@functools.cache
def make_targets() -> frozenset[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return frozenset(re.findall(r"^([A-Za-z0-9_.-]+):(?!=)", text, re.MULTILINE))


def make_problems(command: DocCommand) -> list[str]:
    words = _flat(tokens(command.text))[1:]
    targets = [w for w in words if not w.startswith("-") and "=" not in w]
    return [f"the Makefile has no target {t!r}" for t in targets if t not in make_targets()]


# --- the check --------------------------------------------------------------------------------

CHECKS = {
    "railpilot": railpilot_problems,
    "benchmark": benchmark_problems,
    "python -m": python_m_problems,
    "make": make_problems,
}


def problems(command: DocCommand) -> list[str]:
    try:
        return CHECKS[command.kind](command)
    except ValueError as exc:  # shlex: an unbalanced quote
        return [f"not a shell command line: {exc}"]


def _doc_commands() -> list[DocCommand]:
    found = []
    for doc in DOCS:
        found.extend(extract_commands(doc.read_text(encoding="utf-8"), str(doc.relative_to(ROOT))))
    return found


DOC_COMMANDS = _doc_commands()


def _ids(commands: list[DocCommand]) -> list[str]:
    ids: list[str] = []
    for c in commands:
        base = f"{c.doc}:{c.line}"
        n = sum(1 for i in ids if i == base or i.startswith(base + "#"))
        ids.append(base if n == 0 else f"{base}#{n + 1}")
    return ids


@pytest.mark.parametrize("command", DOC_COMMANDS, ids=_ids(DOC_COMMANDS))
def test_a_command_the_docs_give_works(
    command: DocCommand, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)  # relative paths (`--out out`) as from the repository root
    found = problems(command)
    assert not found, f"{command.where}:\n  " + "\n  ".join(found)


def test_the_docs_give_commands_of_every_kind() -> None:
    kinds = {c.kind for c in DOC_COMMANDS}
    assert kinds >= {"railpilot", "benchmark", "make"}, kinds
    assert len(DOC_COMMANDS) > 100


# --- the checker itself -----------------------------------------------------------------------

SAMPLE = """\
# A sample doc

```sh
railpilot simulate examples/heavy_haul_run.toml --json     # a comment
railpilot simulate examples/heavy_haul_run.toml --no-such-flag
railpilot simulate examples/no_such_file.toml --out out/new_dir
railpilot line simulate examples/line_short_day.toml \\
    --runs 2 --json | tail -n 1
railpilot simulate SCENARIO.toml [--out DIR] [--jsonn]
railpilot link decode capture.hex [--json] [--hex | --rawx] > decoded.txt
railpilot onboard run --server 127.0.0.1:7400 --train-id 1 --direction up|sideways
make demo
make no-such-target
python benchmarks/sim_speed.py --repeat 3
python benchmarks/sim_speed.py --no-such
python benchmarks/no_such.py
.venv/bin/python benchmarks/plan_speed.py --repeat 2
python -m railpilot.no.such.module
```

Prose with `railpilot drive heavy-haul --from 1
--to 2 --running-timee 60` across a line break, and names: `railpilot drive`,
`railpilot ground serve --http-port`, `railpilot ground serve --http-portt`,
`railpilot line simulate ... --runs 100`, `railpilot reproduce no-such-result`,
`railpilot/cluster.py`, `make`s and `pythonic`.
`railpilot drive heavy-haul --from 1 --to 2 --tsr 102.0:100.0:60 --target 101.5@60`
"""


def _sample_problems() -> dict[str, list[str]]:
    return {c.text: problems(c) for c in extract_commands(SAMPLE, "sample.md")}


def test_the_sample_s_commands_are_extracted_with_their_lines() -> None:
    found = [(c.line, c.kind, c.inline) for c in extract_commands(SAMPLE, "sample.md")]
    assert found == [
        (4, "railpilot", False),
        (5, "railpilot", False),
        (6, "railpilot", False),
        (7, "railpilot", False),  # continued on line 8
        (9, "railpilot", False),
        (10, "railpilot", False),
        (11, "railpilot", False),
        (12, "make", False),
        (13, "make", False),
        (14, "benchmark", False),
        (15, "benchmark", False),
        (16, "benchmark", False),
        (17, "benchmark", False),
        (18, "python -m", False),
        (21, "railpilot", True),  # runs on to line 22
        (22, "railpilot", True),
        (23, "railpilot", True),
        (23, "railpilot", True),
        (24, "railpilot", True),
        (24, "railpilot", True),
        (26, "railpilot", True),
    ]


def test_the_checker_passes_commands_that_work() -> None:
    found = _sample_problems()
    for text in (
        "railpilot simulate examples/heavy_haul_run.toml --json     # a comment",
        "railpilot line simulate examples/line_short_day.toml --runs 2 --json | tail -n 1",
        "make demo",
        "python benchmarks/sim_speed.py --repeat 3",
        ".venv/bin/python benchmarks/plan_speed.py --repeat 2",
        "railpilot drive",
        "railpilot ground serve --http-port",
        "railpilot line simulate ... --runs 100",
    ):
        assert found[text.removeprefix(".venv/bin/")] == [], text


def test_the_checker_finds_broken_commands() -> None:
    found = _sample_problems()
    expected = {
        "railpilot simulate examples/heavy_haul_run.toml --no-such-flag": "--no-such-flag",
        "railpilot simulate examples/no_such_file.toml --out out/new_dir": "no_such_file.toml",
        "railpilot simulate SCENARIO.toml [--out DIR] [--jsonn]": "no option --jsonn",
        "railpilot link decode capture.hex [--json] [--hex | --rawx] > decoded.txt": "--rawx",
        "railpilot onboard run --server 127.0.0.1:7400 --train-id 1 --direction up|sideways": (
            "sideways"
        ),
        "make no-such-target": "no target 'no-such-target'",
        "python benchmarks/sim_speed.py --no-such": "has no option --no-such",
        "python benchmarks/no_such.py": "benchmarks/no_such.py is not in the repository",
        "python -m railpilot.no.such.module": "no module railpilot.no.such.module",
        "railpilot drive heavy-haul --from 1 --to 2 --running-timee 60": "--running-timee",
        "railpilot ground serve --http-portt": "--http-portt",
        "railpilot reproduce no-such-result": "no-such-result",
        "railpilot drive heavy-haul --from 1 --to 2 --tsr 102.0:100.0:60 --target 101.5@60": (
            "--tsr = '102.0:100.0:60'"
        ),
    }
    for text, needle in expected.items():
        assert any(needle in p for p in found[text]), (text, found[text])
    # nothing else in the sample is reported: the output folder, the comment, the pipe
    # and the placeholders are not taken for broken paths or arguments
    assert not [p for t, ps in found.items() if t not in expected for p in ps]
    assert found["railpilot simulate examples/no_such_file.toml --out out/new_dir"] == [
        "examples/no_such_file.toml is not in the repository"
    ]


def test_usage_notation_is_expanded_into_each_form() -> None:
    words = tokens("railpilot link decode x.hex [--keys k.toml] [--hex | --raw] --dir up|down")
    assert expand(words) == [
        ["railpilot", "link", "decode", "x.hex", "--dir", "up"],
        ["railpilot", "link", "decode", "x.hex", "--dir", "down"],
        ["railpilot", "link", "decode", "x.hex", "--keys", "k.toml", "--dir", "up"],
        ["railpilot", "link", "decode", "x.hex", "--hex", "--dir", "up"],
        ["railpilot", "link", "decode", "x.hex", "--raw", "--dir", "up"],
    ]


@pytest.mark.parametrize(
    ("word", "placeholder"),
    [
        ("SCENARIO.toml", True),
        ("DIR", True),
        ("HOST:PORT", True),
        ("N-1", True),
        ("...", True),
        ("<file>", True),
        ("path/to/file.py:Name", True),
        ("K1234", False),
        ("SS4-0001", False),
        ("hold at Datong", False),
        ("examples/heavy_haul_day.toml", False),
        ("postgresql://ground@db.example/railpilot", False),
        ("100.0:102.0:60@5000", False),
    ],
)
def test_the_placeholder_rule(word: str, placeholder: bool) -> None:
    assert is_placeholder(word) is placeholder
