"""Imports point down the floors (DESIGN.md and docs/LAYOUT.md), and down the core's rooms:

    apps -> graphs -> nodes -> ros, params -> formats -> core
    studies -> sim, evaluation -> formats -> core   (launch files -> graphs, ros.launch_events)
    core: conjunction -> catalog -> gaps -> od -> filter -> measure -> motion -> earth -> base

* core imports nothing of the package, and no ROS package; a room of the core imports only
  its own room and the rooms below it (`CORE_ROOMS`), and every module of the core is in one;
* formats (the field's files) import only the core; params (the nodes' parameter tables,
  without ROS) only the core and formats; neither imports a ROS package;
* sim and evaluation import only core and formats (and no ROS package);
* studies import core, formats, sim, evaluation (and ros, to read bags), never params, nodes,
  graphs or apps;
* ros imports nothing from params, nodes, graphs, apps, sim, evaluation, studies;
* nodes (the seven node modules, entry.py and nodes/kit/, their machinery) import ros,
  params, formats and core, never apps, graphs, studies or evaluation; sim only in
  nodes/sensor_sim.py (the simulator runs the simulated world: `sim.schedule`);
* graphs (what runs together) imports nodes, params, ros, sim, formats and core, never apps
  or studies;
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

FLOORS = ("core", "formats", "params", "sim", "evaluation", "studies", "ros", "nodes", "graphs",
          "apps")


def _floors(*names: str) -> tuple[str, ...]:
    return tuple(f"ssa_fusion.{n}" for n in names)


FORBIDDEN: dict[str, tuple[str, ...]] = {
    "core": (*_floors(*(f for f in FLOORS if f != "core")), *ROS),
    "formats": (*_floors(*(f for f in FLOORS if f not in ("core", "formats"))), *ROS),
    "params": (*_floors(*(f for f in FLOORS if f not in ("core", "formats", "params"))), *ROS),
    "sim": (*_floors("params", "evaluation", "studies", "ros", "nodes", "graphs", "apps"), *ROS),
    "evaluation": (*_floors("params", "sim", "studies", "ros", "nodes", "graphs", "apps"), *ROS),
    "studies": _floors("params", "nodes", "graphs", "apps"),
    "ros": _floors("params", "nodes", "graphs", "apps", "sim", "evaluation", "studies"),
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


CORE_ROOMS = ("base", "earth", "motion", "measure", "filter", "od", "gaps", "catalog",
              "conjunction")
"""The core's rooms, bottom up: a room may import its own modules and those of rooms before it."""


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


def room_of(module: str) -> str:
    """The core room of `module` ("" for the core's own package, "?" outside every room)."""
    parts = module.split(".")
    if parts[:2] != ["ssa_fusion", "core"]:
        raise ValueError(f"{module} is not in the core")
    if len(parts) == 2:
        return ""
    return parts[2] if parts[2] in CORE_ROOMS else "?"


def room_violations(module: str, imported: set[str]) -> list[str]:
    """The imports of core module `module` that reach a room above its own."""
    room = room_of(module)
    rank = CORE_ROOMS.index(room) if room in CORE_ROOMS else -1
    bad = []
    for name in imported:
        if not _under(name, "ssa_fusion.core") or name == "ssa_fusion.core":
            continue
        target = room_of(name)
        if target == "?" or CORE_ROOMS.index(target) > rank:
            bad.append(f"{module} imports {name}")
    return sorted(bad)


def test_every_core_module_is_in_a_room():
    outside = [m for m in all_modules()
               if floor_of(m) == "core" and m != "ssa_fusion.core" and room_of(m) == "?"]
    assert not outside, f"core modules outside the rooms {CORE_ROOMS}: {outside}"
    rooms = {room_of(m) for m in all_modules() if floor_of(m) == "core"} - {""}
    assert rooms == set(CORE_ROOMS)


def test_the_core_rooms_import_down():
    found = []
    for module, (source, is_package) in all_modules().items():
        if floor_of(module) == "core":
            found += room_violations(module, imports_of(source, module, is_package))
    assert not found, "imports against the core's rooms:\n" + "\n".join(found)


ASSOCIATION = "ssa_fusion.core.catalog.association"
ASSOCIATION_ORDER = ("config", "outcomes", "gating", "assignment", "registration", "tracklets",
                     "deferral", "manager")
"""The association package's modules, in the order its docstring lists them: each imports only
those before it."""


def association_violations(module: str, imported: set[str]) -> list[str]:
    """The imports of an association module that reach one after it in `ASSOCIATION_ORDER`
    (or the package's namespace, which imports them all)."""
    own = module.rpartition(".")[2]
    rank = ASSOCIATION_ORDER.index(own)
    bad = []
    for name in imported:
        if not _under(name, ASSOCIATION) or name == ASSOCIATION:
            continue
        target = name.split(".")[4]
        if target not in ASSOCIATION_ORDER or (target != own
                                               and ASSOCIATION_ORDER.index(target) >= rank):
            bad.append(f"{module} imports {name}")
    return sorted(bad)


def test_the_association_modules_import_in_their_order():
    modules = {m: src for m, (src, pkg) in all_modules().items()
               if _under(m, ASSOCIATION) and m != ASSOCIATION}
    assert {m.rpartition(".")[2] for m in modules} == set(ASSOCIATION_ORDER)
    found = [v for m, src in modules.items() for v in association_violations(m, imports_of(src, m))]
    assert not found, "\n".join(found)
    assert association_violations(f"{ASSOCIATION}.gating",
                                  {f"{ASSOCIATION}.manager", f"{ASSOCIATION}.config.X"}) == [
        f"{ASSOCIATION}.gating imports {ASSOCIATION}.manager"]
    assert association_violations(f"{ASSOCIATION}.gating", {f"{ASSOCIATION}.Associator"})


@pytest.mark.parametrize(("module", "source"), [
    ("ssa_fusion.core.base.types", "from ssa_fusion.core.earth import frames"),
    ("ssa_fusion.core.earth.frames", "from ..motion.kepler import propagate"),
    ("ssa_fusion.core.filter.ekf", "from ssa_fusion.core.gaps.residual import rtn_axes"),
    ("ssa_fusion.core.catalog.association.deferral", "import ssa_fusion.core.conjunction.pc"),
    ("ssa_fusion.core.motion.dynamics", "from ssa_fusion.core import flat_module"),
])
def test_room_checker_finds_an_import_up(module, source):
    assert room_violations(module, imports_of(source, module))


@pytest.mark.parametrize(("module", "source"), [
    ("ssa_fusion.core.catalog.association.deferral", "from ssa_fusion.core.filter import options"),
    ("ssa_fusion.core.earth.frames", "from . import eop\nfrom ..base.constants import R_EARTH"),
    ("ssa_fusion.core.base.types", "import numpy"),
])
def test_room_checker_lets_imports_down_pass(module, source):
    assert not room_violations(module, imports_of(source, module))


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
    ("ssa_fusion.formats.x", "from ssa_fusion.ros import messages"),
    ("ssa_fusion.formats.x", "import yaml\nfrom ssa_fusion.params import tables"),
    ("ssa_fusion.params.x", "import rclpy"),
    ("ssa_fusion.params.x", "from ssa_fusion.nodes import filter"),
    ("ssa_fusion.sim.x", "from ssa_fusion.params import defaults"),
    ("ssa_fusion.params.tables.sensor_sim", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.params.checks", "from ssa_fusion.ros.readiness import split_need"),
    ("ssa_fusion.params.settings", "from ..nodes.kit import base"),
    ("ssa_fusion.nodes.kit.base", "from ssa_fusion.sim.schedule import Pace"),
    ("ssa_fusion.nodes.kit.progress", "from ssa_fusion.graphs import catalog_graph"),
    ("ssa_fusion.sim.schedule", "from ssa_fusion.params.tables import sensor_sim"),
]
GOOD = [
    ("ssa_fusion.core.x", "from .frames import COLUMBUS\nimport numpy"),
    ("ssa_fusion.formats.x", "import lxml\nfrom ssa_fusion.core.earth import timescales"),
    ("ssa_fusion.params.x", "from ssa_fusion.formats import sites"),
    ("ssa_fusion.params.tables.filter", "from ..settings import FILTER_KEYS\n"
                                        "from ssa_fusion.core.gaps.publisher import GapFill"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.params.tables.filter import PARAMETERS\n"
                                "from ssa_fusion.nodes.kit.base import SsaNode"),
    ("ssa_fusion.nodes.kit.shards", "import rclpy\n"
                                    "from ssa_fusion.ros.messages import shard_range"),
    ("ssa_fusion.sim.x", "from ssa_fusion.core import dynamics"),
    ("ssa_fusion.evaluation.x", "from ssa_fusion.core import metrics"),
    ("ssa_fusion.studies.x", "from ssa_fusion.sim import sky\nfrom ssa_fusion.ros import bagio"),
    ("ssa_fusion.ros.x", "import rclpy\nfrom ssa_fusion.core import types"),
    ("ssa_fusion.nodes.sensor_sim", "from ssa_fusion.sim import scenarios"),
    ("ssa_fusion.nodes.filter", "from ssa_fusion.ros import messages\nimport rclpy"),
    ("ssa_fusion.graphs", "from ssa_fusion.sim import sky\nfrom ssa_fusion.params import settings"),
    ("ssa_fusion.apps.x", "from ssa_fusion.studies import reproduce\nfrom ssa_fusion import nodes"),
]


@pytest.mark.parametrize(("module", "source"), BAD)
def test_checker_finds_an_import_against_the_floors(module, source):
    assert violations(module, imports_of(source, module))


@pytest.mark.parametrize(("module", "source"), GOOD)
def test_checker_lets_allowed_imports_pass(module, source):
    assert not violations(module, imports_of(source, module))
