"""The node executables (setup.py console scripts, found by `ros2 run ssa_fusion <node>`).

Each runs `start_process()` first and only then imports its node module, which imports
rclpy and numpy: OpenBLAS reads its thread count when numpy is first imported, and a
SIGINT/SIGTERM during those imports (about a second) must already be caught. The node
module's own `main()` does the rest (and calls `start_process` again, for callers that go
to it directly, where it comes too late for numpy: see `ssa_fusion.limit_blas_threads`).

    python -m ssa_fusion.nodes.entry <node> [--ros-args ...]   # without the executables
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

from ssa_fusion.nodes import start_process
from ssa_fusion.params.tables import NODES


def run_node(name: str, args: list[str] | None = None) -> int:
    """Prepare the process, then import node module `name` and run its main()."""
    if name not in NODES:
        raise ValueError(f"unknown node {name!r}; known: {', '.join(NODES)}")
    start_process()
    return int(importlib.import_module(f"ssa_fusion.nodes.{name}").main(args) or 0)


def _executable(name: str) -> Callable[[], int]:
    """Return the console script of node `name` (setup.py): ``run_node(name)``."""
    def executable() -> int:
        return run_node(name)

    executable.__doc__ = f"Run the {name} node (its executable)."
    return executable


sensor_sim = _executable("sensor_sim")
surrogate = _executable("surrogate")
filter_node = _executable("filter")
recorder = _executable("recorder")
foxglove_bridge = _executable("foxglove_bridge")
catalog_filter = _executable("catalog_filter")
catalog_surrogate = _executable("catalog_surrogate")
conjunction = _executable("conjunction")


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in NODES:
        sys.exit(f"usage: python -m ssa_fusion.nodes.entry {{{','.join(NODES)}}} [--ros-args ...]")
    node = sys.argv.pop(1)
    sys.exit(run_node(node))
