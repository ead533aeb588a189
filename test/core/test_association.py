"""Association of unlabelled detections (`core.catalog.association`): gating and global nearest
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

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.catalog.association import (
    UNASSIGNED,
    AssociationConfig,
    ScanPrediction,
    assign,
    associate,
    gate_scan,
)
from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.earth.frames import razel_gcrs, site_gcrs
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.measure.measurement import RazelModel

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
from ssa_fusion.core.catalog.association import (  # noqa: E402
    Associator,
    DetectionFate,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.filter.options import SKY_FILTER  # noqa: E402
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


# ------------------------------------------------------------------------------------------
# Long-arc predictor and the groups' registration
# ------------------------------------------------------------------------------------------
from ssa_fusion.core.catalog.association import (  # noqa: E402
    Gated,
    gate_long_arc,
    linked_tracks,
    predict_scan,
    register,
)

AZ_RATE = 7.5 / 1000.0  # rad/s: 7.5 km/s across the line of sight at 1000 km
SIG_ALONG = 0.3 / 1000.0  # rad: a long-arc prediction's along-track 0.3 km at 1000 km
R_DET = np.diag([4e-4, 1e-10, 1e-10])  # 20 m, 10 urad


def _train_scan(spacing_km, shift_s: float, missing=()):
    """A train in measurement space: tracks in a row along azimuth, their detections all
    ``shift_s`` s ahead (a common along-track error), each with its own small noise.

    Returns the prediction (with ``zp_rate``) and the detections (truth: detection j is
    track ``truth[j]``)."""
    rng = np.random.default_rng(7)
    along = np.r_[0.0, np.cumsum(spacing_km)] / 1000.0  # rad behind the first
    n = along.size
    zp = np.stack([np.full(n, 1000.0), 1.0 - along, np.full(n, 0.5)], -1)
    HPHt = np.tile(np.diag([1e-4, SIG_ALONG**2, 1e-9]), (n, 1, 1))
    rate = np.tile([0.0, AZ_RATE, 0.0], (n, 1))
    truth = np.array([i for i in range(n) if i not in missing])
    z = zp[truth] + rate[truth] * shift_s + rng.normal(0, 1, (truth.size, 3)) * [
        0.02, 1e-5, 1e-5]
    pred = ScanPrediction(np.array([T0]), np.zeros(truth.size, np.int64), zp[None],
                          HPHt[None], np.ones((1, n), bool), np.zeros((1, n)), rate[None],
                          np.full((1, n), 7.5))
    return pred, z, np.tile(R_DET, (truth.size, 1, 1)), truth


def _wide_feasible(pred, z, R, sigma_km: float = 5.0):
    """The tracks' filter's gate: the same predictions with an along-track sigma_km."""
    wide = ScanPrediction(pred.epochs, pred.epoch_index, pred.zp,
                          np.tile(np.diag([1e-4, (sigma_km / 1000.0) ** 2, 1e-9]),
                                  (1, pred.zp.shape[1], 1, 1)),
                          pred.ok, pred.sigma_pos)
    return gate_scan(wide, z, R, GATE).feasible


def _shifted(pred, shift):
    """The prediction with each track moved by its shift (first order)."""
    return ScanPrediction(pred.epochs, pred.epoch_index,
                          pred.zp + pred.zp_rate * np.asarray(shift)[None, :, None], pred.HPHt,
                          pred.ok, pred.sigma_pos)


SPACING = [1.3, 4.1, 2.2, 3.7, 1.1, 2.9, 4.6, 1.8, 3.2]  # km, irregular


def test_registration_recovers_a_shifted_train_that_plain_gnn_shifts_by_one():
    # the head of the train not detected (at the edge of the view): as many pairs shifted
    # by one member as aligned
    shift = 0.45  # s: 3.4 km along track, more than most spacings
    pred, z, R, truth = _train_scan(SPACING, shift, missing=(0,))
    n = len(SPACING) + 1
    F = _wide_feasible(pred, z, R)
    assert F.sum() > 2 * truth.size  # the tracks' filter gates neighbours too
    fine = gate_scan(pred, z, R, GATE)
    plain = assign(fine.cost, F)
    assert (plain != truth).sum() >= 5  # the premise: GNN takes the neighbours' detections
    s = register(pred, z, R, F, GATE, np.full(n, 2.0))
    assert s == pytest.approx(np.full(n, shift), abs=0.01)
    g = gate_scan(_shifted(pred, s), z, R, GATE)
    assert assign(g.cost, F).tolist() == truth.tolist()


def test_registration_of_an_aligned_train_changes_nothing():
    pred, z, R, truth = _train_scan(SPACING, 0.0, missing=(0, 6))
    F = _wide_feasible(pred, z, R)
    fine = gate_scan(pred, z, R, GATE)
    before = assign(fine.cost, F)
    assert before.tolist() == truth.tolist()
    s = register(pred, z, R, F, GATE, np.full(len(SPACING) + 1, 2.0))
    assert np.abs(s).max() < 0.005  # s: under 40 m
    g = gate_scan(_shifted(pred, s), z, R, GATE)
    assert assign(g.cost, F).tolist() == before.tolist()


def _objective(pred, z, R, F, s: float, sigma: float) -> float:
    """Least assignment cost of the train shifted by s, plus the prior: by brute force."""
    g = gate_scan(_shifted(pred, np.full(pred.zp.shape[1], s)), z, R, GATE)
    best = _brute_force(np.where(F, g.cost, np.inf), F)
    return sum(g.cost[i, j] for j, i in enumerate(best) if i >= 0) + (s / sigma) ** 2


def test_registration_shift_is_the_least_objective_on_a_grid():
    # an independent search: the objective (best assignment's cost + prior) on a fine grid
    spacing = [2.1, 3.9, 1.4, 4.4]
    pred, z, R, _ = _train_scan(spacing, -0.33, missing=(2,))
    F = _wide_feasible(pred, z, R)
    sigma = 1.0
    s = register(pred, z, R, F, GATE, np.full(len(spacing) + 1, sigma))
    grid = np.arange(-1.0, 1.0, 0.002)
    values = [_objective(pred, z, R, F, float(g), sigma) for g in grid]
    best = float(grid[int(np.argmin(values))])
    assert s[0] == pytest.approx(best, abs=0.004)
    assert _objective(pred, z, R, F, float(s[0]), sigma) <= min(values) + 1e-6


def test_groups_get_their_own_shifts_and_a_lone_track_none():
    a, za, Ra, _ = _train_scan(SPACING[:4], 0.4)
    b, zb, Rb, _ = _train_scan(SPACING[4:], -0.3)
    # the second train 0.5 rad away in azimuth; a lone track 1 rad away, no detection
    n_a, n_b = a.zp.shape[1], b.zp.shape[1]
    lone = np.array([[1000.0, 2.5, 0.5]])
    zp = np.concatenate([a.zp[0], b.zp[0] + np.array([0.0, -0.5, 0.0]), lone])
    n = zp.shape[0]
    pred = ScanPrediction(a.epochs, np.zeros(za.shape[0] + zb.shape[0], np.int64), zp[None],
                          np.tile(a.HPHt[0, :1], (1, n, 1, 1)), np.ones((1, n), bool),
                          np.zeros((1, n)), np.tile(a.zp_rate[0, :1], (1, n, 1)),
                          np.full((1, n), 7.5))
    z = np.concatenate([za, zb + np.array([0.0, -0.5, 0.0])])
    R = np.concatenate([Ra, Rb])
    F = _wide_feasible(pred, z, R)
    assert not F[:n_a, za.shape[0]:].any() and not F[n_a:, :za.shape[0]].any()
    s = register(pred, z, R, F, GATE, np.full(n, 2.0))
    assert s[:n_a] == pytest.approx(np.full(n_a, 0.4), abs=0.01)
    assert s[n_a:n_a + n_b] == pytest.approx(np.full(n_b, -0.3), abs=0.01)
    assert s[-1] == 0.0


def test_register_needs_the_rate():
    pred = _prediction(np.array([[1000.0, 1.0, 0.5]] * 2), np.tile(R1, (2, 1, 1)))
    with pytest.raises(ValueError, match="zp_rate"):
        register(pred, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((2, 0), bool), GATE,
                 np.ones(2))


def test_predicted_measurement_rate_is_the_along_track_derivative():
    # zp_rate against the exact prediction of the track a little further along its orbit
    rng = np.random.default_rng(5)
    ekf = BatchEKF(SKY_FILTER, [RADAR.station])
    x = _visible_states(3, T0, rng)
    P = np.tile(np.eye(6) * 1e-6, (3, 1, 1))
    t = T0 + 30.0
    pred = predict_scan(ekf, x, P, np.full(3, T0), t, 0)
    h = 0.2  # s; central difference
    ahead, behind = (predict_scan(ekf, x, P, np.full(3, T0 - d), t, 0) for d in (h, -h))
    dz = ahead.zp[0] - behind.zp[0]
    dz[:, 1:] = (dz[:, 1:] + math.pi) % (2 * math.pi) - math.pi
    assert dz / (2 * h) == pytest.approx(pred.zp_rate[0], rel=1e-4, abs=1e-12)
    assert pred.speed[0] == pytest.approx(np.linalg.norm(
        ekf.predict(x, P, 30.0, T0).x[:, 3:], axis=-1), rel=1e-12)


def test_long_arc_rescoring_keeps_the_wide_gate_and_takes_the_fine_cost():
    inf = math.inf
    wide = Gated(np.array([[1.0, 30.0], [2.0, 3.0]]), np.array([[5.0, 34.0], [6.0, 7.0]]),
                 np.array([[True, False], [True, True]]))
    fine = Gated(np.array([[50.0, inf]]), np.array([[52.0, inf]]), np.array([[False, False]]))
    out = gate_long_arc(wide, fine, np.array([1]))
    assert out.feasible.tolist() == wide.feasible.tolist()
    assert out.cost.tolist() == [[5.0, 34.0], [52.0, 7.0]]
    assert out.d2.tolist() == [[1.0, 30.0], [50.0, 3.0]]


def test_config_refuses_a_negative_predictor_q():
    with pytest.raises(ValueError, match="predictor_q"):
        AssociationConfig(predictor_q=-1e-17)
    assert AssociationConfig(predictor_q=None).predictor_q is None


def _accuracy(scans, outs, assoc) -> float:
    """Of the detections fused into confirmed tracks, the fraction of the track's object."""
    confirmed = set(assoc.track_ids(TrackStatus.CONFIRMED))
    pairs = [(i, o) for s, out in zip(scans, outs, strict=True)
             for i, o, f in zip(out.ids, s.truth.tolist(), out.fate.tolist(), strict=True)
             if i in confirmed and f == DetectionFate.TRACK]
    owner = {i: max(set(v), key=v.count) for i in confirmed
             if (v := [o for j, o in pairs if j == i])}
    return sum(owner[i] == o for i, o in pairs) / len(pairs)


@pytest.fixture(scope="module")
def long_gap_train():
    """A train of 12 objects 1-5 km apart over the radar for 24 h: six passes 1.5 h apart,
    then one after a 14 h gap (the case docs/ASSOCIATION.md describes)."""
    cat = survey.satellite_train(RADAR.station, T0 + 600.0, 12, seed=2)
    return survey.observe_catalog(cat, [RADAR], T0, 24 * 3600.0, seed=2).scans(seed=2)


def test_a_train_after_a_long_gap_keeps_its_tracks(long_gap_train):
    scans = long_gap_train
    gaps = np.diff([s.t for s in scans])
    assert gaps.max() > 10 * 3600.0  # the case has its long gap
    runs = {}
    for name, cfg in (("plain", AssociationConfig(predictor_q=None, register_groups=False)),
                      ("default", AssociationConfig())):
        assoc = Associator(SKY_FILTER, NETWORK, cfg)
        runs[name] = _accuracy(scans, _feed(assoc, scans), assoc)
        assert len(assoc.track_ids(TrackStatus.CONFIRMED)) == 12
    assert runs["plain"] < 0.95  # the premise: GNN on the tracks' filter shifts the train
    assert runs["default"] == 1.0


def test_a_train_registered_in_pieces_misplaces_its_end_and_linked_whole_does_not():
    # predictions 1.5 km ahead of their objects; a 6 km gap splits the gates in two, and
    # the tail has one detection (the rest not yet in view): alone, the tail aligns its
    # detection with the nearest track (the next one back, 0.15 km off)
    spacing = [1.4, 2.0, 6.0, 1.65, 3.4]
    n = len(spacing) + 1
    pred, z, R, truth = _train_scan(spacing, -0.2, missing=(4, 5))
    F = _wide_feasible(pred, z, R, sigma_km=0.75)
    assert not F[:3, 3].any() and not F[3:, :3].any()  # two pieces
    sig = np.full(n, 2.0)
    pieces = register(pred, z, R, F, GATE, sig)
    g = gate_scan(_shifted(pred, pieces), z, R, GATE)
    assert assign(g.cost, F)[3] == 4  # the premise: the tail's detection on the wrong track
    whole = register(pred, z, R, F, GATE, sig, linked=np.ones((n, n), bool))
    assert whole == pytest.approx(np.full(n, -0.2), abs=0.01)
    g = gate_scan(_shifted(pred, whole), z, R, GATE)
    assert assign(g.cost, F).tolist() == truth.tolist()


def test_tracks_on_one_orbit_close_together_are_linked_crossing_or_far_ones_not():
    # range 1000 km, elevation 0: 1 mrad of azimuth is 1 km; rates as km/s across
    zp = np.array([[1000.0, 1.000, 0.0], [1000.0, 1.003, 0.0], [1000.0, 1.001, 0.0],
                   [1000.0, 1.020, 0.0]])
    rate = np.array([[0.0, 7.5e-3, 0.0], [0.0, 7.5e-3, 0.0], [0.0, 2.6e-3, 7.0e-3],
                     [0.0, 7.5e-3, 0.0]])
    n = zp.shape[0]
    fine = ScanPrediction(np.array([T0]), np.zeros(0, np.int64), zp[None],
                          np.tile(np.eye(3) * 1e-8, (1, n, 1, 1)), np.ones((1, n), bool),
                          np.zeros((1, n)), rate[None], np.full((1, n), 7.5))
    cfg = AssociationConfig()
    near = linked_tracks(fine, fine, np.arange(n), cfg.group_link_km,
                         cfg.group_link_speed_fraction)
    # 0-1: 3 km, one velocity; 0-2: 1 km but crossing (~70 deg); 0-3: 20 km
    assert near.tolist() == [[True, True, False, False], [True, True, False, False],
                             [False, False, True, False], [False, False, False, True]]


def test_chi2_quantile_is_scipy_stats_chi2_ppf_bit_for_bit_and_analytic_at_two_dof():
    """`chi2_quantile` (scipy.special only) against scipy.stats' own chi-square quantile,
    float for float, and at 2 degrees of freedom against the closed form -2 ln(1 - p)."""
    from scipy.stats import chi2

    from ssa_fusion.core.catalog.association import MEASUREMENT_DOF, chi2_quantile

    probabilities = (1e-9, 0.01, 0.5, 0.9, 0.95, 0.99, 0.9973, 0.9999, 1 - 1e-9)
    for dof in (1, 2, MEASUREMENT_DOF, 6):
        for p in probabilities:
            assert chi2_quantile(p, dof) == float(chi2.ppf(p, dof)), (p, dof)
    for p in probabilities:
        assert chi2_quantile(p, 2) == pytest.approx(-2.0 * math.log1p(-p), rel=1e-12)
    assert chi2_quantile(AssociationConfig().gate_probability, MEASUREMENT_DOF) == GATE
