"""rclpy nodes of ssa_fusion, one per module, each with `main()` for `ros2 run`.

Importing this package (which happens before a node module imports rclpy) limits BLAS to
one thread and installs the SIGINT/SIGTERM handlers early, so an interrupt during start-up
(imports take about a second) is remembered and the node exits 0 as soon as it can,
instead of dying of the signal's default action.
"""

import signal
import threading

from ssa_fusion import limit_blas_threads

limit_blas_threads()

STOP = threading.Event()
"""Set by SIGINT/SIGTERM; `common.run` ends the node's loop when it is set."""


def _on_signal(signum: int, frame: object) -> None:
    STOP.set()


if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
