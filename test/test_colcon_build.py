"""`colcon build` of both packages, as a ROS user builds them.

The repository root is the ament_python package ssa_fusion and colcon does not descend into
a package, so msg_defs/ (ament_cmake ssa_fusion_msgs) is named as a second base path. The
build goes to a temporary directory with the venv (the ROS 2 wheels' ament prefix) as
underlay, never into the repository; the same command, run from the repository root:

    PATH=$PWD/.venv/bin:$PATH AMENT_PREFIX_PATH=$PWD/.venv colcon build \\
        --base-paths . msg_defs --build-base /tmp/ssa_ws/build --install-base /tmp/ssa_ws/install

(about 13 s on 2 cores: ssa_fusion_msgs 10 s, ssa_fusion 1 s). The tests check the install
tree: ament index entries for both packages, an executable per node in lib/ssa_fusion/ that
runs the installed code, and the messages importable from the install (sourcing its
setup.bash, as a user does).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ssa_fusion.ros.processes import fresh_domain_id

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
NODES = ("sensor_sim", "surrogate", "filter", "recorder")
PACKAGES = ("ssa_fusion", "ssa_fusion_msgs")


def underlay_env(ws: Path) -> dict[str, str]:
    """The environment of a ROS user with the venv as underlay (no colcon defaults of theirs)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "COLCON_PREFIX_PATH",
                        "PYTHONPATH", "ROS_DOMAIN_ID")}
    env.update(PATH=f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}",
               AMENT_PREFIX_PATH=str(VENV), COLCON_HOME=str(ws / "colcon_home"),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> dict:
    """Build both packages once; the install tree, the environment and the build time."""
    ws = tmp_path_factory.mktemp("colcon_ws")
    before = {p.name for p in ROOT.iterdir()}
    cmd = [str(VENV / "bin" / "colcon"), "--log-base", str(ws / "log"), "build",
           "--base-paths", ".", "msg_defs",
           "--build-base", str(ws / "build"), "--install-base", str(ws / "install")]
    env = underlay_env(ws)
    t0 = time.monotonic()
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    seconds = time.monotonic() - t0
    assert done.returncode == 0, f"{' '.join(cmd)}\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}"
    new = {p.name for p in ROOT.iterdir()} - before
    assert not new & {"build", "install", "log"}, f"colcon wrote {new} into the repository"
    print(f"colcon build of {', '.join(PACKAGES)}: {seconds:.1f} s")
    return {"ws": ws, "install": ws / "install", "env": env, "stdout": done.stdout,
            "seconds": seconds}


def sourced(build: dict, script: str, **env: str) -> subprocess.CompletedProcess:
    """Run bash `script` after sourcing the install's setup.bash over the venv underlay, in
    the workspace (not the repository, whose ssa_fusion/ Python would import first)."""
    return subprocess.run(["bash", "-c", f'source "{build["install"]}/setup.bash" && {script}'],
                          cwd=build["ws"], env={**build["env"], **env}, capture_output=True,
                          text=True, timeout=120)


def test_colcon_builds_both_packages(build):
    for pkg in PACKAGES:
        assert f"Finished <<< {pkg}" in build["stdout"], build["stdout"]
    assert "Summary: 2 packages finished" in build["stdout"]


@pytest.mark.parametrize("pkg", PACKAGES)
def test_ament_index_holds_both_packages(build, pkg):
    """Isolated install (colcon's default): each package under install/<pkg>/."""
    prefix = build["install"] / pkg
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / pkg).is_file()
    assert (prefix / "share" / pkg / "package.xml").is_file()


def test_share_holds_launch_and_config(build):
    share = build["install"] / "ssa_fusion" / "share" / "ssa_fusion"
    assert (share / "launch" / "ssa_fusion.launch.py").read_bytes() == (
        ROOT / "launch_scripts" / "ssa_fusion.launch.py").read_bytes()
    assert (share / "config" / "default.yaml").read_bytes() == (
        ROOT / "config" / "default.yaml").read_bytes()


def test_the_sourced_install_resolves_both_packages_and_imports_the_messages(build):
    done = sourced(build, 'python -c "'
                   "from ament_index_python.packages import get_package_prefix as p; "
                   "from ssa_fusion_msgs.msg import Measurement, StateEstimate; "
                   "import ssa_fusion, ssa_fusion_msgs; "
                   "print(p('ssa_fusion'), p('ssa_fusion_msgs'), ssa_fusion.__file__, "
                   'ssa_fusion_msgs.__file__, Measurement().z.shape)"')
    assert done.returncode == 0, done.stderr
    install = build["install"]
    prefix, msgs_prefix, pkg_file, msgs_file, shape = done.stdout.split()
    assert Path(prefix) == install / "ssa_fusion"
    assert Path(msgs_prefix) == install / "ssa_fusion_msgs"
    assert Path(pkg_file).is_relative_to(install / "ssa_fusion")  # not the venv's copy
    assert Path(msgs_file).is_relative_to(install / "ssa_fusion_msgs")
    assert shape == "(3,)"


@pytest.mark.parametrize("node", NODES)
def test_lib_holds_an_executable_per_node(build, node):
    exe = build["install"] / "ssa_fusion" / "lib" / "ssa_fusion" / node
    assert exe.is_file() and os.access(exe, os.X_OK), exe


# A parameter each node declares before it does any work, and a value it refuses: the node
# starts from the install and exits 2 naming it (nothing is simulated or recorded).
BAD_FIRST_PARAMETER = {"sensor_sim": "scenario:=nowhere", "surrogate": "buffer_length:=-1.0",
                       "filter": "kind:=sonar", "recorder": "flush_period:=-1.0"}


@pytest.mark.graph
def test_the_installed_executables_run_the_installed_nodes(build):
    """What `ros2 run ssa_fusion <node>` runs: each starts, reads its parameters and refuses
    an invalid one with exit 2 (loopback, a ROS domain of its own)."""
    lib = build["install"] / "ssa_fusion" / "lib" / "ssa_fusion"
    procs = {node: subprocess.Popen(
        ["bash", "-c", f'source "{build["install"]}/setup.bash" && '
                       f'exec "{lib / node}" --ros-args -p {BAD_FIRST_PARAMETER[node]}'],
        cwd=build["ws"], env={**build["env"], "ROS_DOMAIN_ID": str(fresh_domain_id())},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for node in NODES}
    for node, proc in procs.items():
        _, err = proc.communicate(timeout=120)
        name = BAD_FIRST_PARAMETER[node].split(":=")[0]
        assert proc.returncode == 2, (node, err)
        assert f"error: parameter '{name}'" in err, (node, err)
