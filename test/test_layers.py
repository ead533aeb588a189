"""Imports point down the floors (issue 16; README "Layout"):

    apps -> nodes -> ros -> core      paper -> core      (apps may use every floor)

* core imports nothing from paper, ros, nodes, apps, and no ROS package;
* paper imports nothing from ros, nodes, apps, and no ROS package;
* ros imports nothing from nodes, apps, paper;
* nodes import nothing from apps, and nothing from paper except nodes/sensor_sim.py (the
  simulator runs the paper's scenarios);
* the top-level package imports no floor (every module imports it).

Every module's source is parsed (no import is executed): `import` statements anywhere
(also inside functions and `if TYPE_CHECKING:`), relative imports resolved, and
`importlib.import_module` calls whose module name is a literal or starts with one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "ssa_fusion"

ROS = ("rclpy", "rcl_interfaces", "rosidl_runtime_py", "builtin_interfaces", "std_msgs",
       "rosgraph_msgs", "diagnostic_msgs", "ssa_fusion_msgs", "rosbags", "mcap_ros2",
       "launch", "launch_ros", "ament_index_python")
"""ROS packages (and ROS bag libraries): none in core or paper."""

FLOORS = ("core", "paper", "ros", "nodes", "apps")

FORBIDDEN: dict[str, tuple[str, ...]] = {
    "core": ("ssa_fusion.paper", "ssa_fusion.ros", "ssa_fusion.nodes", "ssa_fusion.apps", *ROS),
    "paper": ("ssa_fusion.ros", "ssa_fusion.nodes", "ssa_fusion.apps", *ROS),
    "ros": ("ssa_fusion.nodes", "ssa_fusion.apps", "ssa_fusion.paper"),
    "nodes": ("ssa_fusion.apps", "ssa_fusion.paper"),
    "": tuple(f"ssa_fusion.{floor}" for floor in FLOORS),
}
"""Per floor ("" = the top-level package), the module prefixes its modules may not import."""

ALLOWED: dict[str, tuple[str, ...]] = {"ssa_fusion.nodes.sensor_sim": ("ssa_fusion.paper",)}
"""Exceptions by module: the prefixes it may import all the same."""


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def floor_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in FLOORS else ""


def imports_of(source: str, module: str, is_package: bool = False) -> set[str]:
    """Every module name `source` (the text of `module`) imports, anywhere in it. For
    ``from X import a`` both X and X.a (a may be a submodule)."""
    package = module if is_package else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "import_module" and node.args):
            arg = node.args[0]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                found.add(arg.value)
            elif (isinstance(arg, ast.JoinedStr) and arg.values
                  and isinstance(arg.values[0], ast.Constant)):
                found.add(str(arg.values[0].value).rstrip("."))
    return found


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def violations(module: str, imported: set[str]) -> list[str]:
    """The imports of `module` that break the rules, as 'module imports name'."""
    forbidden = FORBIDDEN.get(floor_of(module), ())
    allowed = ALLOWED.get(module, ())
    return sorted(
        f"{module} imports {name}"
        for name in imported
        if any(_under(name, p) for p in forbidden) and not any(_under(name, p) for p in allowed)
    )


def all_modules() -> dict[str, tuple[str, bool]]:
    """{module name: (source, is_package)} of every module of ssa_fusion."""
    return {module_name(p): (p.read_text(), p.name == "__init__.py")
            for p in sorted(PACKAGE.rglob("*.py"))}


def test_every_floor_is_found():
    floors = {floor_of(m) for m in all_modules()}
    assert floors == {"", *FLOORS}


def test_imports_point_down():
    found = []
    for module, (source, is_package) in all_modules().items():
        found += violations(module, imports_of(source, module, is_package))
    assert not found, "imports against the floors:\n" + "\n".join(found)


def test_only_sensor_sim_among_the_nodes_uses_the_paper():
    users = [m for m, (src, pkg) in all_modules().items()
             if floor_of(m) == "nodes"
             and any(_under(n, "ssa_fusion.paper") for n in imports_of(src, m, pkg))]
    assert users == ["ssa_fusion.nodes.sensor_sim"]


# The checker itself: each of these imports must be found, and each must break the rules.
BAD = [
    ("ssa_fusion.core.x", "from ssa_fusion.paper import scenarios"),
    ("ssa_fusion.core.x", "from ssa_fusion import paper"),
    ("ssa_fusion.core.x", "from ..paper.scenarios import STATIONS"),
    ("ssa_fusion.core.x", "def f():\n    import rclpy.node\n"),
    ("ssa_fusion.core.x", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                          "    from ssa_fusion.ros import messages\n"),
    ("ssa_fusion.paper.x", "import ssa_fusion.nodes.common"),
    ("ssa_fusion.paper.x", "from rclpy.node import Node"),
    ("ssa_fusion.ros.x", "from ssa_fusion.paper import scenarios"),
    ("ssa_fusion.ros.x", "from ..apps import cli"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.paper import scenarios"),
    ("ssa_fusion.nodes.common", "import importlib\nimportlib.import_module('ssa_fusion.paper')"),
    ("ssa_fusion.nodes.entry", "import importlib\n"
                               "importlib.import_module(f'ssa_fusion.apps.{name}')"),
    ("ssa_fusion.nodes.sensor_sim", "from ssa_fusion.apps import live"),
    ("ssa_fusion", "from ssa_fusion.core import types"),
]
GOOD = [
    ("ssa_fusion.core.x", "from .frames import COLUMBUS\nimport numpy"),
    ("ssa_fusion.paper.x", "from ssa_fusion.core import dynamics"),
    ("ssa_fusion.ros.x", "import rclpy\nfrom ssa_fusion.core import types"),
    ("ssa_fusion.nodes.sensor_sim", "from ssa_fusion.paper import scenarios"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.ros import messages\nimport rclpy"),
    ("ssa_fusion.apps.x", "from ssa_fusion.paper import scenarios\nfrom ssa_fusion import nodes"),
]


@pytest.mark.parametrize(("module", "source"), BAD)
def test_checker_finds_an_import_against_the_floors(module, source):
    assert violations(module, imports_of(source, module))


@pytest.mark.parametrize(("module", "source"), GOOD)
def test_checker_lets_allowed_imports_pass(module, source):
    assert not violations(module, imports_of(source, module))
