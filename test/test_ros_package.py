"""ssa_fusion as a ROS package, without colcon: the venv is an ament prefix of it,
and package.xml declares what the code imports.

The bootstrap installs setup.py's data_files into the venv prefix as `colcon build` would
(the ament index marker, share/ssa_fusion/{package.xml,launch,config}) and the node
executables into lib/ssa_fusion/, so that `ros2 run`/`ros2 launch` find the package with the
venv on AMENT_PREFIX_PATH. test_colcon_build.py builds both packages with colcon itself.
"""

from __future__ import annotations

import ast
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from unittest import mock

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PREFIX = Path(sys.prefix)
"""The venv the tests run in: the prefix a ROS user puts on AMENT_PREFIX_PATH."""
NODES = ("sensor_sim", "surrogate", "filter", "recorder")


def data_files() -> list[tuple[str, list[str]]]:
    """setup.py's data_files: (destination under the prefix, files relative to ROOT)."""
    here = os.getcwd()
    os.chdir(ROOT)  # setup.py globs relative paths
    try:
        with mock.patch("setuptools.setup") as setup:
            exec(compile((ROOT / "setup.py").read_text(), "setup.py", "exec"), {})
    finally:
        os.chdir(here)
    return setup.call_args.kwargs["data_files"]


def test_setup_installs_the_index_marker_package_xml_launch_and_config():
    dests = {dest: files for dest, files in data_files()}
    assert dests["share/ament_index/resource_index/packages"] == ["resource/ssa_fusion"]
    assert dests["share/ssa_fusion"] == ["package.xml"]
    assert sorted(dests["share/ssa_fusion/launch"]) == ["launch_scripts/catalog.launch.py",
                                                       "launch_scripts/ssa_fusion.launch.py"]
    assert "config/default.yaml" in dests["share/ssa_fusion/config"]
    assert "config/catalogs/sample.tle" in dests["share/ssa_fusion/config/catalogs"]


@pytest.mark.parametrize(("dest", "file"), [(d, f) for d, fs in data_files() for f in fs])
def test_the_venv_prefix_holds_each_data_file_as_in_the_repository(dest, file):
    installed = PREFIX / dest / Path(file).name
    assert installed.is_file(), f"{installed} missing: run tools/bootstrap.sh"
    assert installed.read_bytes() == (ROOT / file).read_bytes(), (
        f"{installed} differs from {file}: run tools/bootstrap.sh")


def test_the_venv_share_directory_holds_nothing_else():
    """No stale launch or config file (one removed from the repository) stays installed."""
    want = {PREFIX / dest / Path(f).name for dest, fs in data_files() for f in fs}
    share = PREFIX / "share" / "ssa_fusion"
    assert {p for p in share.rglob("*") if p.is_file()} == {p for p in want
                                                           if share in p.parents}


def test_ament_index_finds_the_package_and_its_executables_in_the_venv(monkeypatch):
    """What `ros2 run ssa_fusion <node>` and `ros2 launch ssa_fusion ...` look up."""
    from ament_index_python.packages import (
        get_package_prefix,
        get_package_share_directory,
        get_packages_with_prefixes,
    )

    monkeypatch.setenv("AMENT_PREFIX_PATH", str(PREFIX))
    assert Path(get_package_prefix("ssa_fusion")) == PREFIX
    share = Path(get_package_share_directory("ssa_fusion"))
    assert (share / "launch" / "ssa_fusion.launch.py").is_file()
    assert (share / "config" / "default.yaml").is_file()
    assert get_packages_with_prefixes()["ssa_fusion_msgs"] == str(PREFIX)
    for node in NODES:  # ros2 run: an executable file in <prefix>/lib/<package>/
        exe = PREFIX / "lib" / "ssa_fusion" / node
        assert exe.is_file() and os.access(exe, os.X_OK), exe


# package.xml declares every runtime dependency -------------------------------------------
IMPORT_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "matplotlib": "python3-matplotlib",
    "yaml": "python3-yaml",
    "rosbags": "python3-rosbags-pip",
    "mcap": "mcap-ros2-support",  # the pip key of mcap-ros2-support, which installs mcap
    "zstandard": "mcap-ros2-support",  # mcap's own dependencies: its chunks' compressions
    "lz4": "mcap-ros2-support",  # (ros/mcap_salvage.py decompresses chunks itself)
    "sgp4": "python3-sgp4-pip",
    "plotly": "python3-plotly-pip",  # report.html (apps/report_html.py)
    "foxglove": "python3-foxglove-sdk-pip",  # foxglove-sdk: the foxglove_bridge node
    "ccsds_ndm": "python3-ccsds-ndm-pip",  # CCSDS OEM/TDM (apps/ccsds*.py)
    "lxml": "python3-lxml",  # a TDM read as a stream (formats/ccsds/tdm_reader.py)
    "numba": "python3-numba-pip",  # the batched EKF's compiled kernels (core/catalog/batch_ekf.py)
    "erfa": "python3-pyerfa-pip",  # frames and time scales (core/earth/frames.py, timescales.py)
    "astropy_iers_data": "python3-astropy-iers-data-pip",  # IERS EOP and leap seconds
    "jplephem": "python3-jplephem-pip",  # the Sun and the Moon (core/earth/ephemeris.py)
    "de421": "python3-de421-pip",  # JPL DE421, the ephemeris jplephem reads
    "pymsis": "python3-pymsis-pip",  # NRLMSISE-00, the simulated air (sim/atmosphere.py)
    "threadpoolctl": None,  # optional: used when installed (ssa_fusion.limit_blas_threads)
    "pydmd": None,  # optional: the BOP-DMD variant of the gap study (studies.bopdmd)
}
"""Third-party modules the code imports -> their rosdep key (None: optional, undeclared)."""
ROSDISTRO_KEYS = {"python3-numpy", "python3-scipy", "python3-matplotlib", "python3-yaml",
                  "python3-lxml", "python3-rosbags-pip", "mcap-ros2-support", "python3-pytest",
                  "python3-hypothesis"}
"""Non-ROS keys of package.xml that ros/rosdistro's rosdep/python.yaml defines (checked by
hand against rosdistro of 2026-08-22; python3-lxml on 2026-11-25); the others must be in
tools/rosdep.yaml."""
ROS_PACKAGES = {"rclpy", "rcl_interfaces", "builtin_interfaces", "std_msgs", "rosgraph_msgs",
                "diagnostic_msgs", "ament_index_python", "launch", "launch_ros",
                "ssa_fusion_msgs", "geometry_msgs", "sensor_msgs", "visualization_msgs"}
"""ROS packages the code imports; their rosdep key is the package name."""


def imported_modules() -> set[str]:
    """Top-level names of every module imported by ssa_fusion/ and the launch file,
    stdlib and ssa_fusion itself left out."""
    names: set[str] = set()
    files = [*(ROOT / "ssa_fusion").rglob("*.py"), *(ROOT / "launch_scripts").glob("*.py")]
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names - set(sys.stdlib_module_names) - {"ssa_fusion"}


def declared(*tags: str) -> set[str]:
    root = ET.parse(ROOT / "package.xml").getroot()
    return {e.text.strip() for tag in tags for e in root.iter(tag) if e.text}


def test_every_imported_package_is_declared_in_package_xml():
    runtime = declared("exec_depend", "depend")
    for module in sorted(imported_modules()):
        if module in ROS_PACKAGES:
            key = module
        else:
            assert module in IMPORT_KEYS, (
                f"the code imports {module!r}: add its rosdep key to package.xml and here")
            key = IMPORT_KEYS[module]
        if key is not None:
            assert key in runtime, f"package.xml lacks <exec_depend>{key}</exec_depend>"


def test_every_key_of_package_xml_is_one_rosdep_resolves():
    custom = yaml.safe_load((ROOT / "tools" / "rosdep.yaml").read_text())
    for key in sorted(declared("exec_depend", "depend", "test_depend", "build_depend")):
        if key in ROS_PACKAGES:
            continue
        assert key in ROSDISTRO_KEYS or key in custom, (
            f"{key}: not a rosdistro key; define it in tools/rosdep.yaml")
    for key, rules in custom.items():  # pip keys, on the platforms ROS supports
        assert key.endswith("-pip"), key
        assert {"debian", "ubuntu"} <= set(rules), key
        assert all(rule["pip"]["packages"] for rule in rules.values()), key
