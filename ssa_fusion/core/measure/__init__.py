"""Measurements: models with their Jacobians, validation, initial orbits, passes.

Position, range/azimuth/elevation and right ascension/declination models (`measurement`),
the checks every input meets before it is used (`validation`), initial orbit determination
(`iod`: Gibbs, Herrick-Gibbs, Gauss) and the passes of a measurement stream
(`pass_windows`). Imports `base`, `earth` and `motion`.
"""
