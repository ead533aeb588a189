"""The core's ground floor: types, constants, compiled loops, rows, metrics, quoting.

What every other room uses: the `types` of measurements and estimates with their enums, the
physical `constants`, `jit` (numba with its cache), `rows` (many measurements or estimates
as columns), consistency `metrics` (NEES, NIS, chi-square bounds) and `quoting` (bounded
values in error messages). Imports nothing of the package.
"""
