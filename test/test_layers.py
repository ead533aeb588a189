"""Imports point down the floors (DESIGN.md and README "Layout"):

    apps -> graphs -> nodes -> ros -> core
    studies -> sim, evaluation -> core       (launch files -> graphs, ros.launch_events)

* core imports nothing of the package, and no ROS package;
* sim and evaluation import only the core (and no ROS package);
* studies import core, sim, evaluation (and ros, to read bags), never nodes, graphs or apps;
* ros imports nothing from nodes, graphs, apps, sim, evaluation, studies;
* nodes import ros and core, never apps, graphs, studies or evaluation; sim only in
  nodes/sensor_sim.py (the simulator runs the simulated world);
* graphs (what runs together) imports nodes, ros, sim and core, never apps or studies;
* the launch files import graphs and ros.launch_events only of the package;
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
"""ROS packages (and ROS bag libraries): none in core, sim or evaluation."""

FLOORS = ("core", "sim", "evaluation", "studies", "ros", "nodes", "graphs", "apps")


def _floors(*names: str) -> tuple[str, ...]:
    return tuple(f"ssa_fusion.{n}" for n in names)


FORBIDDEN: dict[str, tuple[str, ...]] = {
    "core": (*_floors("sim", "evaluation", "studies", "ros", "nodes", "graphs", "apps"), *ROS),
    "sim": (*_floors("evaluation", "studies", "ros", "nodes", "graphs", "apps"), *ROS),
    "evaluation": (*_floors("sim", "studies", "ros", "nodes", "graphs", "apps"), *ROS),
    "studies": _floors("nodes", "graphs", "apps"),
    "ros": _floors("nodes", "graphs", "apps", "sim", "evaluation", "studies"),
    "nodes": _floors("apps", "graphs", "studies", "evaluation", "sim"),
    "graphs": _floors("apps", "studies", "evaluation"),
    "": _floors(*FLOORS),
}
"""Per floor ("" = the top-level package), the module prefixes its modules may not import."""

ALLOWED: dict[str, tuple[str, ...]] = {"ssa_fusion.nodes.sensor_sim": ("ssa_fusion.sim",)}
"""Exceptions by module: the prefixes it may import all the same."""

LAUNCH = Path(__file__).resolve().parents[1] / "launch_scripts"
LAUNCH_MAY_IMPORT = ("ssa_fusion.graphs", "ssa_fusion.ros.launch_events")
"""What of the package a launch file may import."""


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


def test_only_sensor_sim_among_the_nodes_uses_the_simulated_world():
    users = [m for m, (src, pkg) in all_modules().items()
             if floor_of(m) == "nodes"
             and any(_under(n, "ssa_fusion.sim") for n in imports_of(src, m, pkg))]
    assert users == ["ssa_fusion.nodes.sensor_sim"]


def test_launch_files_import_only_the_graphs():
    for path in sorted(LAUNCH.glob("*.launch.py")):
        ours = {n for n in imports_of(path.read_text(), "launch_file")
                if _under(n, "ssa_fusion")}
        bad = [n for n in ours if not any(_under(n, p) or _under(p, n)
                                          for p in LAUNCH_MAY_IMPORT)]
        assert not bad, f"{path.name} imports {bad}"
        assert any(_under(n, "ssa_fusion.graphs") for n in ours), path.name


# The checker itself: each of these imports must be found, and each must break the rules.
BAD = [
    ("ssa_fusion.core.x", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.core.x", "from ssa_fusion import studies"),
    ("ssa_fusion.core.x", "from ..sim.scenarios import STATIONS"),
    ("ssa_fusion.core.x", "def f():\n    import rclpy.node\n"),
    ("ssa_fusion.core.x", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                          "    from ssa_fusion.ros import messages\n"),
    ("ssa_fusion.sim.x", "import ssa_fusion.nodes.common"),
    ("ssa_fusion.sim.x", "from rclpy.node import Node"),
    ("ssa_fusion.sim.x", "from ssa_fusion.evaluation import arms"),
    ("ssa_fusion.evaluation.x", "from ssa_fusion.sim import sky"),
    ("ssa_fusion.studies.x", "from ssa_fusion.apps import live"),
    ("ssa_fusion.studies.x", "from ssa_fusion import graphs"),
    ("ssa_fusion.ros.x", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.ros.x", "from ..apps import cli"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.graphs import node_parameters"),
    ("ssa_fusion.nodes.common", "import importlib\nimportlib.import_module('ssa_fusion.studies')"),
    ("ssa_fusion.graphs", "from ssa_fusion.apps import live"),
    ("ssa_fusion.nodes.entry", "import importlib\n"
                               "importlib.import_module(f'ssa_fusion.apps.{name}')"),
    ("ssa_fusion.nodes.sensor_sim", "from ssa_fusion.apps import live"),
    ("ssa_fusion", "from ssa_fusion.core import types"),
]
GOOD = [
    ("ssa_fusion.core.x", "from .frames import COLUMBUS\nimport numpy"),
    ("ssa_fusion.sim.x", "from ssa_fusion.core import dynamics"),
    ("ssa_fusion.evaluation.x", "from ssa_fusion.core import metrics"),
    ("ssa_fusion.studies.x", "from ssa_fusion.sim import sky\nfrom ssa_fusion.ros import bagio"),
    ("ssa_fusion.ros.x", "import rclpy\nfrom ssa_fusion.core import types"),
    ("ssa_fusion.nodes.sensor_sim", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.ros import messages\nimport rclpy"),
    ("ssa_fusion.graphs", "from ssa_fusion.sim import sky\nfrom ssa_fusion.nodes import settings"),
    ("ssa_fusion.apps.x", "from ssa_fusion.studies import reproduce\nfrom ssa_fusion import nodes"),
]


@pytest.mark.parametrize(("module", "source"), BAD)
def test_checker_finds_an_import_against_the_floors(module, source):
    assert violations(module, imports_of(source, module))


@pytest.mark.parametrize(("module", "source"), GOOD)
def test_checker_lets_allowed_imports_pass(module, source):
    assert not violations(module, imports_of(source, module))
