"""The parameters need no ROS: reading a params file as ``replay``/``report --params-file``
do (`params_file.load_params_file`, the nodes' tables' checks and rules included), every
table, the settings' translation and the doc generator import no rclpy and no other ROS
package (each run in a fresh process, whose modules are then listed)."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

CONFIG = Path(__file__).resolve().parents[2] / "config" / "default.yaml"

ROS = ("rclpy", "rcl_interfaces", "rosidl_runtime_py", "builtin_interfaces", "std_msgs",
       "ssa_fusion_msgs", "launch", "launch_ros", "ament_index_python")
"""Top-level ROS packages none of this may load."""


def _modules_after(code: str) -> tuple[set[str], str]:
    """Run `code` in a fresh interpreter; return the top-level modules it loaded and its
    last line of output."""
    script = code + textwrap.dedent("""
        import json, sys
        print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    return set(json.loads(lines[-1])), "\n".join(lines[:-1])


def test_loading_a_params_file_imports_no_ros(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surrogate:\n  ros__parameters:\n    delays: 0\n")
    loaded, out = _modules_after(textwrap.dedent(f"""
        from ssa_fusion.params.params_file import load_params_file
        print(load_params_file({str(CONFIG)!r}).station)
        try:
            load_params_file({str(bad)!r})
        except ValueError as exc:
            print(exc)
    """))
    assert out.splitlines()[0] == "columbus"
    assert "parameter 'delays' = 0" in out  # refused by the surrogate table's check
    assert "ssa_fusion" in loaded and not loaded & set(ROS), loaded & set(ROS)


def test_every_table_the_settings_and_the_doc_generator_import_no_ros():
    loaded, out = _modules_after(textwrap.dedent("""
        import pkgutil, importlib
        import ssa_fusion.params
        from ssa_fusion.params.tables import NODES, table_of
        for info in pkgutil.walk_packages(ssa_fusion.params.__path__, "ssa_fusion.params."):
            importlib.import_module(info.name)
        print(sum(len(table_of(n).params) for n in NODES))
    """))
    assert int(out) > 100  # every row of every table was built
    assert not loaded & set(ROS), loaded & set(ROS)


def test_replay_offline_and_report_with_a_params_file_load_no_ros(tmp_path):
    """The whole commands, as a user runs them on the sample bag (issue: they started ROS)."""
    bag = CONFIG.parents[1] / "bags" / "sample_iss_j2_rae"
    for argv in (["replay", str(bag), "--offline", "--out", str(tmp_path / "replayed"),
                  "--params-file", str(CONFIG)],
                 ["report", str(bag), "--out", str(tmp_path / "report"),
                  "--params-file", str(CONFIG)]):
        loaded, out = _modules_after(textwrap.dedent(f"""
            from ssa_fusion.apps import cli
            print("exit", cli.main({argv!r}))
        """))
        assert out.splitlines()[-1] == "exit 0", out[-500:]
        assert not loaded & set(ROS), (argv[0], loaded & set(ROS))
