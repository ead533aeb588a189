"""The encounter-plane pictures of a conjunction run's report (`apps.conjunction_plots`).

A bag holds one ConjunctionBatch of a known geometry: the secondary 200 m radial of the
primary, the relative velocity (0, -7.5, 7.5) km/s, so the plane's x axis is radial and its
z axis (0, -1, -1)/√2; each object's position covariance diag(a, b, b)/2, so the combined
one projected on (x, z) is diag(a, b) by hand (σx = 50 m, σz = 120 m). What is drawn must
be that: the ellipses' semi-axes numpy's sqrt-eigenvalues of diag(a, b) (×1, ×3) with the
long one along z, the miss arrow from the primary to (200 m, 0), the circle the hard-body
radius. A second approach, 10⁶ times the covariance, is drawn in km.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import conjunction_plots, conjunction_table, report_catalog, report_figures
from ssa_fusion.core.conjunction.close_approach import CloseApproaches
from ssa_fusion.core.conjunction.watch import WatchUpdate
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_CONJUNCTIONS

C = bagio.rosbags_classes()
T0 = 1.7536e9
SIGMA_X_KM, SIGMA_Z_KM = 0.05, 0.12
HBR_KM = 0.02
MISS_KM = 0.2
BIG = 1e6
"""The second approach's covariance over the first's (σ 50 km and 120 km: drawn in km)."""


def _bag(path: Path) -> Path:
    """One batch, two approaches of the known geometry (module docstring), Pc 1e-3, 1e-6."""
    x1 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])
    x2 = x1 + np.array([MISS_KM, 0.0, 0.0, 0.0, -7.5, 7.5])
    p = np.diag([SIGMA_X_KM ** 2 / 2, SIGMA_Z_KM ** 2 / 2, SIGMA_Z_KM ** 2 / 2,
                 1e-8, 1e-8, 1e-8])
    ps = np.stack([p, p * BIG])
    a = CloseApproaches(("1", "2", "3"), np.array([0, 0]), np.array([1, 2]),
                        np.array([T0 + 600.0, T0 + 900.0]), np.array([MISS_KM, MISS_KM]),
                        np.stack([x1, x1]), np.stack([x2, x2]), ps, ps.copy())
    up = WatchUpdate(["1", "2", "3"], a, np.array([-3.0, -6.0]), (T0, T0 + 86400.0), 5.0,
                     HBR_KM)
    w = bagio.BagWriter(path)
    w.add_topic(TOPIC_CONJUNCTIONS, bagio.CONJUNCTION_BATCH)
    w.write_msg(TOPIC_CONJUNCTIONS, int(T0 * 1e9),
                messages.conjunction_batch_to_msg(up, T0, classes=C))
    w.close()
    return path


@pytest.fixture
def drawn(monkeypatch):
    """The figures saved (by file name); each is written too."""
    figs = {}
    saved = report_figures.save

    def keep(fig, path, dpi=100):
        figs[Path(path).name] = fig
        saved(fig, path, dpi)

    monkeypatch.setattr(report_figures, "save", keep)
    return figs


def _by_gid(items, mark):
    found = [x for x in items if x.get_gid() == mark.value]
    assert len(found) == 1, mark
    return found[0]


def _semi_axes(line, centre):
    """(longest, shortest) distance of the drawn outline from `centre`, and the longest's
    point relative to it."""
    d = line.get_xydata() - np.asarray(centre)
    r = np.hypot(d[:, 0], d[:, 1])
    return r.max(), r.min(), d[np.argmax(r)]


@pytest.mark.parametrize(("rank", "scale", "unit"), [(1, 1e3, "m"), (2, 1.0, "km")])
def test_the_drawn_plane_is_the_known_geometry(tmp_path, drawn, rank, scale, unit):
    c = conjunction_table.latest(_bag(tmp_path / "bag"))
    paths = conjunction_plots.plot_approaches(c, tmp_path)
    assert [p.name for p in paths] == ["encounter_01_1_2.png", "encounter_02_1_3.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)
    ax = drawn[paths[rank - 1].name].get_axes()[0]
    cov = np.diag([SIGMA_X_KM ** 2, SIGMA_Z_KM ** 2]) * (1.0 if rank == 1 else BIG)
    minor, major = np.sqrt(np.linalg.eigvalsh(cov)) * scale  # ascending
    miss = np.array([MISS_KM * scale, 0.0])
    for k, mark in ((1.0, conjunction_plots.Mark.SIGMA_1), (3.0, conjunction_plots.Mark.SIGMA_3)):
        longest, shortest, tip = _semi_axes(_by_gid(ax.get_lines(), mark), miss)
        assert longest == pytest.approx(k * major, rel=1e-6)
        assert shortest == pytest.approx(k * minor, rel=1e-6)
        assert abs(tip[0]) < 1e-6 * longest  # the long axis is the plane's z
    arrow = _by_gid(ax.texts, conjunction_plots.Mark.MISS)
    np.testing.assert_allclose(arrow.xy, miss, atol=1e-9 * scale)
    np.testing.assert_allclose(arrow.xyann, [0.0, 0.0], atol=0.0)
    circle = _by_gid(ax.patches, conjunction_plots.Mark.HARD_BODY)
    assert circle.radius == pytest.approx(HBR_KM * scale, rel=1e-12)
    np.testing.assert_allclose(circle.center, [0.0, 0.0], atol=0.0)
    assert f"[{unit}]" in ax.get_xlabel() and "miss" in ax.get_xlabel()
    assert f"[{unit}]" in ax.get_ylabel() and "z" in ax.get_ylabel()
    title = ax.get_title()
    assert f"1 – {rank + 1}" in title and iso(T0 + 300.0 + 300.0 * rank) in title
    assert ("Pc 0.001" if rank == 1 else "Pc 1e-06") in title


def test_the_report_lists_the_pictures_and_what_it_left_out(tmp_path, drawn):
    bag = _bag(tmp_path / "bag")
    said, section = report_catalog.conjunctions(bag, tmp_path)
    names = ["encounter_01_1_2.png", "encounter_02_1_3.png"]
    assert "encounter planes of the 2 most likely approaches:" in said
    assert all(f"{tmp_path / n}" in said for n in names) and "left out" not in said
    assert all((tmp_path / n).is_file() for n in names) and set(drawn) == set(names)
    html = "\n".join(section)
    assert all(f'<img src="{n}"' in html for n in names) and "conjunctions.csv" in html
    c = conjunction_table.latest(bag)
    (tmp_path / "one").mkdir()
    one = conjunction_plots.plot_approaches(c, tmp_path / "one", drawn=1)
    assert [p.name for p in one] == names[:1]
    assert "(1 of the 2 listed left out)" in conjunction_plots.listing(c, one)
