"""CCSDS in and out (apps.ccsds and its ccsds_* modules): OEM and TDM round-trip through the
ccsds-ndm library; the OEM's GCRF, EME2000 and TEME states are where astropy puts them; TDM
angles (AZEL, RADEC in GCRF/ICRF/EME2000) and time systems (UTC, TAI, TT, GPS) are read as
written; what is not supported is refused with one line; and a TDM of a recorded run,
imported and replayed, gives that run's estimates."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from astropy import units as u
from astropy.coordinates import (
    GCRS,
    ITRS,
    TEME,
    CartesianDifferential,
    CartesianRepresentation,
    PrecessedGeocentric,
)
from astropy.time import Time
from astropy.utils import iers
from ccsds_ndm.mapping import NDMFileFormats
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_common_4_0 as common
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_master_4_0 as master
from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_tdm_2_0 as tdm
from ccsds_ndm.ndm_io import NdmIo

from ssa_fusion.apps import ccsds, cli, evaluate
from ssa_fusion.core.base import types
from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.core.earth.stations import SENSORS, STATIONS
from ssa_fusion.formats.ccsds import common as ccsds_format
from ssa_fusion.formats.ccsds import oem as ccsds_oem
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_MEASUREMENT

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
T0 = 1735689600.0  # 2025-01-01T00:00:00 UTC
MAS = ARCSEC / 1000.0


@pytest.fixture(scope="module", autouse=True)
def astropy_offline():
    """astropy with the IERS-A table of astropy-iers-data: the EOP `core.earth.eop` uses."""
    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    iers.earth_orientation_table.set(iers.IERS_A.open(iers.IERS_A_FILE))


def one_line_error(capsys, argv: list[str], says: str) -> str:
    """Run the CLI: exit 2 with one `error:` line on stderr that contains `says`."""
    assert cli.main(argv) == 2, argv
    err = capsys.readouterr().err
    assert err.startswith("error: ") and says in err and err.count("\n") == 1, err
    return err


# ------------------------------------------------------------------------------------------
# OEM
# ------------------------------------------------------------------------------------------
def write_bag(path: Path, estimates: list[types.StateEstimate],
              measurements: list[types.Measurement] = (), frame_id: str = Frame.GCRF) -> None:
    """A bag of `estimates` on /ssa/estimate, whose headers say `frame_id`, and of
    `measurements` on /ssa/measurement."""
    classes = bagio.rosbags_classes()
    writer = bagio.BagWriter(path)
    writer.add_topic(TOPIC_ESTIMATE, f"{bagio.MSG_PACKAGE}/msg/StateEstimate")
    writer.add_topic(TOPIC_MEASUREMENT, f"{bagio.MSG_PACKAGE}/msg/Measurement")
    for i, e in enumerate(estimates):
        msg = messages.estimate_to_msg(e, classes)
        msg = dataclasses.replace(msg, header=dataclasses.replace(msg.header, frame_id=frame_id))
        writer.write_msg(TOPIC_ESTIMATE, int(T0 * 1e9) + i, msg)
    for m in measurements:
        writer.write_msg(TOPIC_MEASUREMENT, round(m.t * 1e9),
                         messages.measurement_to_msg(m, classes))
    writer.close()


def estimates_bag(path: Path, frame_id: str = Frame.GCRF) -> list[types.StateEstimate]:
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
    write_bag(path, [types.StateEstimate(first.t, first.x + 1.0, np.eye(6), "a"), *out],
              frame_id=frame_id)
    return out


@pytest.mark.parametrize("fmt", ["kvn", "xml"])
def test_oem_round_trips_through_ccsds_ndm(tmp_path, capsys, fmt):
    bag = tmp_path / "run"
    written = [messages.estimate_from_msg(messages.estimate_to_msg(e, bagio.rosbags_classes()))
               for e in estimates_bag(bag)]  # what the bag holds (m -> km, as every reader)
    out = tmp_path / f"run.{fmt}"
    assert cli.main(["export", "oem", str(bag), "--out", str(out), "--format", fmt]) == 0
    assert "8 states with covariance of 2 object(s) (a, b) in GCRF" in capsys.readouterr().out
    doc = NdmIo().from_path(out)  # parsed back by the library itself
    assert type(doc).__name__ == "Oem" and len(doc.body.segment) == 2
    seg = doc.body.segment[0]
    assert (seg.metadata.object_id, seg.metadata.ref_frame, seg.metadata.time_system) == (
        "a", "GCRF", "UTC")
    assert seg.metadata.start_time.startswith("2025-01-01T00:00:00.2499")  # the bag's stamp
    assert ccsds_format.parse_epoch(seg.metadata.stop_time) == written[3].t
    back = ccsds_oem.oem_states(doc)
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
         "no real range/azimuth/elevation or right ascension/declination measurements"),
    ]:
        one_line_error(capsys, argv, says)


def test_a_bag_of_the_old_eci_frame_is_refused(tmp_path, capsys):
    """Bags recorded before the real Earth say "eci" (TEME-like axes turned by ERA only):
    never exported as GCRF, nor in a frame computed from it."""
    bag = tmp_path / "old"
    estimates_bag(bag, frame_id="eci")
    for frame in ("GCRF", "TEME"):
        err = one_line_error(capsys, ["export", "oem", str(bag), "--frame", frame,
                                      "--out", str(tmp_path / f"{frame}.oem")],
                             f"{bag}: its /ssa/estimate messages say frame 'eci', not 'gcrf'")
        assert "re-record the bag" in err
        assert not (tmp_path / f"{frame}.oem").exists()


def itrs_truth() -> tuple[np.ndarray, np.ndarray]:
    """Epochs (Unix UTC, over 41 days) and ITRF states (km, km/s) of a LEO and a GEO object:
    the truth the exported files must reproduce."""
    t = T0 + np.array([0.25, 5.3 * 3600.0, 40.7 * 86400.0])
    leo = np.concatenate([frames.site_itrs(math.radians(30.0), math.radians(-60.0), 500.0),
                          [0.5, 7.0, 1.0]])
    geo = np.array([42164.0 * math.cos(math.radians(75.0)),
                    42164.0 * math.sin(math.radians(75.0)), 0.0, 0.0, 0.0, 0.0])
    return t, np.array([leo, geo])


def exported_oem(tmp_path: Path, frame: str) -> tuple[
        np.ndarray, dict[str, np.ndarray], dict[str, list[types.StateEstimate]],
        list[types.StateEstimate]]:
    """`itrs_truth` as GCRF estimates (`frames.itrs_to_gcrs`) in a bag, exported in `frame`
    and parsed by ccsds-ndm: (epochs, GCRF states by object, the file's states by object,
    the estimates in the bag)."""
    t, truth = itrs_truth()
    rng = np.random.default_rng(3)
    gcrf, estimates = {}, []
    for oid, x_itrs in zip(("leo", "geo"), truth, strict=True):
        gcrf[oid] = frames.itrs_to_gcrs(np.broadcast_to(x_itrs, (len(t), 6)), t)
        for ti, xi in zip(t, gcrf[oid], strict=True):
            A = rng.normal(size=(6, 6)) * np.array([1.0, 1, 1, 1e-3, 1e-3, 1e-3])
            estimates.append(types.StateEstimate(float(ti), xi, A @ A.T, oid))
    write_bag(tmp_path / "bag", estimates)
    out = tmp_path / f"{frame}.oem"
    assert cli.main(["export", "oem", str(tmp_path / "bag"), "--frame", frame,
                     "--out", str(out)]) == 0
    doc = NdmIo().from_path(out)
    assert {s.metadata.ref_frame for s in doc.body.segment} == {frame}
    file_states = ccsds_oem.oem_states(doc)
    for rows in file_states.values():
        np.testing.assert_allclose([r.t for r in rows], t, rtol=0, atol=1e-6)  # bag stamps
    return np.array([r.t for r in file_states["leo"]]), gcrf, file_states, estimates


def astropy_cartesian(x: np.ndarray) -> CartesianRepresentation:
    """States (n, 6) km, km/s as an astropy representation with velocities."""
    return CartesianRepresentation(
        x[:, :3].T * u.km, differentials=CartesianDifferential(x[:, 3:].T * u.km / u.s))


def astropy_states(c) -> np.ndarray:
    """An astropy coordinate's states (n, 6), km, km/s."""
    return np.hstack([c.cartesian.xyz.to_value(u.km).T,
                      c.velocity.d_xyz.to_value(u.km / u.s).T])


def test_oem_in_gcrf_lands_on_the_itrs_truth_through_astropy(tmp_path, capsys):
    """The OEM's GCRF states, read by astropy as GCRS at their UTC epochs and turned to the
    ITRS, are the ITRF truth they were made of: position <= 1 m, velocity <= 1 mm/s."""
    _, truth = itrs_truth()
    t, _, states, _ = exported_oem(tmp_path, "GCRF")  # t: the file's epochs, as a user has
    epochs = Time(t, format="unix", scale="utc")
    for oid, x_itrs in zip(("leo", "geo"), truth, strict=True):
        x = np.array([r.x for r in states[oid]])
        itrs = GCRS(astropy_cartesian(x), obstime=epochs).transform_to(ITRS(obstime=epochs))
        got = astropy_states(itrs)
        assert np.abs(got[:, :3] - x_itrs[:3]).max() <= 1e-3, oid  # km
        assert np.abs(got[:, 3:] - x_itrs[3:]).max() <= 1e-6, oid  # km/s


@pytest.mark.parametrize("frame", ["EME2000", "TEME"])
def test_oem_in_eme2000_and_teme_are_astropys_states(tmp_path, capsys, frame):
    """EME2000 and TEME exports are the GCRF states turned by astropy into its geocentric
    J2000 mean equator and equinox (`PrecessedGeocentric(equinox=J2000)`: GCRS rotated by
    the IAU 2006 frame bias, ERFA bp06) and into its `TEME`: position <= 1 m, velocity
    <= 1 mm/s; the covariance is turned by the same rotation (<= 1e-9 relative).

    Not astropy's `FK5(equinox="J2000")`: that is the FK5 catalogue frame (ICRS -> FK5 of
    Mignard and Froeschle, ~20 mas from EME2000: 0.8 m at 7000 km, 5 m at GEO) and
    barycentric; EME2000 is the dynamical mean equator and equinox of J2000.
    """
    t, gcrf, states, inputs = exported_oem(tmp_path, frame)
    epochs = Time(t, format="unix", scale="utc")
    target = (PrecessedGeocentric(equinox=Time("J2000"), obstime=epochs) if frame == "EME2000"
              else TEME(obstime=epochs))
    # astropy's rotation GCRF -> frame at each epoch: the images of the unit vectors
    axes = np.stack([astropy_states(GCRS(astropy_cartesian(np.tile(np.r_[e, 0, 0, 0],
                                                                       (len(t), 1))),
                                         obstime=epochs).transform_to(target))[:, :3]
                     for e in np.eye(3)], -1)  # (n, 3, 3), columns the images
    b = np.zeros((len(t), 6, 6))
    b[:, :3, :3] = b[:, 3:, 3:] = axes
    for oid, x in gcrf.items():
        want = astropy_states(GCRS(astropy_cartesian(x), obstime=epochs).transform_to(target))
        got = np.array([r.x for r in states[oid]])
        assert np.abs(got[:, :3] - want[:, :3]).max() <= 1e-3, oid  # km
        assert np.abs(got[:, 3:] - want[:, 3:]).max() <= 1e-6, oid  # km/s
        assert np.abs(got[:, :3] - x[:, :3]).max() > 1e-4  # the rotation is there (> 0.1 m)
        p_in = np.array([e.P for e in inputs if e.object_id == oid])
        p_want = b @ p_in @ np.swapaxes(b, -1, -2)
        p_got = np.array([r.P for r in states[oid]])
        assert np.abs(p_got - p_want).max() <= 1e-9 * np.abs(p_in).max(), oid


# ------------------------------------------------------------------------------------------
# TDM out and in
# ------------------------------------------------------------------------------------------
def library_tdm(path: Path, comment: list[str]) -> list[tuple[float, float, float, float]]:
    """A TDM built and written by ccsds-ndm (XML, day-of-year epochs, MILLSTONE in capitals):
    (t, range km, az deg, el deg) of the epochs with all three; one more epoch has only a
    range."""
    rows = [(T0 + 60.0 * k + 0.5, 1200.0 + 3.25 * k, 350.0 + 4.5 * k - 360.0 * (k > 2),
             20.0 + k) for k in range(5)]
    obs = []
    for t, r, az, el in rows:
        epoch = ccsds_format.format_epoch(t).replace("2025-01-01", "2025-001")
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
    assert ("5 range/az/el measurements of 2025-001A from millstone; left out: 1 epoch(s) "
            "without all their keywords") in said
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
        ("radec", text.replace(">AZEL<", ">RADEC<"),
         "segment 1: REFERENCE_FRAME missing (supported: ICRF, GCRF, EME2000)"),
        ("xeyn", text.replace(">AZEL<", ">XEYN<"),
         "segment 1: ANGLE_TYPE = XEYN is not supported (supported: AZEL, RADEC)"),
        ("ut1", text.replace(">UTC<", ">UT1<"),
         "segment 1: TIME_SYSTEM = UT1 is not supported (supported: UTC, TAI, TT, GPS)"),
        ("ru", text.replace(">km<", ">RU<"),
         "segment 1: RANGE_UNITS = RU is not supported (supported: KM)"),
        ("teme", text.replace("<ANGLE_TYPE>AZEL</ANGLE_TYPE>",
                              "<ANGLE_TYPE>RADEC</ANGLE_TYPE>"
                              "<REFERENCE_FRAME>TEME</REFERENCE_FRAME>"),
         "segment 1: REFERENCE_FRAME = TEME is not supported (supported: ICRF, GCRF, "
         "EME2000)"),
        ("garbage", "hello\n", ":1: 'hello': not a CCSDS TDM (not a CCSDS message"),
        ("oem", "CCSDS_OEM_VERS = 3.0\n", "not a CCSDS TDM (another CCSDS message"),
        ("root", "<oem/>", ":1: not a TDM (its root element is <oem>)"),
    ]:
        (tmp_path / f"{name}.xml").write_text(edited)
        argv = ["import", "tdm", str(tmp_path / f"{name}.xml"), "--bag", str(tmp_path / name)]
        err = one_line_error(capsys, argv, says)
        assert str(tmp_path / f"{name}.xml") in err
        assert not (tmp_path / name).exists()


# a LEO object seen from Socorro (optical) and from Millstone (radar), in GCRF
T_SEEN = T0 + 86400.0 * 3 + 1234.5


def seen_from(station: str) -> np.ndarray:
    """A GCRF state (6,) km, km/s of an object 900 km above a point near `station`, at
    `T_SEEN`."""
    s = STATIONS[station]
    above = frames.site_itrs(s.lat_rad + 0.05, s.lon_rad - 0.08, 900.0)
    return frames.itrs_to_gcrs(np.r_[above, 1.0, 7.0, 0.5], T_SEEN)


def kvn_segment(meta: dict[str, str], rows: list[tuple[str, str, float]]) -> str:
    """One KVN TDM segment: META lines from `meta`, DATA lines (keyword, epoch, value)."""
    head = "\n".join(f"{k} = {v}" for k, v in meta.items())
    data = "\n".join(f"{k} = {e} {v!r}" for k, e, v in rows)
    return f"META_START\n{head}\nMETA_STOP\nDATA_START\n{data}\nDATA_STOP\n"


def kvn_tdm(path: Path, segments: list[str]) -> Path:
    path.write_text("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2025-01-05T00:00:00\n"
                    "ORIGINATOR = hand\n" + "".join(segments))
    return path


def radec_rows(epoch: str, frame: str) -> list[tuple[str, str, float]]:
    """ANGLE_1/ANGLE_2 (deg) of the Socorro object at `T_SEEN`, in `frame`, by astropy: the
    topocentric vector (GCRF, `frames.site_gcrs`) turned into its J2000 mean equator and
    equinox (EME2000) or left in GCRS (GCRF, ICRF)."""
    x = seen_from("socorro")
    rho = x[:3] - frames.site_gcrs(STATIONS["socorro"], T_SEEN)
    epochs = Time([T_SEEN], format="unix", scale="utc")
    c = GCRS(CartesianRepresentation(rho[:, None] * u.km), obstime=epochs)
    if frame == "EME2000":
        c = c.transform_to(PrecessedGeocentric(equinox=Time("J2000"), obstime=epochs))
    sph = c.spherical
    return [("ANGLE_1", epoch, float(sph.lon.to_value(u.deg)[0])),
            ("ANGLE_2", epoch, float(sph.lat.to_value(u.deg)[0]))]


def azel_rows(epoch: str) -> list[tuple[str, str, float]]:
    """RANGE (km), ANGLE_1/ANGLE_2 (az/el deg) of the Millstone object at `T_SEEN`."""
    r, az, el = frames.razel_gcrs(seen_from("millstone"), T_SEEN, STATIONS["millstone"])
    return [("RANGE", epoch, float(r)), ("ANGLE_1", epoch, math.degrees(az)),
            ("ANGLE_2", epoch, math.degrees(el))]


RADEC_META = {"TIME_SYSTEM": "UTC", "PARTICIPANT_1": "SOCORRO", "PARTICIPANT_2": "OBJ-1",
              "PATH": "2,1", "ANGLE_TYPE": "RADEC", "REFERENCE_FRAME": "EME2000"}
AZEL_META = {"TIME_SYSTEM": "UTC", "PARTICIPANT_1": "OBJ-1", "PARTICIPANT_2": "millstone",
             "PATH": "2,1,2", "ANGLE_TYPE": "AZEL", "RANGE_UNITS": "km"}


@pytest.mark.parametrize("frame", ["EME2000", "GCRF", "ICRF"])
def test_hand_written_radec_and_azel_are_read_as_written(tmp_path, capsys, frame):
    """A KVN TDM of an optical (RADEC, in `frame`) and a radar (AZEL) segment, the values
    computed for a known GCRF state: imported, they are `frames.radec_gcrs` and
    `frames.razel_gcrs` of it (<= 1 mas, well within 0.1")."""
    epoch = ccsds_format.format_epoch(T_SEEN)
    f = kvn_tdm(tmp_path / "hand.tdm", [
        kvn_segment({**RADEC_META, "REFERENCE_FRAME": frame}, radec_rows(epoch, frame)),
        kvn_segment(AZEL_META, azel_rows(epoch))])
    bag = tmp_path / "bag"
    assert cli.main(["import", "tdm", str(f), "--bag", str(bag)]) == 0
    assert "1 range/az/el and 1 ra/dec measurements of OBJ-1 from millstone, socorro" in \
        capsys.readouterr().out
    ms = {m.kind: m for m in evaluate.load(bag).measurements}
    radec, razel = ms[types.Kind.RA_DEC], ms[types.Kind.RANGE_AZ_EL]
    assert (radec.t, radec.frame_id, radec.object_id) == (T_SEEN, "socorro", "OBJ-1")
    assert (razel.t, razel.frame_id, razel.object_id) == (T_SEEN, "millstone", "OBJ-1")
    np.testing.assert_allclose(radec.R, np.diag(np.square(SENSORS["socorro"].sigma)))
    want = frames.radec_gcrs(seen_from("socorro"), T_SEEN, STATIONS["socorro"])
    d_ra = frames.wrap_pi(radec.z[0] - want[0]) * math.cos(want[1])
    assert max(abs(d_ra), abs(radec.z[1] - want[1])) <= 1 * MAS
    if frame == "EME2000":  # as written, the angles differ from GCRF by the frame bias
        raw = [v for _, _, v in radec_rows(epoch, frame)]
        off = math.hypot(frames.wrap_pi(math.radians(raw[0]) - want[0]) * math.cos(want[1]),
                         math.radians(raw[1]) - want[1])
        assert 5 * MAS < off < 30 * MAS
    r, az, el = frames.razel_gcrs(seen_from("millstone"), T_SEEN, STATIONS["millstone"])
    assert abs(razel.z[0] - r) <= 1e-9
    assert abs(frames.wrap_pi(razel.z[1] - az)) * math.cos(el) <= 1 * MAS
    assert abs(razel.z[2] - el) <= 1 * MAS


@pytest.mark.parametrize(("system", "shift"), [("UTC", 0.0), ("TAI", 37.0), ("TT", 69.184),
                                               ("GPS", 18.0)])
def test_time_systems_become_utc_stamps(tmp_path, system, shift):
    """The same epoch text in TAI is 37 s earlier in UTC in 2025 (TT 69.184 s, GPS 18 s)."""
    epoch = ccsds_format.format_epoch(T_SEEN)
    f = kvn_tdm(tmp_path / "t.tdm", [kvn_segment({**AZEL_META, "TIME_SYSTEM": system},
                                                 azel_rows(epoch))])
    assert cli.main(["import", "tdm", str(f), "--bag", str(tmp_path / "bag")]) == 0
    (m,) = evaluate.load(tmp_path / "bag").measurements
    assert abs(m.t - (T_SEEN - shift)) <= 1e-6
    assert ccsds_format.parse_epoch(epoch, ccsds_format.TimeSystem(system)) == m.t


@pytest.mark.parametrize(("edit", "says"), [
    ({"REFERENCE_FRAME": "TOD"},
     "segment 1: REFERENCE_FRAME = TOD is not supported (supported: ICRF, GCRF, EME2000)"),
    ({"REFERENCE_FRAME": "ITRF2000"}, "segment 1: REFERENCE_FRAME = ITRF2000 is not supported"),
    ({"REFERENCE_FRAME": "TEME"}, "segment 1: REFERENCE_FRAME = TEME is not supported"),
    ({"ANGLE_TYPE": "XSYE"}, "segment 1: ANGLE_TYPE = XSYE is not supported"),
    ({"TIME_SYSTEM": "TDB"}, "segment 1: TIME_SYSTEM = TDB is not supported"),
    ({"PARTICIPANT_1": "DSS-24"}, "segment 1: participants DSS-24, OBJ-1: need one known"),
])
def test_unsupported_kvn_is_refused_with_one_line(tmp_path, capsys, edit, says):
    epoch = ccsds_format.format_epoch(T_SEEN)
    f = kvn_tdm(tmp_path / "bad.tdm", [kvn_segment({**RADEC_META, **edit},
                                                   radec_rows(epoch, "EME2000"))])
    err = one_line_error(capsys, ["import", "tdm", str(f), "--bag", str(tmp_path / "bag")],
                         says)
    assert f"{f}" in err and not (tmp_path / "bag").exists()


def test_invalid_values_are_counted_and_left_out(tmp_path, capsys):
    """Non-finite values, a negative range, |el| or |dec| over 90 deg: those epochs are left
    out, counted and the first named; a file with nothing else is refused."""
    good = ccsds_format.format_epoch(T_SEEN)
    bad = [ccsds_format.format_epoch(T_SEEN + k) for k in range(1, 5)]
    azel = azel_rows(good)
    azel += [("RANGE", bad[0], -1.0), ("ANGLE_1", bad[0], 10.0), ("ANGLE_2", bad[0], 10.0)]
    azel += [("RANGE", bad[1], 900.0), ("ANGLE_1", bad[1], 10.0), ("ANGLE_2", bad[1], 95.0)]
    radec = [("ANGLE_1", bad[2], math.nan), ("ANGLE_2", bad[2], 10.0),
             ("ANGLE_1", bad[3], 10.0), ("ANGLE_2", bad[3], -90.5),
             ("RANGE", bad[3], 1000.0)]
    f = kvn_tdm(tmp_path / "v.tdm", [kvn_segment(AZEL_META, azel),
                                     kvn_segment(RADEC_META, radec)])
    assert cli.main(["import", "tdm", str(f), "--bag", str(tmp_path / "bag")]) == 0
    said = capsys.readouterr().out
    assert "1 range/az/el measurements of OBJ-1" in said
    # the first named by the line that completed its epoch (ANGLE_2 of bad[0])
    assert (f"left out: 4 epoch(s) with invalid values (first: {f}:18: segment 1, {bad[0]} UTC: "
            "negative RANGE -1.0 km); observations not used: 1 RANGE") in said, said
    assert len(evaluate.load(tmp_path / "bag").measurements) == 1
    f = kvn_tdm(tmp_path / "w.tdm", [kvn_segment(RADEC_META, radec)])
    one_line_error(capsys, ["import", "tdm", str(f), "--bag", str(tmp_path / "bag2")],
                   "no usable epoch")


def radec_bag(path: Path, frame_id: str = Frame.GCRF) -> list[types.Measurement]:
    """A bag of RA_DEC measurements of the Socorro object (GCRF, astrometric) and an
    estimate whose header says `frame_id` (the frame of the bag's states, and so of its
    RA/Dec)."""
    x = seen_from("socorro")
    t = T_SEEN + np.arange(3) * 10.0
    xs = x + np.outer(np.arange(3) * 10.0, np.r_[x[3:], 0, 0, 0])  # straight line, fine
    z = frames.radec_gcrs(xs, t, STATIONS["socorro"])
    ms = [types.Measurement(float(ti), zi, np.diag(np.square(SENSORS["socorro"].sigma)),
                            types.Kind.RA_DEC, types.Source.SENSOR, "OBJ-1", "socorro")
          for ti, zi in zip(t, z, strict=True)]
    write_bag(path, [types.StateEstimate(float(t[0]), x, np.eye(6), "OBJ-1")], ms, frame_id)
    return ms


@pytest.mark.parametrize(("frame", "fmt"), [("ICRF", "kvn"), ("EME2000", "xml")])
def test_radec_tdm_round_trip(tmp_path, capsys, frame, fmt):
    """RA_DEC measurements -> TDM (RADEC in ICRF = the GCRF values, or EME2000) -> a new bag:
    the same measurements (<= 1e-12 rad), noise from the comment."""
    ms = radec_bag(tmp_path / "bag")
    out = tmp_path / "o.tdm"
    assert cli.main(["export", "tdm", str(tmp_path / "bag"), "--frame", frame,
                     "--out", str(out), "--format", fmt]) == 0
    assert "3 ra/dec measurements in 1 segment(s)" in capsys.readouterr().out
    seg = NdmIo().from_path(out).body.segment[0]
    assert (seg.metadata.angle_type.value, seg.metadata.reference_frame.value,
            seg.metadata.time_system, seg.metadata.participant_1) == (
        "RADEC", frame, "UTC", "socorro")
    ra_file = math.radians(seg.data.observation[0].angle_1.value)
    assert (abs(ra_file - ms[0].z[0]) > 5 * MAS) == (frame == "EME2000")
    assert cli.main(["import", "tdm", str(out), "--bag", str(tmp_path / "back")]) == 0
    back = evaluate.load(tmp_path / "back").measurements
    assert [m.t for m in back] == [m.t for m in ms]
    for a, b in zip(ms, back, strict=True):
        assert (b.kind, b.frame_id, b.object_id) == (types.Kind.RA_DEC, "socorro", "OBJ-1")
        np.testing.assert_allclose(b.z, a.z, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.R, a.R, rtol=1e-12)


def test_radec_of_an_old_frame_bag_is_not_exported(tmp_path, capsys):
    """RA/Dec of a bag whose states say "eci" were computed in that frame: not exported as
    ICRF/GCRF."""
    radec_bag(tmp_path / "old", frame_id="eci")
    old = tmp_path / "old"
    one_line_error(capsys, ["export", "tdm", str(old), "--out", str(tmp_path / "x.tdm")],
                   "its /ssa/estimate messages say frame 'eci', not 'gcrf'")


def test_tdm_of_a_recorded_run_replays_to_its_estimates(tmp_path, capsys):
    """The sample bag's real measurements -> TDM -> a new bag: the same measurements; run
    offline, the fused estimates equal those the live run recorded (as `test_replay` holds
    for the bag itself) when the sample was recorded with the current frames."""
    out = tmp_path / "run.tdm"
    assert cli.main(["export", "tdm", str(SAMPLE), "--out", str(out)]) == 0
    assert cli.main(["import", "tdm", str(out), "--bag", str(tmp_path / "imported")]) == 0
    live, imported = evaluate.load(SAMPLE), evaluate.load(tmp_path / "imported")
    assert [m.t for m in imported.measurements] == [m.t for m in live.measurements]
    for a, b in zip(live.measurements, imported.measurements, strict=True):
        np.testing.assert_allclose(b.z, a.z, rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(b.R, a.R, rtol=1e-14)
    frames_said = ccsds.load_bag(SAMPLE).state_frames[TOPIC_ESTIMATE]
    if frames_said != {Frame.GCRF}:
        pytest.skip(f"{SAMPLE.name} says frame {sorted(frames_said)}: recorded before the "
                    "real Earth, its estimates are not what a replay computes now; re-record it")
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
        text = ccsds_format.format_epoch(t)
        assert ccsds_format.parse_epoch(text) == messages.stamp_to_seconds(
            messages.seconds_to_stamp(t, bagio.rosbags_classes()))
    assert ccsds_format.parse_epoch("2025-001T00:00:01Z") == T0 + 1
    with pytest.raises(ccsds_format.CcsdsError, match="not a CCSDS epoch"):
        ccsds_format.parse_epoch("yesterday")


@pytest.mark.parametrize("text, says", [
    ("2025-999T00:00:00", "day of year 999 is not in the year 2025"),
    ("2025-000T00:00:00", "day of year 000"),
    ("2024-367T00:00:00", "day of year 367 is not in the year 2024"),
    ("2025-01-01T99:00:00", "time of day 99:00:00 is not one"),
    ("2025-01-01T00:60:00", "time of day 00:60:00 is not one"),
    ("2025-01-01T00:00:75", "time of day 00:00:75 is not one"),
])
def test_an_epoch_out_of_its_calendar_is_refused_not_rolled_over(text, says):
    """Day-of-year 999 and hour 99 were read as days and hours after the date (2027-09,
    2025-01-05): now a CcsdsError, which `import tdm` turns into one line and exit 2."""
    with pytest.raises(ccsds_format.CcsdsError, match=says):
        ccsds_format.parse_epoch(text)
    assert ccsds_format.parse_epoch("2024-366T23:59:59") == ccsds_format.parse_epoch(
        "2024-12-31T23:59:59")


def test_frame_bias_is_erfas():
    """The EME2000 rotation is ERFA's IAU 2006 frame bias: ~23 mas, orthonormal."""
    b = ccsds_format.frame_bias()
    np.testing.assert_allclose(b @ b.T, np.eye(3), atol=1e-15)
    angle = math.acos((np.trace(b) - 1) / 2)
    assert 20 * MAS < angle < 26 * MAS


def test_an_empty_xml_value_is_refused_in_one_line(tmp_path, capsys):
    """An empty ``<RANGE></RANGE>`` ended `import tdm` in a ValueError traceback; now the
    file is refused with one line naming the line and the keyword, and no bag is left."""
    rows = [("2025-01-01T00:00:00", "9468.2"), ("2025-01-01T00:00:30", "")]
    obs = "".join(f"<observation><EPOCH>{e}</EPOCH><{k}{u}>{v}</{k}></observation>"
                  for e, r in rows for k, u, v in (("RANGE", "", r),
                                                   ("ANGLE_1", ' units="deg"', "35.8"),
                                                   ("ANGLE_2", ' units="deg"', "-43.6")))
    f = tmp_path / "empty.xml"
    f.write_text('<?xml version="1.0" encoding="UTF-8"?><tdm id="CCSDS_TDM_VERS" version="2.0">'
                 "<header><CREATION_DATE>2025-01-02T00:00:00</CREATION_DATE><ORIGINATOR>t"
                 "</ORIGINATOR></header><body><segment><metadata><TIME_SYSTEM>UTC</TIME_SYSTEM>"
                 "<PARTICIPANT_1>columbus</PARTICIPANT_1><PARTICIPANT_2>OBJ-1</PARTICIPANT_2>"
                 "<MODE>SEQUENTIAL</MODE><PATH>1,2,1</PATH><ANGLE_TYPE>AZEL</ANGLE_TYPE>"
                 f"</metadata><data>{obs}</data></segment></body></tdm>")
    assert cli.main(["import", "tdm", str(f), "--bag", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "RANGE" in err[0] and str(f) in err[0], err
    assert not (tmp_path / "bag").exists()
