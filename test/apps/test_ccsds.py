"""CCSDS in and out (apps.ccsds): OEM and TDM round-trip through the ccsds-ndm library, and a
TDM of a recorded run, imported and replayed, gives that run's estimates."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from ccsds_ndm.mapping import NDMFileFormats
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_common_4_0 as common
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_master_4_0 as master
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_tdm_2_0 as tdm
from ccsds_ndm.ndm_io import NdmIo

from ssa_fusion.apps import ccsds, cli, evaluate
from ssa_fusion.core import types
from ssa_fusion.core.stations import SENSORS
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_ESTIMATE

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
T0 = 1735689600.0  # 2025-01-01T00:00:00 UTC


def estimates_bag(path: Path) -> list[types.StateEstimate]:
    """A small bag of estimates of two objects; the first epoch of "a" is published twice
    (a prediction, then its update): the OEM keeps the last."""
    rng = np.random.default_rng(7)
    out = []
    for oid in ("a", "b"):
        for k in range(4):
            A = rng.normal(size=(6, 6))
            x = rng.normal(size=6) * np.array([7000.0, 7000, 7000, 7, 7, 7])
            out.append(types.StateEstimate(T0 + 10.0 * k + 0.25, x, A @ A.T + np.eye(6),
                                           oid, types.UpdateSource.SENSOR, 1.5))
    first = out[0]
    out.insert(0, types.StateEstimate(first.t, first.x + 1.0, np.eye(6), "a"))
    classes = bagio.rosbags_classes()
    writer = bagio.BagWriter(path)
    writer.add_topic(TOPIC_ESTIMATE, f"{bagio.MSG_PACKAGE}/msg/StateEstimate")
    for i, e in enumerate(out):
        writer.write_msg(TOPIC_ESTIMATE, int(T0 * 1e9) + i, messages.estimate_to_msg(e, classes))
    writer.close()
    return out[1:]


@pytest.mark.parametrize("fmt", ["kvn", "xml"])
def test_oem_round_trips_through_ccsds_ndm(tmp_path, capsys, fmt):
    bag = tmp_path / "run"
    written = [messages.estimate_from_msg(messages.estimate_to_msg(e, bagio.rosbags_classes()))
               for e in estimates_bag(bag)]  # what the bag holds (m -> km, as every reader)
    out = tmp_path / f"run.{fmt}"
    assert cli.main(["export", "oem", str(bag), "--out", str(out), "--format", fmt]) == 0
    assert "8 states with covariance of 2 object(s) (a, b)" in capsys.readouterr().out
    doc = NdmIo().from_path(out)  # parsed back by the library itself
    assert type(doc).__name__ == "Oem" and len(doc.body.segment) == 2
    seg = doc.body.segment[0]
    assert (seg.metadata.object_id, seg.metadata.ref_frame, seg.metadata.time_system) == (
        "a", "TEME", "UTC")
    assert seg.metadata.start_time.startswith("2025-01-01T00:00:00.2499")  # the bag's stamp
    assert ccsds.parse_epoch(seg.metadata.stop_time) == written[3].t
    back = ccsds.oem_states(doc)
    for e, b in zip(written, [*back["a"], *back["b"]], strict=True):
        assert (b.object_id, b.t) == (e.object_id, e.t)
        np.testing.assert_array_equal(b.x, e.x)  # km, km/s, every digit
        np.testing.assert_array_equal(b.P, e.P)  # km^2, km^2/s, km^2/s^2


def test_oem_of_one_object_and_clear_errors(tmp_path, capsys):
    bag = tmp_path / "run"
    estimates_bag(bag)
    assert cli.main(["export", "oem", str(bag), "--object", "b"]) == 0
    doc = NdmIo().from_path(tmp_path / "run.oem")  # default: next to the bag
    assert [s.metadata.object_id for s in doc.body.segment] == ["b"]
    capsys.readouterr()
    for argv, says in [
        (["export", "oem", str(bag), "--object", "zz", "--out", str(tmp_path / "zz.oem")],
         "no estimates of object 'zz' (objects: a, b)"),
        (["export", "oem", str(bag)], "run.oem exists already"),
        (["export", "oem", str(tmp_path / "none")], "no such bag"),
        (["export", "tdm", str(bag), "--out", str(tmp_path / "x.tdm")],
         "no real range/azimuth/elevation measurements"),
    ]:
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and says in err and err.count("\n") == 1, err


def library_tdm(path: Path, comment: list[str]) -> list[tuple[float, float, float, float]]:
    """A TDM built and written by ccsds-ndm (XML, day-of-year epochs, MILLSTONE in capitals):
    (t, range km, az deg, el deg) of the epochs with all three; one more epoch has only a
    range."""
    rows = [(T0 + 60.0 * k + 0.5, 1200.0 + 3.25 * k, 350.0 + 4.5 * k - 360.0 * (k > 2),
             20.0 + k) for k in range(5)]
    obs = []
    for t, r, az, el in rows:
        epoch = ccsds.format_epoch(t).replace("2025-01-01", "2025-001")
        obs += [tdm.TrackingDataObservationType(epoch=epoch, range=r),
                tdm.TrackingDataObservationType(epoch=epoch, angle_1=common.AngleType(
                    value=az, units=common.AngleUnits.DEG)),
                tdm.TrackingDataObservationType(epoch=epoch, angle_2=common.AngleType(
                    value=el, units=common.AngleUnits.DEG))]
    obs.append(tdm.TrackingDataObservationType(epoch="2025-001T01:00:00", range=999.0))
    meta = tdm.TdmMetadata(comment=comment, time_system="UTC", participant_1="MILLSTONE",
                           participant_2="2025-001A", path="1,2,1",
                           angle_type=tdm.AngleTypeType.AZEL, range_units=tdm.RangeUnitsType.KM)
    doc = master.Tdm(header=tdm.TdmHeader(creation_date="2025-01-02T00:00:00", originator="t"),
                     body=tdm.TdmBody(segment=[tdm.TdmSegment(
                         metadata=meta, data=tdm.TdmData(observation=obs))]))
    NdmIo().to_file(doc, NDMFileFormats.XML, path)
    return rows


@pytest.mark.parametrize("how", ["preset", "comment", "option"])
def test_a_library_written_tdm_imports_as_its_measurements(tmp_path, capsys, how):
    comment = ["ssa_fusion sigma: 0.5 0.1 0.2"] if how == "comment" else []
    rows = library_tdm(tmp_path / "in.xml", comment)
    option = ["--sigma", "0.03", "0.01", "0.02"] if how == "option" else []
    bag = tmp_path / "in_bag"
    assert cli.main(["import", "tdm", str(tmp_path / "in.xml"), "--bag", str(bag), *option]) == 0
    said = capsys.readouterr().out
    assert "5 measurements of 2025-001A from millstone; 1 epoch(s) without all" in said
    ms = evaluate.load(bag).measurements
    assert len(ms) == len(rows)
    sigma = {"preset": np.array(SENSORS["millstone"].sigma),
             "comment": np.array([0.5, math.radians(0.1), math.radians(0.2)]),
             "option": np.array([0.03, math.radians(0.01), math.radians(0.02)])}[how]
    for m, (t, r, az, el) in zip(ms, rows, strict=True):
        assert (m.t, m.object_id, m.frame_id, m.kind, m.source) == (
            t, "2025-001A", "millstone", types.Kind.RANGE_AZ_EL, types.Source.SENSOR)
        np.testing.assert_allclose(m.z, [r, math.radians(az % 360), math.radians(el)],
                                   rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(m.R, np.diag(sigma**2), rtol=1e-12)


def test_unsupported_tdm_is_one_line_and_exit_2(tmp_path, capsys):
    library_tdm(tmp_path / "in.xml", [])
    text = (tmp_path / "in.xml").read_text()
    for name, edited, says in [
        ("station", text.replace("MILLSTONE", "DSS-24"), "need one known station"),
        ("radec", text.replace(">AZEL<", ">RADEC<"), "ANGLE_TYPE = RADEC is not supported"),
        ("garbage", "hello\n", "not a readable CCSDS message"),
    ]:
        (tmp_path / f"{name}.xml").write_text(edited)
        argv = ["import", "tdm", str(tmp_path / f"{name}.xml"), "--bag", str(tmp_path / name)]
        assert cli.main(argv) == 2, name
        err = capsys.readouterr().err
        assert err.startswith("error: ") and says in err and err.count("\n") == 1, err


def test_tdm_of_a_recorded_run_replays_to_its_estimates(tmp_path, capsys):
    """The sample bag's real measurements -> TDM -> a new bag -> offline replay: the fused
    estimates equal those the live run recorded (as `test_replay` holds for the bag itself)."""
    out = tmp_path / "run.tdm"
    assert cli.main(["export", "tdm", str(SAMPLE), "--out", str(out)]) == 0
    assert cli.main(["import", "tdm", str(out), "--bag", str(tmp_path / "imported")]) == 0
    live, imported = evaluate.load(SAMPLE), evaluate.load(tmp_path / "imported")
    assert [m.t for m in imported.measurements] == [m.t for m in live.measurements]
    for a, b in zip(live.measurements, imported.measurements, strict=True):
        np.testing.assert_allclose(b.z, a.z, rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(b.R, a.R, rtol=1e-14)
    replayed = tmp_path / "replayed"
    assert cli.main(["replay", str(tmp_path / "imported"), "--offline", "--out",
                     str(replayed)]) == 0
    a = {e.t: e for e in live.estimates if e.update_source}
    b = {e.t: e for e in evaluate.load(replayed).estimates if e.update_source}
    assert sorted(a) == sorted(b)
    for t in a:
        assert a[t].update_source == b[t].update_source, t
        assert np.abs(a[t].x - b[t].x).max() <= 1e-9 * np.abs(a[t].x).max(), t
        np.testing.assert_allclose(a[t].P, b[t].P, rtol=1e-6, atol=1e-12)


def test_epochs_round_trip_to_the_nanosecond():
    for t in (T0, T0 + 0.123456789, 1.5e9 + 86399.999999999):
        text = ccsds.format_epoch(t)
        assert ccsds.parse_epoch(text) == messages.stamp_to_seconds(
            messages.seconds_to_stamp(t, bagio.rosbags_classes()))
    assert ccsds.parse_epoch("2025-001T00:00:01Z") == T0 + 1
    with pytest.raises(ccsds.CcsdsError, match="not a CCSDS UTC epoch"):
        ccsds.parse_epoch("yesterday")
