# The two commands of the README. Both bring .venv/ up to date first (tools/bootstrap.sh,
# idempotent: a few seconds when nothing changed).
.PHONY: demo test bootstrap

bootstrap:
	@bash tools/bootstrap.sh

demo: bootstrap
	.venv/bin/ssa-fusion live

test: bootstrap
	.venv/bin/python -m pytest
