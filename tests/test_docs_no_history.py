"""docs/ and src/ name no issue number and no commit: history belongs in git log.

A user's manual says what a part does and how to use it; "issue 12", "#12" or a commit
hash point a reader at a history they do not have. This test finds, in every text file of
docs/ and src/ (and README.md):

- an issue number: "issue 12", "issues 9 and 10", "Issue #12", or "#12" standing alone
  (looked for in ``.md`` and ``.py`` files only, and not a colour such as ``color: #333;``
  nor a protocol check's number such as "check #8");
- a git commit: a word of 7-40 lower-case hex digits that is the prefix of a commit in
  ``git log --format=%H`` of this repository. Other hex words (a SHA-256 of a data file, a
  frame in hex, a DOI's digits) are data and are allowed.

A failure lists every place as ``path:line: text``.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_ISSUE = re.compile(r"\bissues?\s+#?\d+(?:\s*(?:,|and|or)\s*#?\d+)*", re.IGNORECASE)
#: "#12" alone; not a colour (``color: #222;``), an anchor, an entity, nor a protocol check's
#: number ("check #8", "5.4 #13": the frame checks of the protocol's section 5.4)
_HASH_ISSUE = re.compile(r"(?<![\w&#/:])(?<!: )(?<!check )(?<!checks )(?<!\d\.\d )#\d+\b(?![\w;-])")
_HEX_WORD = re.compile(r"(?<![0-9A-Za-z_])[0-9a-f]{7,40}(?![0-9A-Za-z_])")
_TEXT_SUFFIXES = {".py", ".md", ".toml", ".txt", ".html", ".js", ".css", ".sql", ".json"}
_HASH_ISSUE_SUFFIXES = {".py", ".md"}


def _files() -> list[Path]:
    found = [ROOT / "README.md"]
    for folder in (ROOT / "docs", ROOT / "src"):
        found.extend(
            p
            for p in sorted(folder.rglob("*"))
            if p.is_file() and p.suffix in _TEXT_SUFFIXES and "__pycache__" not in p.parts
        )
    return found


def _commits() -> frozenset[str]:
    git = shutil.which("git")
    if git is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: no commits to look for")
    out = subprocess.run(
        [git, "log", "--all", "--format=%H"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return frozenset(out.split())


def issue_references(text: str, suffix: str) -> list[tuple[int, str]]:
    """(line, the words) of every issue number in a text."""
    found: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        found.extend((number, m.group(0)) for m in _ISSUE.finditer(line))
        if suffix in _HASH_ISSUE_SUFFIXES:
            rest = _ISSUE.sub(" ", line)  # "issue #7" is counted once, above
            found.extend((number, m.group(0)) for m in _HASH_ISSUE.finditer(rest))
    return found


def commit_references(text: str, commits: frozenset[str]) -> list[tuple[int, str]]:
    """(line, the word) of every hex word that is the prefix of one of ``commits``."""
    prefixes: dict[int, frozenset[str]] = {}
    found: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        for match in _HEX_WORD.finditer(line):
            word = match.group(0)
            if len(word) not in prefixes:
                prefixes[len(word)] = frozenset(c[: len(word)] for c in commits)
            if word in prefixes[len(word)]:
                found.append((number, word))
    return found


def _report(kind: str, places: list[str]) -> str:
    return f"{len(places)} {kind} (history belongs in git log):\n  " + "\n  ".join(places)


def test_no_issue_number_in_docs_or_src() -> None:
    places = []
    for path in _files():
        text = path.read_text(encoding="utf-8", errors="replace")
        for number, words in issue_references(text, path.suffix):
            places.append(f"{path.relative_to(ROOT)}:{number}: {words}")
    assert not places, _report("issue numbers", places)


def test_no_commit_hash_in_docs_or_src() -> None:
    commits = _commits()
    places = []
    for path in _files():
        text = path.read_text(encoding="utf-8", errors="replace")
        for number, word in commit_references(text, commits):
            places.append(f"{path.relative_to(ROOT)}:{number}: {word}")
    assert not places, _report("commit hashes", places)


# --- the checks themselves ----------------------------------------------------------------


def test_issue_numbers_are_found_in_their_forms() -> None:
    text = "see issue 12\nIssues 9 and 10 too\nissue #7\nas #12 says\n(#3)\n"
    assert [w for _, w in issue_references(text, ".md")] == [
        "issue 12",
        "Issues 9 and 10",
        "issue #7",
        "#12",
        "#3",
    ]


def test_what_is_not_an_issue_number_is_left_alone() -> None:
    text = (
        "colour: #333;\nan anchor docs/x.md#3-limits\n&#12; an entity\nissue tracker\n"
        "check #8 of 5.4, spec 5.4 #13\n"
    )
    assert issue_references(text, ".md") == []
    assert issue_references("see #333", ".css") == []


def test_a_commit_prefix_is_found_and_other_hex_is_not() -> None:
    commits = frozenset({"4b28624c0ffee0123456789abcdef0123456789a"})
    text = (
        "measured on `4b28624`\n"
        "the frame 4b28624c0ffee0\n"
        "sha256 4b28624c0ffee0123456789abcdef0123456789a0123456789abcdef01234567\n"
        "deadbeef and 1234567\n"
    )
    assert commit_references(text, commits) == [(1, "4b28624"), (2, "4b28624c0ffee0")]
