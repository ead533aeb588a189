"""README.md against the tree and the command line, without running anything.

* Layout: the first code block of README's "## Layout" section names every module file of
  the package (``__init__.py`` aside) under its floor, and every module it names exists
  there. A floor's entry starts with a line ``ssa_fusion/<floor>/`` (or, for a module of the
  top-level package, ``ssa_fusion/<name>.py``) at the start of the line and goes on over the
  indented lines below it; a module is named by its file name (``tracker.py``). The other
  entries (``msg_defs/``, ``config/``, ...) must name paths that exist.
* Commands: every ``ssa-fusion ...`` (or ``.venv/bin/ssa-fusion ...``) line of the code blocks
  of README.md, docs/CCSDS.md, docs/MULTIHOST.md and docs/CONJUNCTIONS.md names an existing
  subcommand and only options its parser knows: each is parsed by
  `ssa_fusion.apps.cli.build_parser`, never run.
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
COMMAND_DOCS = (README, ROOT / "docs" / "CCSDS.md", ROOT / "docs" / "MULTIHOST.md",
                ROOT / "docs" / "CONJUNCTIONS.md")
FLOORS = ("core", "sim", "evaluation", "studies", "ros", "nodes", "apps")
"""The package's subpackages (test_layers.py's floors but the top-level graphs.py)."""

PLACEHOLDERS = {"BAG", "FILE", "OUT", "DIR"}
"""Path placeholders of the docs' command lines, parsed as a dummy path."""


def code_blocks(text: str) -> list[str]:
    """The fenced code blocks of a markdown text, in order."""
    return re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.M | re.S)


def layout_block(readme: str) -> str:
    """The first code block of the "## Layout" section of a README's text."""
    start = readme.index("\n## Layout\n")
    end = readme.find("\n## ", start + 1)
    blocks = code_blocks(readme[start:] if end == -1 else readme[start:end])
    assert blocks, "README's Layout section has no code block"
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


def listed_modules(entries: dict[str, str]) -> dict[str, set[str]]:
    """{floor: the module files its entry names}; a top-level module is its own floor."""
    listed: dict[str, set[str]] = {}
    for key, text in entries.items():
        floor = re.fullmatch(r"ssa_fusion/(\w+)/", key)
        if floor:
            body = text[len(key):]
            listed[floor.group(1)] = set(re.findall(r"(?<![\w./-])([\w/]+\.py)\b", body))
        elif re.fullmatch(r"ssa_fusion/\w+\.py", key):
            name = key.removeprefix("ssa_fusion/")
            listed[name] = {name}
    return listed


def tree_modules(package: Path) -> dict[str, set[str]]:
    """{floor: the module files under it} of the package on disk."""
    tree: dict[str, set[str]] = {}
    for path in sorted(package.rglob("*.py")):
        if path.name == "__init__.py":
            continue
        parts = path.relative_to(package).parts
        if len(parts) == 1:
            tree[path.name] = {path.name}
        else:
            tree.setdefault(parts[0], set()).add("/".join(parts[1:]))
    return tree


def _paths(modules: dict[str, set[str]]) -> list[str]:
    return sorted(f"ssa_fusion/{name}" if floor == name else f"ssa_fusion/{floor}/{name}"
                  for floor, names in modules.items() for name in names)


def differences(tree: dict[str, set[str]],
                listed: dict[str, set[str]]) -> tuple[list[str], list[str]]:
    """(modules the tree has and the layout does not name under their floor,
    modules the layout names that its floor does not have)."""
    missing = {floor: names - listed.get(floor, set()) for floor, names in tree.items()}
    ghosts = {floor: names - tree.get(floor, set()) for floor, names in listed.items()}
    return _paths(missing), _paths(ghosts)


def readme_layout() -> dict[str, str]:
    return layout_entries(layout_block(README.read_text(encoding="utf-8")))


def test_the_layout_names_every_module_under_its_floor() -> None:
    missing, _ = differences(tree_modules(PACKAGE), listed_modules(readme_layout()))
    assert not missing, f"README's Layout does not name, under their floor: {missing}"


def test_every_module_the_layout_names_exists() -> None:
    _, ghosts = differences(tree_modules(PACKAGE), listed_modules(readme_layout()))
    assert not ghosts, f"README's Layout names modules the tree does not have: {ghosts}"


def test_the_layout_has_every_floor_and_only_paths_that_exist() -> None:
    entries = readme_layout()
    for floor in FLOORS:
        assert f"ssa_fusion/{floor}/" in entries, f"README's Layout has no ssa_fusion/{floor}/"
    assert "ssa_fusion/graphs.py" in entries
    absent = [key for key in entries if not (ROOT / key).exists()]
    assert not absent, f"README's Layout names paths that do not exist: {absent}"


def test_the_layout_comparison_finds_a_missing_a_misplaced_and_an_invented_module(
        tmp_path: Path) -> None:
    package = tmp_path / "ssa_fusion"
    for name in ("__init__.py", "graphs.py", "core/__init__.py", "core/a.py", "core/b.py",
                 "nodes/base.py"):
        (package / name).parent.mkdir(parents=True, exist_ok=True)
        (package / name).write_text("")
    block = ("ssa_fusion/core/   the library: a.py,\n"
             "                   c.py (a note, not.a module)\n"
             "ssa_fusion/nodes/  nodes: b.py, base.py\n"
             "msg_defs/          messages: x.py is not a package module\n")
    listed = listed_modules(layout_entries(block))
    assert listed == {"core": {"a.py", "c.py"}, "nodes": {"b.py", "base.py"}}
    missing, ghosts = differences(tree_modules(package), listed)
    assert missing == ["ssa_fusion/core/b.py", "ssa_fusion/graphs.py"]
    assert ghosts == ["ssa_fusion/core/c.py", "ssa_fusion/nodes/b.py"]


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
    assert len(command_lines(README)) >= 10
    assert len(command_lines(ROOT / "docs" / "CCSDS.md")) >= 5


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
