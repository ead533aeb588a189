"""The docs against the tree and the command line, without running anything.

* Layout: the first code block of docs/LAYOUT.md's "## The tree" section names every module
  file of the package (``__init__.py`` aside) and every module it names exists. An entry starts
  with an unindented line ``ssa_fusion/<path>/`` (a package: a floor such as ``core/``, a
  room such as ``core/earth/``, or deeper, ``formats/ccsds/``) or ``ssa_fusion/<name>.py`` (a
  module of the top-level package), and goes on over the indented lines below it. A module is
  named by its path from the entry's package: ``frames.py`` in the entry of
  ``ssa_fusion/core/earth/``, or ``earth/frames.py`` in that of ``ssa_fusion/core/``. Every
  package of the tree (every directory with an ``__init__.py``) has an entry of its own, and
  the other entries (``msg_defs/``, ``config/``, ...) must name paths that exist.
* Commands: every ``ssa-fusion ...`` (or ``.venv/bin/ssa-fusion ...``) line of the code blocks
  of README.md and of every page in docs/ names an existing subcommand and only options its
  parser knows: each is parsed by `ssa_fusion.apps.cli.build_parser`, never run.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from ssa_fusion.apps.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "ssa_fusion"
README = ROOT / "README.md"
LAYOUT = ROOT / "docs" / "LAYOUT.md"
COMMAND_DOCS = (README, *sorted((ROOT / "docs").glob("*.md")))

PLACEHOLDERS = {"BAG", "FILE", "OUT", "DIR"}
"""Path placeholders of the docs' command lines, parsed as a dummy path."""


def code_blocks(text: str) -> list[str]:
    """The fenced code blocks of a markdown text, in order."""
    return re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.M | re.S)


def layout_block(doc: str) -> str:
    """The first code block of the "## The tree" section of a markdown text."""
    start = doc.index("\n## The tree\n")
    end = doc.find("\n## ", start + 1)
    blocks = code_blocks(doc[start:] if end == -1 else doc[start:end])
    assert blocks, "the layout's section has no code block"
    return blocks[0]


def layout_entries(block: str) -> dict[str, str]:
    """{first word: text} of a layout block's entries: an unindented line and the indented
    lines after it."""
    entries: dict[str, str] = {}
    key = ""
    for line in block.splitlines():
        if not line.strip():
            continue
        if line[0].isspace():
            assert key, f"the layout block starts with an indented line: {line!r}"
            entries[key] += "\n" + line
        else:
            key = line.split()[0]
            assert key not in entries, f"{key} has two entries in the layout"
            entries[key] = line
    return entries


def listed_modules(entries: dict[str, str]) -> set[str]:
    """The module files the entries name, as paths from the package (``core/earth/frames.py``,
    ``graphs.py``)."""
    listed: set[str] = set()
    for key, text in entries.items():
        package = re.fullmatch(r"ssa_fusion/([\w/]+/)", key)
        if package:
            body = text[len(key):]
            listed |= {package.group(1) + name
                       for name in re.findall(r"(?<![\w./-])([\w/]+\.py)\b", body)}
        elif re.fullmatch(r"ssa_fusion/\w+\.py", key):
            listed.add(key.removeprefix("ssa_fusion/"))
    return listed


def listed_packages(entries: dict[str, str]) -> set[str]:
    """The packages that have an entry of their own, as paths from the package
    (``core/earth``)."""
    return {m.group(1) for key in entries if (m := re.fullmatch(r"ssa_fusion/([\w/]+)/", key))}


def tree_modules(package: Path) -> set[str]:
    """The module files of the package on disk, as paths from it."""
    return {path.relative_to(package).as_posix() for path in package.rglob("*.py")
            if path.name != "__init__.py" and "__pycache__" not in path.parts}


def tree_packages(package: Path) -> set[str]:
    """The packages under the package on disk (directories with an ``__init__.py``)."""
    return {path.parent.relative_to(package).as_posix()
            for path in package.rglob("__init__.py") if path.parent != package}


def differences(tree: set[str], listed: set[str]) -> tuple[list[str], list[str]]:
    """(modules the tree has and the layout does not name where they are,
    modules the layout names that the tree does not have there)."""
    return ([f"ssa_fusion/{name}" for name in sorted(tree - listed)],
            [f"ssa_fusion/{name}" for name in sorted(listed - tree)])


def doc_layout() -> dict[str, str]:
    return layout_entries(layout_block(LAYOUT.read_text(encoding="utf-8")))


def test_the_layout_names_every_module_where_it_is() -> None:
    missing, _ = differences(tree_modules(PACKAGE), listed_modules(doc_layout()))
    assert not missing, f"docs/LAYOUT.md does not name, where they are: {missing}"


def test_every_module_the_layout_names_exists() -> None:
    _, ghosts = differences(tree_modules(PACKAGE), listed_modules(doc_layout()))
    assert not ghosts, f"docs/LAYOUT.md names modules the tree does not have: {ghosts}"


def test_every_package_has_its_entry_and_every_entry_exists() -> None:
    entries = doc_layout()
    without = sorted(tree_packages(PACKAGE) - listed_packages(entries))
    assert not without, f"docs/LAYOUT.md has no entry for the packages {without}"
    assert "ssa_fusion/graphs.py" in entries
    absent = [key for key in entries if not (ROOT / key).exists()]
    assert not absent, f"docs/LAYOUT.md names paths that do not exist: {absent}"


def test_the_layout_comparison_finds_a_missing_a_misplaced_and_an_invented_module(
        tmp_path: Path) -> None:
    package = tmp_path / "ssa_fusion"
    for name in ("__init__.py", "graphs.py", "core/__init__.py", "core/a.py", "core/b.py",
                 "core/earth/__init__.py", "core/earth/frames.py", "core/earth/sun.py",
                 "core/base/__init__.py", "core/base/types.py", "nodes/__init__.py",
                 "nodes/base.py"):
        (package / name).parent.mkdir(parents=True, exist_ok=True)
        (package / name).write_text("")
    block = ("ssa_fusion/core/   the library: a.py, earth/frames.py,\n"
             "                   c.py (a note, not.a module)\n"
             "ssa_fusion/core/earth/  the Earth: sun.py, types.py\n"
             "ssa_fusion/nodes/  nodes: b.py, base.py\n"
             "msg_defs/          messages: x.py is not a package module\n")
    entries = layout_entries(block)
    listed = listed_modules(entries)
    assert listed == {"core/a.py", "core/c.py", "core/earth/frames.py", "core/earth/sun.py",
                      "core/earth/types.py", "nodes/b.py", "nodes/base.py"}
    missing, ghosts = differences(tree_modules(package), listed)
    assert missing == ["ssa_fusion/core/b.py", "ssa_fusion/core/base/types.py",
                       "ssa_fusion/graphs.py"]
    assert ghosts == ["ssa_fusion/core/c.py", "ssa_fusion/core/earth/types.py",
                      "ssa_fusion/nodes/b.py"]
    assert tree_packages(package) - listed_packages(entries) == {"core/base"}


def command_lines(doc: Path) -> list[str]:
    """The `ssa-fusion` command lines of `doc`'s code blocks (continuations joined, comments
    and anything before the command, such as environment settings, left out)."""
    found = []
    for block in code_blocks(doc.read_text(encoding="utf-8")):
        for line in block.replace("\\\n", " ").splitlines():
            if "ssa-fusion" not in line:
                continue  # output and other tools' lines, which need not be shell words
            words = shlex.split(line, comments=True)
            for i, word in enumerate(words):
                if Path(word).name == "ssa-fusion":
                    if all(re.fullmatch(r"\w+=.*", before) for before in words[:i]):
                        found.append(shlex.join(words[i:]))
                    break
    return found


def _docs_command_lines() -> list[tuple[str, str]]:
    return [(doc.relative_to(ROOT).as_posix(), line)
            for doc in COMMAND_DOCS for line in command_lines(doc)]


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()


def _parses(parser: argparse.ArgumentParser, args: list[str]) -> str:
    """'' if `args` parse, else argparse's complaint."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser.parse_args(args)
        except SystemExit as exc:
            return f"exit {exc.code}: {err.getvalue().strip()}"
    return ""


def test_the_docs_show_command_lines() -> None:
    assert len(command_lines(README)) >= 5
    assert len(command_lines(ROOT / "docs" / "CCSDS.md")) >= 5
    assert len(_docs_command_lines()) >= 60


@pytest.mark.parametrize(("doc", "line"), _docs_command_lines())
def test_a_command_line_of_the_docs_parses(parser: argparse.ArgumentParser, doc: str,
                                           line: str) -> None:
    args = [word for word in shlex.split(line)[1:] if word != "..."]
    args = ["placeholder_path" if word in PLACEHOLDERS else word for word in args]
    complaint = _parses(parser, args)
    assert not complaint, f"{doc}: `{line}` does not parse ({complaint})"


def test_an_unknown_subcommand_or_option_does_not_parse(parser: argparse.ArgumentParser) -> None:
    assert _parses(parser, ["live", "--time-scale", "10"]) == ""
    assert _parses(parser, ["live", "--no-such-option"])
    assert _parses(parser, ["no-such-command"])
    assert _parses(parser, ["export", "oem", "placeholder_path", "--frame", "NOT_A_FRAME"])
