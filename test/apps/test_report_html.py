"""report.html: `ssa-fusion report` writes one self-contained page beside
its PNGs, and it renders in a real browser: headless Chromium (Debian's `chromium`; .ci/run
installs it) draws every plot, shows no error, and its screenshot is not blank.

Chromium opens the page over file:// only, with its background networking off: the page
itself must need no network (plotly.js is inlined).
"""

from __future__ import annotations

import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from test_evaluate import synthetic  # the synthetic BagData helper (test/apps on sys.path)

from ssa_fusion.apps import evaluate, report, report_html
from ssa_fusion.evaluation.arms import ArmName
from ssa_fusion.evaluation.passes import PassReport

ROOT = Path(__file__).resolve().parents[2]
SAMPLE_BAG = ROOT / "bags" / "sample_iss_j2_rae"
SAMPLE_FIGURES = 6
"""orbit 3D, ground track with station masks, per-arm error ±3σ, forecasts vs withheld,
NEES, NIS."""
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--disable-extensions",
                  "--host-resolver-rules=MAP * ~NOTFOUND", "--window-size=1400,2000")
"""No network (file:// only; any host name fails to resolve), software WebGL for the 3D
plot (--enable-unsafe-swiftshader: the page is our own, trusted content)."""


class _Page(HTMLParser):
    """What a browser DOM holds: classes of every div and svg, the visible text (outside
    script and style), and the rows of each table."""

    def __init__(self) -> None:
        super().__init__()
        self.div_classes: list[list[str]] = []
        self.svg_classes: list[list[str]] = []
        self.text: list[str] = []
        self.tables: list[int] = []
        self._skip = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        classes = (dict(attrs).get("class") or "").split()
        if tag == "div":
            self.div_classes.append(classes)
        elif tag == "svg":
            self.svg_classes.append(classes)
        elif tag in ("script", "style"):
            self._skip += 1
        elif tag == "table":
            self.tables.append(0)
        elif tag == "tr" and self.tables:
            self.tables[-1] += 1

    def handle_endtag(self, tag: str) -> None:
        if tag in ("script", "style"):
            self._skip -= 1

    def handle_data(self, data: str) -> None:
        if not self._skip and data.strip():
            self.text.append(data.strip())


def _chromium(page: Path, screenshot: Path, work: Path) -> str:
    """Open `page` in headless Chromium (`CHROMIUM_FLAGS`, a fresh profile in `work`),
    save a screenshot of its first 1400 x 2000 px and return its DOM after load."""
    work.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["chromium", *CHROMIUM_FLAGS, f"--user-data-dir={work / 'profile'}",
                           f"--screenshot={screenshot}", "--dump-dom", page.as_uri()],
                          cwd=work, capture_output=True, timeout=60,
                          env={"HOME": str(work), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    return done.stdout.decode()


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[evaluate.BagData,
                                                              evaluate.Evaluation, Path]:
    """The sample bag's report directory (report.json, PNGs, report.html)."""
    data = evaluate.load(SAMPLE_BAG)
    ev = evaluate.evaluate(data)
    out = tmp_path_factory.mktemp("report") / "sample_report"
    report.write(data, ev, out)
    return data, ev, out


@pytest.fixture(scope="module")
def rendered(request: pytest.FixtureRequest,
             tmp_path_factory: pytest.TempPathFactory) -> tuple[_Page, Path]:
    """The page as headless Chromium rendered it: its DOM (parsed) and a screenshot."""
    if shutil.which("chromium") is None:
        pytest.skip("chromium is not on PATH (Debian: apt-get install chromium; .ci/run "
                    "installs it)")
    sample = request.getfixturevalue("sample")
    work = tmp_path_factory.mktemp("chromium")
    shot = work / "screenshot.png"
    dom = _chromium(sample[2] / "report.html", shot, work)  # ~5 s, mostly start-up
    parsed = _Page()
    parsed.feed(dom)
    return parsed, shot


def test_report_writes_the_page_beside_its_pngs_and_it_needs_no_network(sample):
    out = sample[2]
    assert {p.name for p in out.iterdir()} >= {"report.json", "report.html", "arms.png",
                                               "forecast_vs_withheld.png"}
    text = (out / "report.html").read_text(encoding="utf-8")
    assert "<script src=" not in text  # plotly.js inlined, nothing fetched
    assert text.count("Plotly.newPlot") == SAMPLE_FIGURES


def test_chromium_draws_every_plot_and_the_table_without_errors(rendered, sample):
    page, _ = rendered
    plots = [c for c in page.div_classes if "plotly-graph-div" in c]
    assert len(plots) == SAMPLE_FIGURES
    assert all("js-plotly-plot" in c for c in plots)  # Plotly.newPlot ran on each
    # each 2D figure's SVG was drawn (the 3D one draws on a WebGL canvas, plus its SVG)
    assert sum("main-svg" in c for c in page.svg_classes) >= SAMPLE_FIGURES
    arms = len(sample[1].gap.arms)
    assert page.tables == [arms + 1]  # header + one row per arm; no per-pass table
    text = " ".join(page.text)
    assert "Error" not in text and "error while" not in text.lower()
    assert "WebGL is not supported" not in text
    assert not any("render-error" in c for c in page.div_classes)
    # axes labelled with units (SVG text of the 2D figures)
    for label in ("longitude [deg]", "latitude [deg]", "hours into the gap [h]", "error [km]",
                  "range [km]", "azimuth [rad]", "elevation [rad]", "NEES [-]", "NIS [-]",
                  "95 % χ² band"):
        assert label in text, label
    for arm in ArmName:
        assert str(arm) in text


def test_the_screenshot_shows_plots_not_a_blank_page(rendered):
    import matplotlib.image

    _, shot = rendered
    img = matplotlib.image.imread(shot)  # (rows, cols, RGB[A]) in [0, 1]
    assert img.shape[:2] == (2000, 1400)
    rgb = img[..., :3]
    assert rgb.std() > 0.05  # a blank page: 0
    not_white = np.any(rgb < 0.95, axis=2)
    assert not_white.mean() > 0.05  # text, table, Earth, orbit, error curves
    colored = np.ptp(rgb, axis=2) > 0.1  # not a grey: the Earth, the orbit, the curves
    assert colored[:350].mean() < 0.01  # title and table: black on white
    assert colored[450:1000, 300:1000].mean() > 0.1  # the 3D orbit (drawn with WebGL)
    assert colored[1050:].mean() > 0.01  # the per-arm error curves below it


def test_a_real_sky_evaluation_gets_the_per_pass_table(sample):
    data, ev, _ = sample
    passes = PassReport(passes=[(3600.0, "radar_a", 12, 0.25, 0.4),
                                    (9000.0, "radar_a,optical_b", 30, 0.12, 0.2)],
                            t_start=0.0, t=np.array([0.0, 60.0]),
                            pos_err_km=np.array([0.3, 0.2]), nees=np.array([5.0, 7.0]),
                            nees_band=(1.24, 14.45), gaps_h=np.array([1.5]))
    html = report_html.build(data, evaluate.Evaluation(ev.gap, ev.settings, passes))
    page = _Page()
    page.feed(html)
    text = " ".join(page.text)
    assert "After each pass" in text and "radar_a,optical_b" in text
    assert "position error after the pass [km]" in text
    assert page.tables == [len(ev.gap.arms) + 1, 3]


def test_a_position_bag_without_forecasts_gets_the_other_figures():
    data = synthetic()
    html = report_html.build(data, evaluate.evaluate(data))
    # orbit, ground track, errors, NEES: no forecasts, and its estimates carry no NIS (all 0)
    assert html.count("Plotly.newPlot") == 4
    assert "x GCRF [km]" in html and "NEES [-]" in html


def test_the_visibility_circle_is_at_the_masks_central_angle_from_the_station():
    from ssa_fusion.core.base.constants import R_EARTH
    from ssa_fusion.core.earth.frames import COLUMBUS

    h, el = 420.0, np.radians(10.0)
    lam = report_html.visibility_central_angle(h, el)
    # analytic: the triangle Earth centre - station - object, with the angle 90° + el at the
    # station, R opposite the object's angle and R + h opposite it (law of sines)
    nadir = np.arcsin(R_EARTH * np.cos(el) / (R_EARTH + h))
    assert lam == pytest.approx(np.pi / 2 - el - nadir, abs=1e-12)
    assert np.degrees(lam) == pytest.approx(12.5, abs=0.1)  # the ISS above 10°: ~1390 km
    lat, lon = report_html.small_circle(COLUMBUS.lat_rad, COLUMBUS.lon_rad, lam)
    # every point of the circle is at central angle λ from the station (haversine)
    lat0, lon0 = COLUMBUS.lat_rad, COLUMBUS.lon_rad
    d = 2 * np.arcsin(np.sqrt(np.sin((lat - lat0) / 2) ** 2
                              + np.cos(lat) * np.cos(lat0) * np.sin((lon - lon0) / 2) ** 2))
    assert np.allclose(d, lam, atol=1e-12)
    # and from its northernmost point the object at h is seen exactly at the mask elevation
    r_sat = (R_EARTH + h) * np.array([np.cos(lat[0]) * np.cos(lon[0]),
                                      np.cos(lat[0]) * np.sin(lon[0]), np.sin(lat[0])])
    r_st = R_EARTH * np.array([np.cos(COLUMBUS.lat_rad) * np.cos(COLUMBUS.lon_rad),
                               np.cos(COLUMBUS.lat_rad) * np.sin(COLUMBUS.lon_rad),
                               np.sin(COLUMBUS.lat_rad)])
    los = r_sat - r_st
    assert np.arcsin(los @ r_st / (np.linalg.norm(los) * R_EARTH)) == pytest.approx(el, abs=1e-9)
    assert lat[0] == pytest.approx(COLUMBUS.lat_rad + lam, abs=1e-12)  # bearing 0: north


def test_the_ground_track_draws_each_network_station_with_its_mask():
    from ssa_fusion.sim.sky import SKY_SCENARIOS

    net = report_html.run_stations(SKY_SCENARIOS["iss_network"].estimator())
    masks = {s.name: m for s, m in net}
    assert masks == {"millstone": 5.0, "tira": 10.0, "altair": 5.0, "socorro": 20.0,
                     "maui": 20.0, "diego_garcia": 20.0}
    assert [m for _, m in report_html.run_stations(
        SKY_SCENARIOS["iss_radar_columbus"].estimator())] == [10.0]
    data = evaluate.load(SAMPLE_BAG)
    fig = report_html.ground_track(data, net)
    names = " ".join(str(t.name) for t in fig.data)
    assert "tira: above its 10° mask" in names and "socorro: above its 20° mask" in names
    assert fig.layout.xaxis.title.text == "longitude [deg]"
    assert fig.layout.yaxis.title.text == "latitude [deg]"
