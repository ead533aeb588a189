"""How orbits move: dynamics, Keplerian motion, propagation with the STM, force models.

The truth and filter models (`dynamics`: two-body, J2, drag, SGP4/SDP4), the analytic
two-body solution (`kepler`), compiled propagation with variational equations
(`propagation`), the batch fit's force model with solve-for parameters (`force_model`), the
high-fidelity force model (`force_spec`, `geopotential`, `srp`, `force_kernel`,
`high_fidelity`: geopotential, Sun, Moon, SRP, drag, with the STM and the sensitivities) and
element sets with their vectorised SGP4 states (`element_sets`). Imports `base` and `earth`.
"""
