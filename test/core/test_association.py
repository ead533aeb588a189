"""Association of unlabelled detections (`core.association`): gating and global nearest
neighbour against Stone Soup's GNN (`GNNWith2DAssignment`, `DistanceHypothesiser`,
Mahalanobis), brute-force enumeration of every assignment, scipy's Mahalanobis distance,
the per-object measurement model, and analytic cases."""

from __future__ import annotations

import datetime
import itertools
import math

import numpy as np
import pytest
from scipy.spatial.distance import mahalanobis

from ssa_fusion.core.association import (
    UNASSIGNED,
    AssociationConfig,
    ScanPrediction,
    assign,
    associate,
    gate_scan,
)
from ssa_fusion.core.batch_ekf import BatchEKF
from ssa_fusion.core.constants import MU_EARTH
from ssa_fusion.core.filter_options import FilterOptions
from ssa_fusion.core.frames import razel_gcrs, site_gcrs
from ssa_fusion.core.measurement import RazelModel
from ssa_fusion.core.stations import SENSORS
from ssa_fusion.core.timescales import UNIX_EPOCH_JD

RADAR = SENSORS["columbus"]
T0 = 1_735_732_800.0  # 2025-01-01T12:00:00Z
GATE = AssociationConfig().gate


def _prediction(zp: np.ndarray, HPHt: np.ndarray) -> ScanPrediction:
    """A one-epoch prediction of N tracks given directly in measurement space."""
    n = zp.shape[0]
    return ScanPrediction(np.array([T0]), np.zeros(0, np.int64), zp[None], HPHt[None],
                          np.ones((1, n), bool), np.zeros((1, n)))


def _gated(zp, HPHt, z, R):
    pred = _prediction(np.asarray(zp, float), np.asarray(HPHt, float))
    pred = ScanPrediction(pred.epochs, np.zeros(len(z), np.int64), pred.zp, pred.HPHt,
                          pred.ok, pred.sigma_pos)
    return gate_scan(pred, np.asarray(z, float), np.asarray(R, float), GATE)


def _random_scan(rng, n: int, m: int, spread: float = 2.0):
    """N tracks and M detections in measurement space, packed so that gates overlap."""
    zp = np.array([1000.0, 1.0, 0.5]) + rng.normal(0, 1, (n, 3)) * [spread * 0.02, 3e-4, 3e-4]
    A = rng.normal(0, 1, (n, 3, 3)) * [0.01, 2e-4, 2e-4]
    HPHt = A @ np.swapaxes(A, 1, 2) + np.diag([1e-4, 1e-8, 1e-8])
    z = np.array([1000.0, 1.0, 0.5]) + rng.normal(0, 1, (m, 3)) * [spread * 0.02, 3e-4, 3e-4]
    R = np.tile(np.diag([4e-4, 1.2e-7, 1.2e-7]), (m, 1, 1)) * rng.uniform(0.5, 2.0, (m, 1, 1))
    return zp, HPHt, z, R


# ------------------------------------------------------------------------------------------
# Configuration
# ------------------------------------------------------------------------------------------
def test_gate_is_the_chi_square_quantile_with_three_degrees_of_freedom():
    # tables: chi-square 3 dof, P = 0.9999 -> 21.108; P = 0.99 -> 11.345
    assert AssociationConfig().gate == pytest.approx(21.108, abs=1e-3)
    assert AssociationConfig(gate_probability=0.99).gate == pytest.approx(11.345, abs=1e-3)


@pytest.mark.parametrize("bad", [{"gate_probability": 1.0}, {"confirm_hits": 9},
                                 {"delete_after_missed_passes": 0}, {"pass_gap_s": 0.0}])
def test_config_refuses_nonsense(bad):
    with pytest.raises(ValueError, match=next(iter(bad)).split("_")[0]):
        AssociationConfig(**bad)


# ------------------------------------------------------------------------------------------
# Prediction and gating against independent computations
# ------------------------------------------------------------------------------------------
def _visible_states(n: int, t: float, rng) -> np.ndarray:
    """N circular-speed states ~600-1200 km from the radar, above it."""
    site = site_gcrs(RADAR.station, t)
    up = site / np.linalg.norm(site)
    x = np.empty((n, 6))
    for i in range(n):
        r = site + up * rng.uniform(600, 1200) + rng.normal(0, 300, 3)
        v = np.cross(r, rng.normal(0, 1, 3))
        x[i, :3] = r
        x[i, 3:] = v / np.linalg.norm(v) * math.sqrt(MU_EARTH / np.linalg.norm(r))
    return x


def test_predicted_measurements_and_distances_match_the_per_object_model():
    rng = np.random.default_rng(3)
    ekf = BatchEKF(FilterOptions().with_(q=1e-12), [RADAR.station])
    n = 5
    x = _visible_states(n, T0, rng)
    P = np.tile(np.diag([0.5, 0.5, 0.5, 1e-6, 1e-6, 1e-6]), (n, 1, 1))
    t_scan = np.array([T0 + 20.0, T0 + 20.0, T0 + 30.0])  # two epochs in one scan
    truth = ekf.predict(x[[0, 2, 4]], P[[0, 2, 4]], t_scan - T0, T0).x
    z = razel_gcrs(truth, t_scan, RADAR.station) + np.array([0.01, 2e-4, -2e-4])
    R = np.tile(RADAR.R, (3, 1, 1))
    out = associate(ekf, x, P, np.full(n, T0), t_scan, z, R, 0, AssociationConfig())
    model = RazelModel(RADAR.station, UNIX_EPOCH_JD)
    for j in range(3):
        pred = ekf.predict(x, P, t_scan[j] - T0, T0)
        for i in range(n):
            zp, H = model.h_and_H(pred.x[i], t_scan[j])
            S = H @ pred.P[i] @ H.T + R[j]
            y = z[j] - zp
            y[1:] = (y[1:] + math.pi) % (2 * math.pi) - math.pi
            d = mahalanobis(z[j], z[j] - y, np.linalg.inv(S))
            assert out.gated.d2[i, j] == pytest.approx(d * d, rel=1e-6)
            assert out.gated.cost[i, j] == pytest.approx(d * d + math.log(np.linalg.det(S)),
                                                         rel=1e-6, abs=1e-6)
    # each detection is its own track's
    assert out.track.tolist() == [0, 2, 4]


def test_azimuth_innovation_wraps_at_north():
    g = _gated([[1000.0, 2 * math.pi - 1e-4, 0.5]], [np.diag([1e-4, 1e-8, 1e-8])],
               [[1000.0, 1e-4, 0.5]], [np.diag([4e-4, 1e-8, 1e-8])])
    assert g.d2[0, 0] == pytest.approx((2e-4) ** 2 / 2e-8, rel=1e-9)


# ------------------------------------------------------------------------------------------
# Analytic cases
# ------------------------------------------------------------------------------------------
R1 = np.diag([1.0, 1.0, 1.0])


def test_gate_boundary_is_inclusive():
    # S = 2 I, innovation along range: d^2 = y^2 / 2
    for scale, inside in ((1 - 1e-9, True), (1 + 1e-9, False)):
        y = math.sqrt(2 * GATE * scale)
        g = _gated([[1000.0, 1.0, 0.5]], [R1], [[1000.0 + y, 1.0, 0.5]], [R1])
        assert g.d2[0, 0] == pytest.approx(GATE * scale, rel=1e-12)
        assert bool(g.feasible[0, 0]) is inside
        assert assign(g.cost, g.feasible).tolist() == [0 if inside else UNASSIGNED]


def test_crossing_detections_go_to_their_own_tracks():
    # detections listed in the other order than the tracks, crossing in range
    zp = [[1000.0, 1.0, 0.5], [1003.0, 1.0, 0.5]]
    g = _gated(zp, [R1 * 0.5] * 2, [[1002.6, 1.0, 0.5], [1000.3, 1.0, 0.5]], [R1 * 0.5] * 2)
    assert assign(g.cost, g.feasible).tolist() == [1, 0]


def test_global_not_greedy():
    # detection 0 is nearest to track 0, but only track 0 gates detection 1: the global
    # assignment gives 1 -> 0 and 0 -> 1 (greedy would leave detection 1 unassigned)
    zp = [[1000.0, 1.0, 0.5], [1005.0, 1.0, 0.5]]
    z = [[1002.0, 1.0, 0.5], [997.5, 1.0, 0.5]]
    g = _gated(zp, [R1 * 0.5] * 2, z, [R1 * 0.5] * 2)
    assert g.feasible.tolist() == [[True, True], [True, False]]
    assert g.d2[0, 0] < g.d2[1, 0]
    assert assign(g.cost, g.feasible).tolist() == [1, 0]


def test_detection_inside_two_gates_goes_to_the_least_cost_track():
    # one detection 2 km off both tracks; track 0 with S = I (d^2 = 4, ln det S = 0),
    # track 1 with S = 4 I (d^2 = 1, ln det S = 3 ln 4 = 4.16): costs 4 and 5.16 -> track 0
    # although track 1 is nearer in Mahalanobis distance
    zp = [[1000.0, 1.0, 0.5], [1000.0, 1.0, 0.5]]
    g = _gated(zp, [R1 * 0.5, R1 * 3.5], [[1002.0, 1.0, 0.5]], [R1 * 0.5])
    assert g.d2[:, 0].tolist() == pytest.approx([4.0, 1.0])
    assert g.cost[:, 0].tolist() == pytest.approx([4.0, 1.0 + 3 * math.log(4.0)])
    assert assign(g.cost, g.feasible).tolist() == [0]


def test_no_tracks_or_no_detections():
    assert assign(np.zeros((0, 3)), np.zeros((0, 3), bool)).tolist() == [UNASSIGNED] * 3
    assert assign(np.zeros((2, 0)), np.zeros((2, 0), bool)).tolist() == []


# ------------------------------------------------------------------------------------------
# Against brute force and Stone Soup
# ------------------------------------------------------------------------------------------
def _brute_force(cost: np.ndarray, feasible: np.ndarray) -> list[int]:
    """Every partial one-to-one assignment of feasible pairs: most pairs, then least cost."""
    n, m = cost.shape
    best: tuple[int, float] = (1, 0.0)
    out = [UNASSIGNED] * m
    for choice in itertools.product(range(-1, n), repeat=m):
        used = [i for i in choice if i >= 0]
        if len(set(used)) != len(used) or any(i >= 0 and not feasible[i, j]
                                              for j, i in enumerate(choice)):
            continue
        key = (-len(used), sum(cost[i, j] for j, i in enumerate(choice) if i >= 0))
        if key < best or best == (1, 0.0):
            best, out = key, list(choice)
    return out


@pytest.mark.parametrize("seed", range(40))
def test_assignment_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    n, m = rng.integers(1, 5, 2)
    g = _gated(*_random_scan(rng, int(n), int(m)))
    assert assign(g.cost, g.feasible).tolist() == _brute_force(g.cost, g.feasible)


stonesoup = pytest.importorskip("stonesoup")


def _stone_soup(zp, HPHt, z, R) -> list[int]:
    """Stone Soup's GNN on tracks given in measurement space (a static 3-D state with
    covariance H P H^T, measured by the identity with each detection's own R), its
    hypotheses scored d^2 + ln det S within the chi-square gate."""
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.measures import SquaredMahalanobis
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        RandomWalk,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    class GnnCost(SquaredMahalanobis):
        """d^2 + ln det S inside the gate, else inf (beyond the missed distance)."""

        def __call__(self, state1, state2):
            d2 = super().__call__(state1, state2)
            if not d2 <= GATE:
                return math.inf
            return d2 + math.log(np.linalg.det(state1.covar))

    when = datetime.datetime(2025, 1, 1, 12)
    static = CombinedLinearGaussianTransitionModel([RandomWalk(0.0)] * 3)
    updater = KalmanUpdater(LinearGaussian(3, (0, 1, 2), np.eye(3)))
    hyp = DistanceHypothesiser(KalmanPredictor(static), updater, GnnCost(),
                               missed_distance=1e12)
    tracks = [Track([GaussianState(np.asarray(zp[i], float).reshape(3, 1), HPHt[i], when)])
              for i in range(len(zp))]
    dets = [Detection(np.asarray(z[j], float).reshape(3, 1), when,
                      measurement_model=LinearGaussian(3, (0, 1, 2), R[j]))
            for j in range(len(z))]
    hyps = GNNWith2DAssignment(hyp).associate(set(tracks), set(dets), when)
    out = [UNASSIGNED] * len(z)
    for i, tr in enumerate(tracks):
        h = hyps.get(tr)
        if h is not None and h.measurement in dets:
            out[dets.index(h.measurement)] = i
    return out


@pytest.mark.parametrize("seed", range(25))
def test_gating_and_assignment_equal_stone_soup_gnn(seed):
    rng = np.random.default_rng(100 + seed)
    n, m = rng.integers(1, 9, 2)
    zp, HPHt, z, R = _random_scan(rng, int(n), int(m))
    g = _gated(zp, HPHt, z, R)
    assert g.feasible.any()  # the case exercises the gate
    assert assign(g.cost, g.feasible).tolist() == _stone_soup(zp, HPHt, z, R)


# ------------------------------------------------------------------------------------------
# Track management on a simulated train (unlabelled scans, truth kept aside)
# ------------------------------------------------------------------------------------------
from ssa_fusion.core.association import (  # noqa: E402
    Associator,
    DetectionFate,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.filter_options import SKY_FILTER  # noqa: E402
from ssa_fusion.sim import survey  # noqa: E402

MASK = math.radians(RADAR.min_elevation_deg)
NETWORK = {RADAR.station.name: RADAR.station}


@pytest.fixture(scope="module")
def train_obs():
    """A train of 5 objects 1-5 km apart over the radar, 4 h: its first passes."""
    cat = survey.satellite_train(RADAR.station, T0 + 600.0, 5, seed=2)
    return survey.observe_catalog(cat, [RADAR], T0, 4 * 3600.0, seed=2)


def _passes(scans, gap: float = 600.0):
    t = np.array([s.t for s in scans])
    return np.split(np.arange(len(scans)), np.flatnonzero(np.diff(t) > gap) + 1)


def _feed(assoc, scans, empty: bool = False):
    out = []
    for s in scans:
        z = s.z[:0] if empty else s.z
        out.append(assoc.process_scan(RADAR.station.name, s.t, z,
                                      np.broadcast_to(RADAR.R, (z.shape[0], 3, 3)), MASK))
    return out


def test_scans_hide_the_labels_and_keep_every_measurement(train_obs):
    scans = train_obs.scans(seed=0)
    index = np.concatenate([s.index for s in scans])
    assert np.array_equal(np.sort(index), np.arange(len(train_obs)))
    for s in scans:
        assert np.array_equal(s.truth, train_obs.obj[s.index])
        assert np.array_equal(s.z, train_obs.z[s.index])
        assert np.all(train_obs.t[s.index] == s.t)
    # shuffled: the simulator orders a scan by object, the scans do not
    assert any(not np.all(np.diff(s.truth) > 0) for s in scans if s.truth.size > 2)
    assert {s.truth.size for s in scans} >= {5}


def test_a_train_is_tracked_one_track_per_object(train_obs):
    scans = train_obs.scans(seed=0)
    assoc = Associator(SKY_FILTER, NETWORK)
    outs = _feed(assoc, scans)
    confirmed = set(assoc.track_ids(TrackStatus.CONFIRMED))
    assert len(confirmed) == 5
    assert assoc.counts[TrackEvent.TRACK_INITIATED] == 5
    assert assoc.counts[TrackEvent.TRACK_CONFIRMED] == 5
    owner: dict[str, set[int]] = {}
    for s, o in zip(scans, outs, strict=True):
        assert set(o.fate.tolist()) <= {DetectionFate.TRACK, DetectionFate.TRACKLET,
                                        DetectionFate.NEW_TRACKLET}
        for i, obj in zip(o.ids, s.truth.tolist(), strict=True):
            owner.setdefault(i, set()).add(obj)
    # every track (and the tracklet it came from) holds one object's detections only
    assert all(len(v) == 1 for v in owner.values())
    assert sorted(next(iter(owner[i])) for i in confirmed) == list(range(5))
    assert len(_passes(scans)) >= 2  # the second pass went to the tracks of the first


def _first_pass_tracked(obs, config: AssociationConfig):
    """An associator that tracked the first pass (5 confirmed tracks), the scans, passes."""
    scans = obs.scans(seed=0)
    passes = _passes(scans)
    assoc = Associator(SKY_FILTER, NETWORK, config)
    _feed(assoc, [scans[i] for i in passes[0]])
    assert len(assoc.track_ids(TrackStatus.CONFIRMED)) == 5
    return assoc, scans, passes


def test_tracks_missing_their_passes_are_deleted(train_obs):
    assoc, scans, passes = _first_pass_tracked(
        train_obs, AssociationConfig(delete_after_missed_passes=1))
    _feed(assoc, [scans[i] for i in passes[1]], empty=True)  # the radar saw nothing
    _feed(assoc, [scans[passes[-1][-1]]], empty=True)  # a scan after: the pass has ended
    assert assoc.track_ids(TrackStatus.CONFIRMED) == []
    assert assoc.counts[TrackEvent.DELETED_MISSED_PASSES] == 5


def test_tracks_whose_covariance_outgrows_the_bound_are_deleted(train_obs):
    assoc, scans, passes = _first_pass_tracked(
        train_obs, AssociationConfig(max_position_sigma_km=5.0))
    s = scans[passes[0][-1]]
    _feed(assoc, [survey.Scan(s.t + 24 * 3600.0, s.sensor, s.z[:0], s.truth[:0],
                              s.index[:0])], empty=True)
    assert assoc.counts[TrackEvent.DELETED_COVARIANCE] == 5
    assert assoc.track_ids(TrackStatus.CONFIRMED) == []


def test_a_tentative_track_that_stops_being_seen_is_dropped(train_obs):
    scans = train_obs.scans(seed=0)
    first = _passes(scans)[0]
    assoc = Associator(SKY_FILTER, NETWORK)
    samples = SKY_FILTER.iod.iod_samples
    _feed(assoc, [scans[i] for i in first[:samples]])
    assert len(assoc.track_ids(TrackStatus.TENTATIVE)) == 5
    window = AssociationConfig().confirm_window
    _feed(assoc, [scans[i] for i in first[samples:samples + window]], empty=True)
    assert assoc.track_ids(TrackStatus.TENTATIVE) == []
    assert assoc.counts[TrackEvent.TENTATIVE_DROPPED] == 5
    assert assoc.counts[TrackEvent.TRACK_CONFIRMED] == 0
