"""Catalog survey: what a radar network measures of a whole catalog, against
per-object SGP4 (the `sgp4` package's Satrec, one object and one epoch at a time)."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from sgp4.api import jday
from sgp4.exporter import export_tle

from ssa_fusion.core.earth.frames import razel_gcrs, teme_to_gcrs
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
BASE = catalog.read_catalog(SAMPLE)[0]  # CBERS 2, LEO
RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]


def _exact(sensor):
    return dataclasses.replace(sensor, sigma=(0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def cat():
    return survey.synthetic_catalog(BASE, 12, seed=3)


def test_noise_free_measurements_are_sgp4_seen_from_the_station(cat):
    """Each measurement equals range/az/el of `sgp4`'s own per-object state at its epoch
    (TEME, turned to the GCRF), and it lies above the sensor's mask."""
    sensors = [_exact(s) for s in RADARS]
    t0 = BASE.epoch_unix
    obs = survey.observe_catalog(cat, sensors, t0, 6 * 3600.0, seed=0, chunk_states=5000)
    assert len(obs) > 100 and (np.diff(obs.t) >= 0).all()
    for i in np.linspace(0, len(obs) - 1, 25).astype(int):
        sat = cat[obs.obj[i]].satrec
        sec = obs.t[i]
        jd, fr = jday(1970, 1, 1, 0, 0, 0.0)
        e, r, v = sat.sgp4(jd, fr + sec / 86400.0)
        assert e == 0
        s = sensors[obs.sensor[i]]
        want = razel_gcrs(teme_to_gcrs(np.array([*r, *v]), sec), sec, s.station)
        assert obs.z[i] == pytest.approx(want, rel=1e-9, abs=1e-9)
        assert obs.z[i, 2] >= s.min_elevation(np.array(obs.z[i, 1]))


def test_every_epoch_above_the_mask_is_measured(cat):
    """Completeness: for one object and one radar, the measured epochs are exactly the
    cadence epochs where the object is above the mask (one at a time, no vectorisation)."""
    sensor = _exact(RADARS[0])
    t0 = BASE.epoch_unix
    obs = survey.observe_catalog(cat[:1], [sensor], t0, 12 * 3600.0)
    t = t0 + sensor.cadence_s * np.arange(int(12 * 3600 // sensor.cadence_s) + 1)
    jd, fr = jday(1970, 1, 1, 0, 0, 0.0)
    up = []
    for tk in t:
        _, r, _ = cat[0].satrec.sgp4(jd, fr + tk / 86400.0)
        az_el = razel_gcrs(teme_to_gcrs(np.array(r), tk), tk, sensor.station)
        up.append(az_el[2] >= math.radians(sensor.min_elevation_deg))
    assert np.array_equal(obs.t, t[np.array(up)])
    assert len(obs) > 0


def test_noise_has_the_sensors_sigma_and_chunking_changes_nothing(cat):
    t0 = BASE.epoch_unix
    a = survey.observe_catalog(cat, RADARS, t0, 6 * 3600.0, seed=7)
    b = survey.observe_catalog(cat, RADARS, t0, 6 * 3600.0, seed=7, chunk_states=777)
    assert np.array_equal(a.z, b.z) and np.array_equal(a.t, b.t)
    exact = survey.observe_catalog(cat, [_exact(s) for s in RADARS], t0, 6 * 3600.0)
    d = a.z - exact.z
    d[:, 1] = (d[:, 1] + math.pi) % (2 * math.pi) - math.pi
    sigma = np.asarray(RADARS[0].sigma)
    assert d.std(0) == pytest.approx(sigma, rel=0.1)
    assert a.per_object().sum() == len(a)


def test_synthetic_catalog_keeps_the_regime_and_survives_a_tle_round_trip(cat):
    """Same mean motion, eccentricity and inclination as the base; node and anomaly spread;
    written as TLEs (sgp4's exporter) and read back, the same positions."""
    for e in cat:
        assert e.satrec.no_kozai == BASE.satrec.no_kozai
        assert e.satrec.inclo == BASE.satrec.inclo
    raan = np.array([e.satrec.nodeo for e in cat])
    assert raan.std() > 1.0  # spread over the circle
    text = "\n".join(f"{e.name}\n" + "\n".join(export_tle(e.satrec)) for e in cat)
    back = catalog.parse_tle(text)
    t = BASE.epoch_unix + np.array([0.0, 3600.0])
    x0 = catalog_states(cat, t).x
    x1 = catalog_states(back, t).x
    assert [e.object_id for e in back] == [e.object_id for e in cat]
    assert np.abs(x1 - x0)[..., :3].max() < 0.05  # km: TLE columns round the elements


def test_optical_sensors_are_refused():
    with pytest.raises(ValueError, match="radars only"):
        survey.observe_catalog([BASE], [SENSORS["socorro"]], BASE.epoch_unix, 60.0)
