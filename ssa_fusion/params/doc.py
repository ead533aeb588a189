"""docs/NODES.md's parameter tables, generated from the nodes' own tables.

Each node's section of docs/NODES.md holds its parameters between two markers::

    <!-- parameters filter: generated from ssa_fusion/params/tables/filter.py; do not edit -->
    | name | type | default | unit | range | run time | meaning |
    ...
    <!-- end of parameters filter -->

`render` rewrites what stands between them from the node's table (`tables`), noting where
config/default.yaml sets another value than the default; ``test/params/test_doc.py`` fails
when the doc and the tables differ. After changing a table::

    python -m ssa_fusion.params.doc docs/NODES.md
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from ssa_fusion.params.rows import Computed, Default, ParameterTable
from ssa_fusion.params.tables import NODES, table_of

HEADER = ("| name | type | default | unit | range | run time | meaning |\n"
          "|---|---|---|---|---|---|---|\n")
"""The columns of a parameter table."""
_REGION = re.compile(r"(<!-- parameters (\w+): [^\n]*-->\n)(.*?)(<!-- end of parameters \2 -->)",
                     re.DOTALL)


def begin_marker(node: str) -> str:
    """Return the line that opens `node`'s generated table."""
    return (f"<!-- parameters {node}: generated from ssa_fusion/params/tables/{node}.py; "
            "do not edit -->")


def end_marker(node: str) -> str:
    """Return the line that closes `node`'s generated table."""
    return f"<!-- end of parameters {node} -->"


def _type(value: Default) -> str:
    """Return the ROS type name of a parameter whose default is `value`."""
    if isinstance(value, tuple | list):
        return (_type(value[0]) if value else "double") + "[]"
    return {bool: "bool", int: "integer", float: "double", str: "string"}[type(value)]


def _value(value: object) -> str:
    """Return `value` as the docs write a parameter value."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'`"{value}"`' if not value else f"`{value}`"
    if isinstance(value, tuple | list):
        return "`[" + ", ".join(_value(v).strip("`") for v in value) + "]`"
    return repr(value)


def _cell(text: str) -> str:
    """Return `text` fit for a Markdown table cell."""
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(table: ParameterTable, yaml_values: Mapping[str, Any]) -> str:
    """Return the Markdown table of `table` (`yaml_values`: config/default.yaml's)."""
    rows = []
    for p in table:
        example: Default = p.default.example if isinstance(p.default, Computed) else p.default
        default = p.default.text if isinstance(p.default, Computed) else _value(p.default)
        if p.name in yaml_values and not isinstance(p.default, Computed):
            given = yaml_values[p.name]
            plain = list(p.default) if isinstance(p.default, tuple) else p.default
            if given != plain:
                default += f" (yaml: {_value(given)})"
        cells = (f"`{p.name}`", _type(example), default, p.unit,
                 p.check.text if p.check else "–", "yes" if p.runtime else "no",
                 p.description)
        rows.append("| " + " | ".join(_cell(c) for c in cells) + " |\n")
    return HEADER + "".join(rows)


def _yaml_values(path: Path) -> dict[str, dict[str, Any]]:
    """Return config/default.yaml's ``ros__parameters`` by node."""
    loaded = yaml.safe_load(path.read_text())
    return {node: dict(section.get("ros__parameters") or {}) for node, section in loaded.items()}


def render(doc: str, config: Path) -> str:
    """Return `doc` with every generated table rewritten from the nodes' tables."""
    values = _yaml_values(config)

    def table(match: re.Match[str]) -> str:
        node = match.group(2)
        return (begin_marker(node) + "\n" + markdown(table_of(node), values.get(node, {}))
                + match.group(4))

    return _REGION.sub(table, doc)


def documented(doc: str) -> list[str]:
    """Return the nodes whose generated table `doc` holds, in order."""
    return [m.group(2) for m in _REGION.finditer(doc)]


def main(argv: list[str] | None = None) -> int:
    """Rewrite the tables of a NODES.md (``--check``: exit 1 if they are out of date)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("doc", type=Path, nargs="?", default=Path("docs/NODES.md"))
    parser.add_argument("--config", type=Path, default=None,
                        help="the nodes' params YAML (default: config/default.yaml beside docs/)")
    parser.add_argument("--check", action="store_true", help="only say whether it is current")
    args = parser.parse_args(argv)
    config = args.config or args.doc.resolve().parents[1] / "config" / "default.yaml"
    text = args.doc.read_text()
    missing = [n for n in NODES if n not in documented(text)]
    new = render(text, config)
    if args.check:
        problems = [f"no table of {', '.join(missing)}"] if missing else []
        if new != text:
            problems.append("out of date: run python -m ssa_fusion.params.doc")
        for problem in problems:
            print(f"{args.doc}: {problem}", file=sys.stderr)
        return 1 if problems else 0
    args.doc.write_text(new)
    if missing:
        print(f"{args.doc}: no markers for {', '.join(missing)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
