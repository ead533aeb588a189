"""`ssa-fusion report` of a catalog's bag: every object scored on its own rows only.

A bag is written from a known truth (SGP4 of a synthetic catalog) with estimates that are
the truth plus a known, different error per object (one object's error 1000 times the
others'); the report's per-object numbers must equal a direct computation per object:
numpy's median and percentile of the position errors, the NEES from the inverse covariance,
the post-fit residuals from the scalar measurement model (`measurement.RazelModel`, not the
report's vectorised one). An unlabelled bag's association score must equal
`evaluation.association`'s.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import cli
from ssa_fusion.core.base.metrics import chi2_bounds
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import StateEstimate, UpdateSource
from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.measure.measurement import RazelModel
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.evaluation.association import detection_labels, score_association
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_CONFIG,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
)
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
STATIONS = ",".join(r.station.name for r in RADARS)
C = bagio.rosbags_classes()
SIGMA_KM = (0.02, 0.05, 0.1, 20.0)
"""Per object, the 1-σ of its estimates' position error (km): the last object's 1000 times
the first's."""


@dataclasses.dataclass
class Run:
    """What the bag was written from."""

    meas: MeasurementRows
    est: EstimateRows
    truth: np.ndarray
    """The true state at each estimate row."""


@pytest.fixture(scope="module")
def run() -> Run:
    """4 objects measured for 3 h; one estimate per object and epoch: truth + its error."""
    base = catalog.read_catalog(SAMPLE)[0]
    entries = survey.synthetic_catalog(base, len(SIGMA_KM), seed=4)
    obs = survey.observe_catalog(entries, RADARS, base.epoch_unix, 3 * 3600.0, seed=2)
    ids = [obs.object_ids[k] for k in obs.obj]
    meas = MeasurementRows(obs.t, ids, [obs.sensors[j].station.name for j in obs.sensor],
                           obs.z, np.stack([obs.sensors[j].R for j in obs.sensor]),
                           shard_key=messages.shard_keys(ids))
    pairs = np.unique(np.stack([obs.obj.astype(float), obs.t]), axis=1)
    obj, t = pairs[0].astype(int), pairs[1]
    epochs = np.unique(t)
    states = catalog_states(entries, epochs).x
    truth = states[obj, np.searchsorted(epochs, t)]
    rng = np.random.default_rng(7)
    sig = np.asarray(SIGMA_KM)[obj]
    x = truth.copy()
    x[:, :3] += rng.normal(size=(len(t), 3)) * sig[:, None]
    P = np.zeros((len(t), 6, 6))
    P[:, [0, 1, 2], [0, 1, 2]] = (sig ** 2)[:, None]
    P[:, [3, 4, 5], [3, 4, 5]] = 1e-6
    P[obj == 1, :3, :3] *= 4.0  # object 1 claims twice its σ: NEES mostly below the band
    est = EstimateRows(t, [obs.object_ids[k] for k in obj], x, P, rng.chisquare(3, len(t)),
                       UpdateSource.SENSOR)
    est.shard_key = messages.shard_keys(est.object_id)
    return Run(meas, est, truth)


def _writer(bag: Path, first: float) -> bagio.BagWriter:
    """A bag with the catalog_filter's settings (one shard, the radar network)."""
    w = bagio.BagWriter(bag)
    w.add_topic(TOPIC_CONFIG, "std_msgs/msg/String")
    text = bagio.typestore().types["std_msgs/msg/String"]
    params = {**dataclasses.asdict(CATALOG_FILTER), "station": STATIONS}
    w.write_msg(TOPIC_CONFIG, int(first * 1e9), text(data=settings.catalog_config_message(params)))
    return w


def write_bag(bag: Path, r: Run, truth_batches: bool) -> Path:
    """Measurements and estimates in 10-minute batches; the truth on /ssa/truth: each
    object's as one EstimateBatch (`truth_batches`), else one StateEstimate a row."""
    w = _writer(bag, r.meas.t[0])
    for topic, msgtype in ((TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH),
                           (TOPIC_ESTIMATE_BATCH, bagio.ESTIMATE_BATCH),
                           (TOPIC_TRUTH, bagio.ESTIMATE_BATCH if truth_batches
                            else bagio.STATE_ESTIMATE)):
        w.add_topic(topic, msgtype)
    ids = np.asarray(r.est.object_id)
    for k, oid in enumerate(sorted(set(r.est.object_id))):
        mine = np.flatnonzero(ids == oid)
        tr = EstimateRows(r.est.t[mine], [oid] * len(mine), r.truth[mine],
                          np.zeros((len(mine), 6, 6)), np.zeros(len(mine)), UpdateSource.NONE)
        if truth_batches:
            w.write_msg(TOPIC_TRUTH, int(r.meas.t[0] * 1e9) + k,
                        messages.estimate_batch_to_msg(tr, classes=C))
            continue
        for i in range(len(mine)):
            w.write_msg(TOPIC_TRUTH, int(tr.t[i] * 1e9), messages.estimate_to_msg(
                StateEstimate(tr.t[i], tr.x[i], tr.P[i], oid, int(UpdateSource.NONE)),
                classes=C))
    step = np.floor((r.meas.t - r.meas.t[0]) / 600.0).astype(int)
    est_step = np.floor((r.est.t - r.meas.t[0]) / 600.0).astype(int)
    for s in np.unique(step).tolist():
        t_ns = int((r.meas.t[0] + (s + 1) * 600.0) * 1e9)
        w.write_msg(TOPIC_MEASUREMENT_BATCH, t_ns, messages.measurement_batch_to_msg(
            r.meas.take(np.flatnonzero(step == s)), classes=C))
        e = np.flatnonzero(est_step == s)
        if len(e):
            w.write_msg(TOPIC_ESTIMATE_BATCH, t_ns + 1,
                        messages.estimate_batch_to_msg(r.est.take(e), classes=C))
    w.close()
    return bag


def reference(r: Run, oid: str) -> dict:
    """Object `oid`'s numbers computed directly, from its own rows only."""
    e = np.flatnonzero(np.asarray(r.est.object_id) == oid)
    d = r.est.x[e] - r.truth[e]
    err = np.linalg.norm(d[:, :3], axis=1)
    nees = np.array([di @ np.linalg.inv(Pi) @ di for di, Pi in zip(d, r.est.P[e], strict=True)])
    lo, hi = chi2_bounds(6)
    nlo, nhi = chi2_bounds(3)
    at = {float(t): i for t, i in zip(r.est.t[e], e, strict=True)}
    models = {s.station.name: RazelModel(s.station, UNIX_EPOCH_JD) for s in RADARS}
    norm = []
    for i in np.flatnonzero(np.asarray(r.meas.object_id) == oid).tolist():
        x = r.est.x[at[float(r.meas.t[i])]]
        y = r.meas.z[i] - models[r.meas.frame_id[i]].h(x, float(r.meas.t[i]))
        y[1] = wrap_angle(float(y[1]))
        norm.append(y / np.sqrt(np.diag(r.meas.R[i])))
    nis = r.est.nis[e]
    return {"estimates": len(e), "median": np.median(err), "p95": np.percentile(err, 95),
            "nees_inside": np.mean((nees >= lo) & (nees <= hi)), "nees_mean": np.mean(nees),
            "nis_inside": np.mean((nis >= nlo) & (nis <= nhi)),
            "rms": np.sqrt(np.mean(np.square(norm))), "measurements": len(norm)}


@pytest.mark.parametrize("truth_batches", [True, False])
def test_each_objects_numbers_are_its_own(run, tmp_path, capsys, truth_batches):
    bag = write_bag(tmp_path / "bag", run, truth_batches)
    out = tmp_path / "rep"
    assert cli.main(["report", str(bag), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "catalog's bag" in said and "no /ssa/config" not in said
    assert f"catalog_filter settings: recorded with the bag ({TOPIC_CONFIG}; 1 shard(s)): " \
           f"station {STATIONS}" in said
    rep = json.loads((out / "report.json").read_text())
    rows = {o["object"]: o for o in rep["worst"]}
    ids = sorted(set(run.est.object_id))
    assert set(rows) == set(ids)
    assert rep["worst"][0]["object"] == ids[-1]  # the largest error ranks first
    for oid in ids:
        want, got = reference(run, oid), rows[oid]
        assert got["estimates"] == got["estimates_with_truth"] == want["estimates"]
        assert got["measurements"] == got["residual_rows"] == want["measurements"]
        assert got["position_error_median_km"] == pytest.approx(want["median"], rel=1e-9)
        assert got["position_error_p95_km"] == pytest.approx(want["p95"], rel=1e-9)
        assert got["nees_inside_95"] == pytest.approx(want["nees_inside"], abs=1e-12)
        assert got["nees_mean"] == pytest.approx(want["nees_mean"], rel=1e-6)
        assert got["nis_inside_95"] == pytest.approx(want["nis_inside"], abs=1e-12)
        assert got["postfit_residual_rms_sigma"] == pytest.approx(want["rms"], rel=1e-6)
    # the small-error objects are not touched by the large one's rows
    assert rows[ids[0]]["position_error_p95_km"] < 0.1
    assert rows[ids[0]]["postfit_residual_rms_sigma"] < 3.0
    assert rows[ids[-1]]["postfit_residual_rms_sigma"] > 100.0
    assert rows[ids[1]]["nees_inside_95"] < 0.5  # its covariance claims too much
    s = rep["summary"]
    err = np.linalg.norm(run.est.x[:, :3] - run.truth[:, :3], axis=1)
    assert s["objects"] == len(ids) and s["estimates"] == len(run.est)
    assert s["position_error_km"]["median"] == pytest.approx(np.median(err), rel=1e-9)
    assert s["position_error_km"]["p95"] == pytest.approx(np.percentile(err, 95), rel=1e-9)
    lines = (out / "objects.csv").read_text().splitlines()
    assert len(lines) == 1 + len(ids)
    assert "<table" in (out / "report.html").read_text()


def test_unlabelled_tracks_score_as_evaluation_association(run, tmp_path, capsys):
    """Detections without ids, placed in tracks (some wrongly); the report's association is
    `evaluation.association`'s, each track's measurements its own associated rows, each
    confirmed track scored against the truth of the object most of its detections are of."""
    ids = sorted(set(run.meas.object_id))
    obj = np.asarray(run.meas.object_id)
    track = np.full(len(obj), "", dtype=object)
    track[obj == ids[0]] = "T0"
    track[obj == ids[1]] = "T1"
    track[np.flatnonzero(obj == ids[1])[:3]] = "T0"  # three of object 1's placed in T0
    track[obj == ids[2]] = "T2"  # a tracklet: never confirmed (no estimates)
    placed = np.flatnonzero(track != "")
    associated = run.meas.take(placed)
    associated.object_id = track[placed].tolist()
    unlabelled = dataclasses.replace(run.meas, object_id=[""] * len(run.meas),
                                     shard_key=np.zeros(len(run.meas), np.uint32))
    est_obj = np.asarray(run.est.object_id)
    keep = np.flatnonzero(np.isin(est_obj, ids[:2]))
    est = run.est.take(keep)
    est.object_id = ["T0" if o == ids[0] else "T1" for o in est_obj[keep]]
    bag = tmp_path / "bag"
    w = _writer(bag, run.meas.t[0])
    for topic, msgtype in ((TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH),
                           (TOPIC_DETECTION_TRUTH, bagio.MEASUREMENT_BATCH),
                           (TOPIC_ASSOCIATED, bagio.MEASUREMENT_BATCH),
                           (TOPIC_ESTIMATE_BATCH, bagio.ESTIMATE_BATCH),
                           (TOPIC_TRUTH, bagio.ESTIMATE_BATCH)):
        w.add_topic(topic, msgtype)
    t_ns = int(run.meas.t[-1] * 1e9) + 1
    w.write_msg(TOPIC_TRUTH, t_ns, messages.estimate_batch_to_msg(dataclasses.replace(
        run.est, x=run.truth, P=np.zeros_like(run.est.P)), classes=C))
    w.write_msg(TOPIC_MEASUREMENT_BATCH, t_ns, messages.measurement_batch_to_msg(unlabelled,
                                                                                classes=C))
    w.write_msg(TOPIC_DETECTION_TRUTH, t_ns, messages.measurement_batch_to_msg(run.meas,
                                                                              classes=C))
    w.write_msg(TOPIC_ASSOCIATED, t_ns, messages.measurement_batch_to_msg(associated, classes=C))
    w.write_msg(TOPIC_ESTIMATE_BATCH, t_ns, messages.estimate_batch_to_msg(est, classes=C))
    w.close()
    out = tmp_path / "rep"
    assert cli.main(["report", str(bag), "--out", str(out)]) == 0
    capsys.readouterr()
    rep = json.loads((out / "report.json").read_text())
    want = score_association(run.meas.object_id, detection_labels(run.meas, associated),
                             {"T0", "T1"})
    a = rep["association"]
    assert a["accuracy"] == pytest.approx(want.accuracy) and 0.9 < a["accuracy"] < 1.0
    assert a["coverage"] == pytest.approx(want.coverage)
    assert a["confirmed_tracks"] == 2 and a["objects_with_track"] == want.objects_with_track
    rows = {o["object"]: o for o in rep["worst"]}
    assert {k: rows[k]["measurements"] for k in ("T0", "T1", "T2")} == {
        k: int(np.sum(track == k)) for k in ("T0", "T1", "T2")}
    assert rows["T2"]["estimates"] == 0
    assert rows["T0"]["truth_object"] == ids[0] and rows["T1"]["truth_object"] == ids[1]
    for track, oid in (("T0", ids[0]), ("T1", ids[1])):  # scored against its object's truth
        want_err = reference(run, oid)
        assert rows[track]["position_error_median_km"] == pytest.approx(want_err["median"],
                                                                        rel=1e-9)
        assert rows[track]["position_error_p95_km"] == pytest.approx(want_err["p95"], rel=1e-9)
