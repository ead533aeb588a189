"""The International Laser Ranging Service's files: CRD (ranges) and CPF (predictions).

`crd` reads Consolidated laser Ranging Data (CRD v1 and v2: sessions of normal points or
full-rate ranges, meteorological, pointing, calibration and statistics records) as a
stream of items; `crd_in` makes its two-way normal points and meteorological records the
measurements `ssa-fusion import crd` writes; `cpf` reads Consolidated Prediction Format
orbits (CPF v1 and v2: ITRF positions, optional velocities). The station coordinates these
need are SINEX (`formats.sinex`). Errors are one line naming the file, the line, the
record and the field (`formats.records.RecordError`).
"""
