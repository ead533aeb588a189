"""The seven rclpy nodes of ssa_fusion, one per module, each with `main()` for `ros2 run`.

sensor_sim, surrogate, filter, recorder, foxglove_bridge, catalog_filter and
catalog_surrogate are thin adapters on one base class (`kit.base.SsaNode`): messages in and
out, their parameter table (`ssa_fusion.params.tables`), timers; the maths is the core's,
the simulated world `sim`'s. `kit` holds their shared machinery, `entry` the executables.
They import `ros`, `params`, `formats` and `core` (sensor_sim also `sim`).

Importing this package (or a node module) changes nothing in the process. What a node
process needs before it starts, `start_process()` does: the node's `main()` calls it, and
the executables (`entry`) call it before they import the node module, so that it comes
before numpy is imported and before the second or so of imports a node takes.
"""

import signal
import threading

from ssa_fusion import limit_blas_threads

STOP = threading.Event()
"""Set by SIGINT/SIGTERM once `start_process` installed its handlers; `process.run` ends the
node's loop when it is set."""


def _on_signal(signum: int, frame: object) -> None:
    STOP.set()


def start_process() -> None:
    """Prepare this process to run a node (again: no effect).

    * BLAS and OpenMP get one thread (`ssa_fusion.limit_blas_threads`): the graph runs
      several single-threaded processes side by side.
    * SIGINT and SIGTERM set `STOP` instead of ending the process: an interrupt during
      start-up is remembered and the node exits 0 as soon as it can, instead of dying of
      the signal's default action. (Only from the main thread: Python allows no other.)
    """
    limit_blas_threads()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(sig) is not _on_signal:
                signal.signal(sig, _on_signal)
