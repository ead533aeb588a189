# The two commands of the README. Both bring .venv/ up to date first (tools/bootstrap.sh,
# idempotent: a few seconds when nothing changed).
.PHONY: demo test bootstrap

# Many single-threaded processes share 2 cores: a spinning multi-threaded BLAS slows all.
export OPENBLAS_NUM_THREADS ?= 1
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST

bootstrap:
	@bash tools/bootstrap.sh

demo: bootstrap
	.venv/bin/ssa-fusion live

# Gates first: ruff on the whole tree (docstring and annotation rules on every module of
# the package, pyproject.toml) and mypy on the package; any finding fails. The tests then run
# as two groups side by side (tools/run_tests.sh: the graph tests and the rest), each in a
# network namespace of its own where the machine allows (tools/isolated.sh): no other ROS
# graph on the machine can cross-talk with the test graphs.
test: bootstrap
	.venv/bin/ruff check .
	.venv/bin/mypy
	tools/run_tests.sh
