"""`ssa-fusion` command line: the offline and orchestration jobs around the node graph."""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
from types import ModuleType

from ssa_fusion import limit_blas_threads

# subcommand -> module providing add_arguments(parser) and run(args) -> int
_COMMANDS = {
    "live": ("ssa_fusion.apps.live", "run the node graph on a scenario, record a bag, evaluate it"),
    "reproduce": ("ssa_fusion.studies.reproduce", "reproduce the paper's experiments (three arms)"),
    "replay": ("ssa_fusion.apps.replay", "replay a recorded bag through surrogate + filter"),
    "report": ("ssa_fusion.apps.report", "metrics table and plots from a recorded bag"),
    "bag": ("ssa_fusion.apps.bag", "bag tools: `bag repair` makes a killed recorder's bag "
                                   "readable by any reader"),
    "export": ("ssa_fusion.apps.ccsds", "CCSDS out of a bag: `export oem` (estimates with "
                                        "covariance, GCRF), `export tdm` (range/az/el, "
                                        "ra/dec)"),
    "import": ("ssa_fusion.apps.ccsds", "measurements into a bag: `import tdm FILE --bag "
                                        "OUT` (CCSDS range/az/el and ra/dec that `replay` "
                                        "runs), `import crd FILE... --stations SINEX --bag "
                                        "OUT` (ILRS laser ranging)"),
    "pc": ("ssa_fusion.apps.pc", "collision probability of CCSDS CDMs, beside the message's "
                                 "own"),
}


def _module(name: str) -> ModuleType | None:
    """Return the module of command `name`, or None when it cannot be imported here."""
    module = _COMMANDS[name][0]
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name != module:
            raise
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Return the `ssa-fusion` parser, one subcommand per command whose module imports.

    `only`: the command about to run; only its module is imported (each command imports
    what it needs: an offline command never loads ROS because `live` does).
    """
    parser = argparse.ArgumentParser(prog="ssa-fusion", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (_, help_text) in _COMMANDS.items():
        module = _module(name) if only in (None, name) else None
        if module is None and only in (None, name):
            continue
        p = sub.add_parser(name, help=help_text, description=help_text)
        if module is not None:
            module.add_arguments(p)
            p.set_defaults(_run=module.run)
    return parser


def _command_in(argv: list[str]) -> str | None:
    """Return the subcommand `argv` starts with, else None (``--help``: every command)."""
    return argv[0] if argv and argv[0] in _COMMANDS else None


class Interrupted(BaseException):
    """SIGTERM or SIGHUP, raised in the main thread like KeyboardInterrupt for SIGINT.

    So a command's cleanup (`finally`: stop every node it started, close the bag) runs.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


_RECEIVED: list[int] = []
"""The stop signal received, if any (`_interrupt`)."""


def _interrupt(signum: int, _frame: object) -> None:
    for sig in _STOP_SIGNALS:  # a second signal must not cut the cleanup short
        signal.signal(sig, signal.SIG_IGN)
    _RECEIVED.append(signum)
    raise Interrupted(signum)


def _stopped(command: str, signum: int) -> int:
    """Say that `command` was stopped by signal `signum`; return its exit code, 128 + it."""
    print(f"{command}: stopped by {signal.Signals(signum).name}; every process it started "
          "was stopped", file=sys.stderr)
    return 128 + signum


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; return its exit code.

    SIGINT, SIGTERM and SIGHUP stop it cleanly: the command's cleanup runs (a live run stops
    every node it started and closes the bag), a line says so, and the exit code is 128 +
    the signal's number (130, 143, 129), as a shell reports it.
    """
    limit_blas_threads()  # before build_parser imports the commands, and with them numpy
    # from the first moment: a signal during the imports (a second or two) ends the same way
    _RECEIVED.clear()
    previous = {sig: signal.signal(sig, _interrupt) for sig in _STOP_SIGNALS}
    command = "ssa-fusion"
    try:
        words = sys.argv[1:] if argv is None else argv
        args = build_parser(_command_in(words)).parse_args(words)
        command = f"ssa-fusion {args.command}"
        if _RECEIVED:  # its Interrupted raised where Python ignores errors (an import's
            raise Interrupted(_RECEIVED[0])  # module-lock callback) and lost: stop before running
        return int(args._run(args) or 0)
    except Interrupted as exc:
        return _stopped(command, exc.signum)
    except Exception:
        # raised inside a C extension's call back into Python (rclpy taking a message),
        # Interrupted comes out as that extension's error (pybind11: "Unable to convert
        # call argument"): the signal still stopped the command, its cleanup has run
        if not _RECEIVED:
            raise
        return _stopped(command, _RECEIVED[0])
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())
