"""`ssa-fusion` command line: the offline and orchestration jobs around the node graph."""

from __future__ import annotations

import argparse
import importlib
import sys

from ssa_fusion import limit_blas_threads

# subcommand -> module providing add_arguments(parser) and run(args) -> int
_COMMANDS = {
    "live": ("ssa_fusion.apps.live", "run the node graph on a scenario, record a bag, evaluate it"),
    "reproduce": ("ssa_fusion.paper.reproduce", "reproduce the paper's experiments (three arms)"),
    "replay": ("ssa_fusion.apps.replay", "replay a recorded bag through surrogate + filter"),
    "report": ("ssa_fusion.apps.report", "metrics table and plots from a recorded bag"),
}


def _available() -> dict[str, tuple[object, str]]:
    found = {}
    for name, (module, help_text) in _COMMANDS.items():
        try:
            found[name] = (importlib.import_module(module), help_text)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
    return found


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ssa-fusion", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (module, help_text) in _available().items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    limit_blas_threads()  # before build_parser imports the commands, and with them numpy
    args = build_parser().parse_args(argv)
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
