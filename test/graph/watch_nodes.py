"""Test process: print (one JSON line) the ROS node names this process discovers.

    watch_nodes.py CONTROL WINDOW_S TIMEOUT_S

Spins until node CONTROL is discovered (at most TIMEOUT_S wall s), then WINDOW_S wall s
more, so that a node announced as early as CONTROL would be seen too; prints every node name
seen and exits 0 (1 when CONTROL never came).
"""

import json
import sys
import time

import rclpy


def main() -> int:
    control, window, timeout = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    rclpy.init()
    node = rclpy.create_node("node_watcher")
    seen: set[str] = set()
    deadline, until = time.monotonic() + timeout, None
    while time.monotonic() < (until or deadline):
        rclpy.spin_once(node, timeout_sec=0.1)
        seen.update(node.get_node_names())
        if until is None and control in seen:
            until = time.monotonic() + window
    print(json.dumps(sorted(seen)), flush=True)
    return 0 if control in seen else 1


if __name__ == "__main__":
    sys.exit(main())
