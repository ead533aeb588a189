"""Where the real laser-ranging data are: ``../shared/realdata/lageos2-2016`` beside the
repository (the files stay there, never in the repository; tests that read them are skipped
without them). A git worktree one directory deeper finds them one level further up."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _find() -> Path | None:
    for base in (ROOT.parent, ROOT.parent.parent):
        d = base / "shared" / "realdata" / "lageos2-2016"
        if d.is_dir():
            return d
    return None


LAGEOS = _find()
"""The directory of the LAGEOS-2 February 2016 data (its SOURCE.md says what they are), or
None."""
needs_lageos = pytest.mark.skipif(LAGEOS is None,
                                  reason="no ../shared/realdata/lageos2-2016 beside the "
                                         "repository")


def lageos(name: str) -> Path:
    """Return the path of one of the LAGEOS-2 files (only under `needs_lageos`)."""
    assert LAGEOS is not None
    return LAGEOS / name


CRD = "lageos2_20160211-13.npt"
CPF = "lageos2_cpf_160213_5441.sgf"
STATIONS = "SLRF2014_POS+VEL_2030.0_200428.snx"
ECCENTRICITIES = "ecc_une.snx"


def lageos_inputs(sigma_km: float = 5e-6):
    """Return (measurements, network, meteo, reference) of the LAGEOS-2 files, as
    `import crd` makes them (stations and eccentricities at each station's first point,
    the objects' centre-of-mass offset, range-bias priors of 1 m, noise `sigma_km`)."""
    import numpy as np

    from ssa_fusion.core.base.types import Kind, Measurement, Source
    from ssa_fusion.core.measure.laser_model import LaserNetwork
    from ssa_fusion.core.measure.laser_range import COM_OFFSETS_KM
    from ssa_fusion.core.measure.laser_station import LaserStation, velocity_per_year
    from ssa_fusion.formats import sinex
    from ssa_fusion.formats.ilrs.crd_in import read_laser_ranges
    from ssa_fusion.formats.reference_orbit import read_reference

    ranges = read_laser_ranges([lageos(CRD)])
    sol = sinex.read_solutions(lageos(STATIONS))
    ecc = sinex.read_eccentricities(lageos(ECCENTRICITIES))
    stations = {}
    for sid, st in ranges.stations.items():
        s, e = sinex.solution_at(sol, sid, st.first), sinex.eccentricity_at(ecc, sid, st.first)
        stations[sid] = LaserStation(sid, s.position_m / 1e3, velocity_per_year(s.velocity_m_yr),
                                     s.t_ref, e.une_m / 1e3, min(st.wavelengths_nm) / 1e3)
    target = next(iter(ranges.targets.values()))
    network = LaserNetwork(stations, COM_OFFSETS_KM[target.ilrs_id],
                           bias_sigma_km={sid: 1e-3 for sid in stations})
    ids, oids = ranges.station_ids, ranges.object_ids
    ms = [Measurement(t=float(t), z=np.array([r]), R=np.array([[sigma_km**2]]),
                      kind=Kind.LASER_RANGE, source=Source.SENSOR,
                      object_id=oids[ranges.target[i]], frame_id=ids[ranges.station[i]])
          for i, (t, r) in enumerate(zip(ranges.t, ranges.range_km, strict=True))]
    return ms, network, ranges.meteo, read_reference(lageos(CPF))
