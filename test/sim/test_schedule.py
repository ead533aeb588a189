"""`sim.schedule`: what the simulator node publishes when, without ROS. The epochs withheld
are those of the outages, computed here by hand; the pace publishes each epoch once, in
order, and lockstep steps a catalog by `step_s` in windows computed ahead, or one object
from epoch to epoch with the releases its consumers want before each."""

import math
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.core.base import types
from ssa_fusion.formats.element_sets import read_catalog
from ssa_fusion.sim import scenarios, sky, survey
from ssa_fusion.sim.schedule import (
    RELEASE_MARGIN_S,
    CatalogPace,
    Event,
    ObjectStep,
    Pace,
    Phase,
    ScheduleError,
    SimSettings,
    check_window,
    plan,
    resolve,
)

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"


def _paper(**kw):
    base, real_sky = resolve("iss_j2_rae")
    settings = SimSettings(object_id="sat", cadence=30.0, gap_start=600.0, gap_length=300.0,
                           after_gap=300.0, noise_sigma=(0.0, 0.0, 0.0), **kw)
    return plan("iss_j2_rae", base, real_sky, settings)


def test_resolve_gives_the_paper_scenario_and_the_real_sky_one():
    assert resolve("molniya_sdp4_pos") == (scenarios.get("molniya_sdp4_pos"), None)
    base, real_sky = resolve("iss_network")
    assert base is scenarios.DEFAULT_LIVE and real_sky is sky.SKY_SCENARIOS["iss_network"]
    with pytest.raises(ValueError, match="unknown scenario"):
        resolve("no_such_scenario")


def test_a_paper_run_withholds_the_epochs_of_its_gap_and_has_the_truth_at_each():
    run = _paper()
    epochs = sorted({t for t, _, _ in run.schedule})
    t0 = epochs[0]
    assert np.allclose(np.diff(epochs), 30.0) and epochs[-1] - t0 == pytest.approx(1200.0)
    withheld = [t - t0 for t, what, _ in run.schedule if what == Event.WITHHELD]
    assert withheld == pytest.approx([600.0 + 30.0 * k for k in range(10)])  # [600, 900)
    truths = [t for t, what, _ in run.schedule if what == Event.TRUTH]
    assert truths == epochs
    for t, what, content in run.schedule:
        assert content.object_id == "sat" and content.t == t
        if what != Event.TRUTH:
            assert isinstance(content, types.Measurement) and content.frame_id == "columbus"
            assert not np.asarray(content.R).any()  # the noise given: none
    assert run.catalog is None and list(run.times) == [t for t, _, _ in run.schedule]
    assert run.summary == "41 epochs every 30.0 s, gaps [(600.0, 900.0)] s"


def test_a_paper_run_with_two_gaps_ends_after_the_last_one():
    run = _paper(gaps=(120.0, 60.0, 600.0, 90.0))
    t0 = run.times[0]
    withheld = [t - t0 for t, what, _ in run.schedule if what == Event.WITHHELD]
    assert withheld == pytest.approx([120.0, 150.0, 600.0, 630.0, 660.0])
    assert run.times[-1] - t0 == pytest.approx(690.0 + 300.0)


def test_a_catalog_run_gives_rows_of_its_measurements():
    base, real_sky = resolve("iss_radar_columbus")
    settings = SimSettings(object_id="", cadence=60.0, duration=6 * 3600.0, catalog=str(SAMPLE),
                           objects=3, seed=1)
    run = plan("iss_radar_columbus", base, real_sky, settings)
    whole = survey.observe_catalog(read_catalog(SAMPLE)[:3], real_sky.radars, run.times[0],
                                   6 * 3600.0, seed=1)
    assert run.schedule == [] and len(whole) > 0
    t0 = survey.catalog_start(read_catalog(SAMPLE)[:3])
    assert run.times.tolist() == [t0, t0 + 6 * 3600.0]
    obs = run.catalog.stream.until(whole.t[len(whole) // 2])
    assert 0 < len(obs) < len(whole) and np.array_equal(obs.z, whole.z[:len(obs)])
    keys = np.arange(len(obs.object_ids), dtype=np.uint32) + 7
    rows = run.catalog.rows(obs, keys)
    assert rows.object_id == [obs.object_ids[k] for k in obs.obj]
    assert set(rows.frame_id) == {"columbus"} and (rows.shard_key == obs.obj + 7).all()
    assert np.array_equal(rows.t, obs.t) and rows.R.shape == (len(obs), 3, 3)


def test_a_catalog_is_handed_out_in_lockstep_steps_computed_ahead():
    """The steps' windows join into the whole run's measurements, each within its step."""
    base, real_sky = resolve("iss_radar_columbus")
    settings = SimSettings(object_id="", cadence=60.0, duration=6 * 3600.0, catalog=str(SAMPLE),
                           objects=3, seed=1)
    run = plan("iss_radar_columbus", base, real_sky, settings)
    whole = survey.observe_catalog(read_catalog(SAMPLE)[:3], real_sky.radars, run.times[0],
                                   6 * 3600.0, seed=1)
    pace = CatalogPace(run.catalog, step_s=1800.0)
    windows = []
    while not pace.done:
        before = pace.sim_now
        w = pace.step(ceiling=math.inf)
        assert w is not None and ((w.t > before) & (w.t <= pace.sim_now)).all()
        windows.append(w)
    pace.close()
    assert len(windows) == 12 and pace.published == len(whole)
    assert np.array_equal(np.concatenate([w.z for w in windows]), whole.z)
    assert np.array_equal(np.concatenate([w.obj for w in windows]), whole.obj)


def test_settings_that_give_no_run_are_schedule_errors_naming_the_parameters():
    base, real_sky = resolve("leo_optical")
    with pytest.raises(ScheduleError, match="has no radar to observe a catalog"):
        plan("leo_optical", base, real_sky,
             SimSettings(object_id="", cadence=60.0, catalog=str(SAMPLE)))
    base, real_sky = resolve("iss_radar_columbus")
    with pytest.raises(ScheduleError, match="parameter 'catalog' = "):
        plan("iss_radar_columbus", base, real_sky,
             SimSettings(object_id="", cadence=60.0, catalog=str(SAMPLE.parent)))
    with pytest.raises(ScheduleError, match="parameters 'start', 'duration'"):
        check_window(4.0e9, 86400.0)


def test_the_open_loop_publishes_each_epoch_once_in_order():
    pace = Pace(np.array([0.0, 10.0, 20.0, 20.0, 30.0]))
    assert list(pace.due(-5.0)) == [] and list(pace.due(10.0)) == [0, 1]
    assert list(pace.due(5.0)) == []  # the clock never takes back what went out
    assert list(pace.due(25.0)) == [2, 3] and not pace.done
    assert list(pace.due(1e9)) == [4] and pace.done


def test_lockstep_steps_by_its_step_under_the_ceiling():
    pace = Pace(np.array([100.0, 110.0, 120.0, 130.0, 140.0]), step_s=15.0)
    assert pace.sim_now == 100.0 and not pace.clock_behind
    assert list(pace.step(ceiling=200.0)) == [0, 1] and pace.sim_now == 115.0
    assert pace.clock_behind
    pace.clock_behind = False  # the node published the step's clock
    assert pace.step(ceiling=120.0) is None and pace.sim_now == 115.0  # held by the ceiling
    assert list(pace.step(ceiling=200.0)) == [2, 3]
    assert list(pace.step(ceiling=200.0)) == [4] and pace.done


def test_one_objects_lockstep_releases_what_is_wanted_before_each_epoch():
    """Each epoch: the forecasts, then the decisions, of the epochs before it (only when a
    consumer has something due by then), then its clock, then its events; the releases up
    to the last epoch at the end."""
    pace = Pace(np.array([100.0, 130.0, 130.0, 160.0]))
    due: dict[Phase, float] = {Phase.FORECASTS: 120.0, Phase.DECISIONS: float("inf")}
    asked: list[tuple[Phase, float]] = []

    def wants(phase: Phase, t: float) -> bool:
        asked.append((phase, t))
        return due[phase] <= t

    def step(ceiling: float = 1e9) -> ObjectStep | None:
        return pace.object_step(ceiling, wants)

    before = 130.0 - RELEASE_MARGIN_S
    assert step() == ObjectStep(Phase.CLOCK, 100.0)  # nothing due before 100
    assert step() == ObjectStep(Phase.EVENTS, 100.0, range(0, 1))
    assert step(ceiling=120.0) == ObjectStep(Phase.FORECASTS, before)
    due[Phase.DECISIONS] = 125.0  # the filter, having fused those forecasts
    assert step(ceiling=120.0) == ObjectStep(Phase.DECISIONS, before)
    assert step(ceiling=120.0) is None  # 130 is past the ceiling
    assert step() == ObjectStep(Phase.CLOCK, 130.0)
    assert step() == ObjectStep(Phase.EVENTS, 130.0, range(1, 3))
    due.update({Phase.FORECASTS: float("inf"), Phase.DECISIONS: float("inf")})
    assert step() == ObjectStep(Phase.CLOCK, 160.0)
    assert step() == ObjectStep(Phase.EVENTS, 160.0, range(3, 4))
    assert not pace.object_done
    due[Phase.DECISIONS] = 160.0  # the end: up to the last epoch
    assert step() == ObjectStep(Phase.DECISIONS, 160.0)
    assert step() is None and pace.object_done
    assert asked[-2:] == [(Phase.FORECASTS, 160.0), (Phase.DECISIONS, 160.0)]
def _sky_truth(**kw: object) -> np.ndarray:
    base, real_sky = resolve("iss_radar_columbus")
    settings = SimSettings(object_id="sat", cadence=600.0, duration=6 * 3600.0, **kw)
    run = plan("iss_radar_columbus", base, real_sky, settings)
    return np.array([c.x for _, what, c in run.schedule if what == Event.TRUTH])


def test_a_real_sky_run_turns_its_orbit_for_a_geometry_seed_and_takes_its_truth():
    """``geometry_seed`` turns the object's orbit as the benchmarks' case of that seed
    (`sky.case_geometry`: the same plane and phase, from the same start), and ``truth``
    high_fidelity is the world's truth (`sky.truth` of that scenario): independent of the
    schedule, the expected states are computed from the scenario here."""
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_window(
        sky.SKY_SCENARIOS["iss_radar_columbus"].t0, 6 * 3600.0).with_(truth_cadence_s=600.0)
    t = s.t0 + 600.0 * np.arange(37)
    own = _sky_truth()
    assert np.allclose(own, sky.truth(s, t), atol=1e-9)
    turned = _sky_truth(geometry_seed=5)
    assert np.allclose(turned, sky.truth(s.with_geometry(*sky.case_geometry(5)), t), atol=1e-9)
    assert np.linalg.norm(turned[0, :3] - own[0, :3]) > 100.0  # another plane and phase
    hf = _sky_truth(truth="high_fidelity", seed=3)
    world = s.with_(truth=sky.TruthModel.HIGH_FIDELITY, world=s.world.with_(weather_seed=3))
    assert np.allclose(hf, sky.truth(world, t), atol=1e-9)
    assert np.linalg.norm(hf[-1, :3] - own[-1, :3]) > 0.1  # SGP4 is another orbit


def test_a_seeded_live_case_starts_later_on_an_orbit_of_its_own():
    """`sky.seeded_case` (what ``live --seed`` runs): the start moved by whole minutes within
    a day, the orbit turned as `case_geometry`, reproducibly, and another seed another case."""
    s = sky.SKY_SCENARIOS["iss_network"]
    a, b, again = sky.seeded_case(s, 11), sky.seeded_case(s, 12), sky.seeded_case(s, 11)
    assert a == again and a != b
    assert 0.0 <= a.t0 - s.t0 < 86400.0 and (a.t0 - s.t0) % 60.0 == 0.0
    assert a.x0 == s.with_geometry(*sky.case_geometry(11)).x0
    assert a.world.weather_seed == 11 and a.outages == s.outages
