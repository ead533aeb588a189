"""The ssa-fusion command: cli, args, live, replay, report, evaluate."""
