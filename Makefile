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

test: bootstrap
	.venv/bin/python -m pytest
