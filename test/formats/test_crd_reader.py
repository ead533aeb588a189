"""The CRD reader (formats.ilrs.crd) and the normal points `import crd` takes from it
(formats.ilrs.crd_in): the real LAGEOS-2 file against values read off it by hand, small
v1/v2/full-rate files, and hostile input refused in one line naming file, line and field."""

from __future__ import annotations

import calendar
from collections import Counter

import numpy as np
import pytest
from crd_samples import FULL_RATE, V1, V2, bounded
from fuzz_text import error_of, mutated
from hypothesis import HealthCheck, given, settings
from realdata import CRD, lageos, needs_lageos

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.formats.ilrs.crd import CrdReader
from ssa_fusion.formats.ilrs.crd_in import read_laser_ranges
from ssa_fusion.formats.ilrs.crd_records import (
    CalibrationRecord,
    CrdSession,
    DataType,
    EpochEvent,
    MeteoRecord,
    PointingRecord,
    RangeRecord,
    RangeSupplement,
    SessionStatistics,
)
from ssa_fusion.formats.records import MAX_LINE, RecordError

DAY_2016_02_13 = calendar.timegm((2016, 2, 13, 0, 0, 0))


def items(path):
    return list(CrdReader(path))


@needs_lageos
def test_the_real_file_reads_as_checked_by_hand():
    got = items(lageos(CRD))
    kinds = Counter(type(i).__name__ for i in got)
    assert kinds == {"CrdSession": 9, "RangeRecord": 70, "MeteoRecord": 135,
                     "CalibrationRecord": 10, "SessionStatistics": 9}
    s = got[0]
    assert isinstance(s, CrdSession)
    # h2 YARL 7090 5 13 3 / h3 lageos2 9207002 5986 22195 0 1 / h4 1 2016 2 13 13 42 16 ...
    assert (s.station_name, s.pad, s.system_number, s.occupancy, s.time_scale) == (
        "YARL", 7090, 5, 13, 3)
    assert (s.target_name, s.ilrs_id, s.sic, s.norad) == ("lageos2", 9207002, 5986, 22195)
    assert s.data_type == DataType.NORMAL_POINT and s.version == 1
    assert s.start == DAY_2016_02_13 + 13 * 3600 + 42 * 60 + 16
    assert s.end == DAY_2016_02_13 + 14 * 3600 + 6 * 60 + 46
    assert s.station_delay_applied and not s.troposphere_applied and not s.com_applied
    assert s.wavelengths_nm == {"std": 532.0}  # c0 0 532.000 std ...
    first = next(i for i in got if isinstance(i, RangeRecord))
    # 11 49382.400562600000 0.039237325685 std 2 120.0 94 57.0 ... 15.67 0
    assert first.t == DAY_2016_02_13 + 49382.4005626
    assert first.time_of_flight_s == 0.039237325685
    assert first.epoch_event == EpochEvent.GROUND_TRANSMIT and first.config_id == "std"
    assert (first.window_s, first.raw_ranges, first.bin_rms_ps, first.return_rate_pct) == (
        120.0, 94, 57.0, 15.67)
    met = next(i for i in got if isinstance(i, MeteoRecord))  # 20 49382.401 983.70 301.40 24. 0
    assert (met.pressure_hpa, met.temperature_k, met.humidity_pct) == (983.7, 301.4, 24.0)
    cal = next(i for i in got if isinstance(i, CalibrationRecord))  # 40 ... 105320.0 -17.0 27.0
    assert (cal.delay_ps, cal.rms_ps) == (105320.0, 27.0)
    stats = next(i for i in got if isinstance(i, SessionStatistics))  # 50 std 57.5 ... 0
    assert (stats.rms_ps, stats.quality) == (57.5, 0)
    stations = Counter((i.session.pad, i.session.station_name) for i in got
                       if isinstance(i, RangeRecord))
    assert stations == {(7090, "YARL"): 12, (7119, "HA4T"): 27, (7825, "STL3"): 17,
                        (7941, "MATM"): 14}


@needs_lageos
def test_the_real_normal_points_as_laser_ranges():
    r = read_laser_ranges([lageos(CRD)])
    assert len(r) == 70 and r.duplicates == 0 and r.sessions == 9 and len(r.meteo) == 135
    assert list(r.stations) == ["7090", "7119", "7825", "7941"]
    assert r.object_ids == ["22195"]  # Haleakala's sessions give no NORAD id: the others' do
    assert np.all(np.diff(r.t) >= 0)
    k = np.flatnonzero(r.t == DAY_2016_02_13 + 49382.4005626)
    assert len(k) == 1 and r.station_ids[r.station[k[0]]] == "7090"
    assert r.range_km[k[0]] == 0.5 * C_KM_S * 0.039237325685  # ~5881.5 km
    # Matera: c0 says 532 nm, its laser's fundamental 1064 (c1): the transmit one counts
    assert set(r.wavelength_nm.tolist()) == {532.0, 532.1}
    assert r.stations["7825"].wavelengths_nm == {532.1}


def test_v1_across_midnight_and_v2_with_na(tmp_path):
    p = tmp_path / "v1.npt"
    p.write_text(V1)
    got = items(p)
    ranges = [i for i in got if isinstance(i, RangeRecord)]
    day = calendar.timegm((2020, 3, 4, 0, 0, 0))
    assert [r.t for r in ranges] == [day + 85810.0, day + 86400 + 300.25]
    assert [i.t for i in got if isinstance(i, MeteoRecord)] == [day + 85800.0,
                                                               day + 86400 + 310.0]
    assert [i.azimuth_deg for i in got if isinstance(i, PointingRecord)] == [123.4]
    lr = read_laser_ranges([p])
    # event 0 (receive): transmitted one time of flight before
    np.testing.assert_array_equal(lr.t, [day + 85810.0, day + 86400 + 300.25 - 0.045])
    assert lr.object_ids == ["8820"]

    q = tmp_path / "v2.npt"
    q.write_text(V2)
    got = items(q)
    s = got[0]
    assert s.version == 2 and s.network == "ILRS" and s.end is None
    assert s.wavelengths_nm == {"c2": 1064.0}
    (r,) = [i for i in got if isinstance(i, RangeRecord)]
    assert (r.raw_ranges, r.bin_rms_ps, r.return_rate_pct) == (None, None, None)
    assert [type(i).__name__ for i in got[1:]] == [
        "MeteoRecord", "CalibrationRecord", "CalibrationRecord", "RangeRecord",
        "RangeSupplement", "PointingRecord", "SessionStatistics"]
    assert next(i for i in got if isinstance(i, RangeSupplement)).com_m is None


def test_full_rate_is_read_and_refused_by_the_importer(tmp_path):
    p = tmp_path / "fr.frd"
    p.write_text(FULL_RATE)
    ranges = [i for i in items(p) if isinstance(i, RangeRecord)]
    assert len(ranges) == 2 and not any(r.normal_point for r in ranges)
    msg = bounded(error_of(lambda q: read_laser_ranges([q]), RecordError, p, FULL_RATE), p)
    assert ":4: session 1" in msg and "full-rate" in msg and "normal points" in msg


def _refused(path, text):
    return bounded(error_of(items, RecordError, path, text), path)


def _replace(old: str, new: str, text: str = V1) -> str:
    assert old in text
    return text.replace(old, new, 1)


HOSTILE = {
    "truncated record": (_replace("  12.00 0\n", "\n"), ":12: record 11: 10 field(s), want 12"),
    "nan time of flight": (_replace("0.040000000000", "nan"),
                           ":12: record 11: time of flight: nan is not a decimal number"),
    "infinite pressure": (_replace("1001.50", "inf"), ":10: record 20: surface pressure: inf"),
    "underscored number": (_replace("1001.50", "1_001.5"), "is not a decimal number"),
    "pressure out of range": (_replace("1001.50", "5001.50"),
                              "surface pressure: 5001.50 mbar outside [300, 1100]"),
    "negative time of flight": (_replace("0.040000000000", "-0.04"),
                                "time of flight: -0.04 s outside"),
    "month 13": (_replace("h4  1 2020  3", "h4  1 2020 13"), ":5: H4: start month: 13 outside"),
    "30 February": (_replace("2020  3  4 23", "2020  2 30 23"),
                    "start: 2020-02-30 is not a date"),
    "epoch event 7": (_replace("0.040000000000 cfg 2", "0.040000000000 cfg 7"),
                      "epoch event: 7 outside [0, 6]"),
    "time scale not UTC": (_replace("12 34  4", "12 34  1"),
                           ":3: H2: station epoch time scale 1: not one of the UTC ones"),
    "data before H4": (_replace("h4  1", "20 85800.000  1001.50 290.10  55. 0\nh4  1"),
                       ":5: record 20: in the headers (H1 .. H4): it belongs inside a session"),
    "H3 before H2": (_replace("h2 TEST       7001 12 34  4\n", "", V1).replace(
        "h3 lageos1", "h3 lageos1", 1), "H3: without the H2 before it"),
    "normal point in full rate": (_replace("h4  1 2020", "h4  0 2020"),
                                  "a normal point in a session of full rate data"),
    "H5 in v1": (_replace("c0 0", "h5 1 20 030423 HTS 1\nc0 0"), "H5 is a CRD v2 record"),
    "no H8": (_replace("h8\nh9\n", ""),
              "the file ends inside session 1 (its H4 at line 5) without its H8: truncated?"),
    "no H9": (_replace("h9\n", ""), "the file ends without H9 (the end-of-file record)"),
    "after H9": (V1 + "11 1.0 0.04 cfg 2 120.0 1 1.0 1 1 1 1 0\n", "after H9"),
    "not a CRD file": ("CCSDS_TDM_VERS = 2.0\n", ":1: CCSDS_TDM...: not a CRD file"),
    "another format": (_replace("h1 CRD", "h1 CPF"), "format CPF: not a CRD file"),
    "unknown record": (_replace("60  cfg", "77  cfg"), ":9: record 77: not a CRD record"),
    "no C0": (_replace("c0 0  532.000 cfg las det tim\n", ""), None),
    "empty": ("", ":1: empty: not a CRD file"),
    "a 100 kB line": (_replace("00 a made-up", "00 " + "x" * 100_000),
                      f":1: line longer than {MAX_LINE} bytes"),
    "binary garbage": (bytes(range(128, 256)) * 4, ":1: not text"),
    "a NUL byte": (_replace("h2 TEST", "h2 TE\x00ST"), ":3: a NUL byte at column 6"),
    "a terminal escape": (_replace("h2 TEST", "h2 \x1b[2J\x1b[31mTEST"),
                          ":3: control character '\\x1b' at column 4"),
    "a carriage return inside": (_replace("h2 TEST", "h2 TE\rST"),
                                 "control character '\\r'"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_crd_is_refused_in_one_line(tmp_path, case):
    text, expected = HOSTILE[case]
    path = tmp_path / "hostile.npt"
    if expected is None:  # the reader takes it; the importer refuses it
        msg = bounded(error_of(lambda q: read_laser_ranges([q]), RecordError, path, text), path)
        assert "system configuration 'cfg' has no C0 record" in msg
        return
    msg = _refused(path, text)
    assert expected in msg, msg
    assert "\x1b" not in msg and "\x00" not in msg


def test_importer_refusals(tmp_path):
    path = tmp_path / "x.npt"
    for old, new, expected in (
            ("0 0 0 0 1 0 2 0", "0 1 0 0 1 0 2 0", "the troposphere correction is applied"),
            ("0 0 0 0 1 0 2 0", "0 0 1 0 1 0 2 0", "the centre-of-mass correction is applied"),
            ("0 0 0 0 1 0 2 0", "0 0 0 0 0 0 2 0", "the station's system delay is not applied"),
            ("0 0 0 0 1 0 2 0", "0 0 0 0 1 0 1 0", "range type 1 (one_way): not two-way"),
            ("0.040000000000 cfg 2", "0.040000000000 cfg 3", "epoch event 3")):
        msg = bounded(error_of(lambda q: read_laser_ranges([q]), RecordError, path,
                               _replace(old, new)), path)
        assert expected in msg, msg


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(text=mutated(V1, ["h1", "H4", "11", "20", "na", "nan", "\x00", "\x1b", "-1", "99999",
                         "\n", " ", "h8", "h9", "c0", "1e400"]))
def test_mutated_crd_reads_or_is_refused_in_one_line(tmp_path, text):
    path = tmp_path / "fuzz.npt"
    path.write_text(text)
    try:
        read_laser_ranges([path])
    except RecordError as exc:
        bounded(str(exc), path)
