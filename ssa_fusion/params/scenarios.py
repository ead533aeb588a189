"""What sensor_sim's parameters need of the simulator's scenarios, written out.

The ``scenario`` parameter names a paper orbit scenario (`sim.scenarios`) or a real-sky one
(`sim.sky`); its defaults of ``cadence``, ``gap_start``, ``gap_length`` and ``after_gap`` are
the scenario's. The parameters may not import the simulated world (test/test_layers.py), so
the names and these few numbers are written out here, as `defaults` writes out the default
scenario's estimator settings; test/params/test_scenarios.py checks them against `sim`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Timing:
    """A paper scenario's schedule, s: its cadence, tracking before the gap, gap, after it."""

    cadence_s: float
    track_s: float
    gap_s: float
    after_s: float


_ISS = Timing(cadence_s=30.0, track_s=55770.0, gap_s=5580.0, after_s=1800.0)
"""The ISS scenarios': every 30 s, a one-orbit gap after ten orbits of tracking."""

PAPER_SCENARIOS: dict[str, Timing] = {
    "iss_j2_pos": _ISS,
    "iss_drag_pos": _ISS,
    "iss_sgp4_pos": _ISS,
    "iss_sgp4_pos_nodrag": _ISS,
    "iss_j2_pos_noisy": _ISS,
    "iss_j2_rae": _ISS,
    "molniya_sdp4_pos": Timing(cadence_s=600.0, track_s=432000.0, gap_s=43200.0,
                               after_s=3600.0),
}
"""The paper's orbit scenarios (`sim.scenarios.SCENARIOS` whose ``is_orbit``), in its order."""

SKY_SCENARIOS: dict[str, float] = {
    "iss_radar_columbus": 60.0,
    "iss_network": 60.0,
    "iss_network_april": 60.0,
    "leo_optical": 60.0,
}
"""The real-sky scenarios (`sim.sky.SKY_SCENARIOS`) and their truth cadence, s."""

DEFAULT_LIVE = "iss_j2_rae"
"""The paper scenario whose gap a real-sky scenario's gap parameters default to
(`sim.scenarios.DEFAULT_LIVE`)."""

NAMES = (*PAPER_SCENARIOS, *SKY_SCENARIOS)
"""What the ``scenario`` parameter takes."""

TRUTHS = ("sgp4", "high_fidelity")
"""What the ``truth`` parameter takes (`sim.world.TruthModel`'s values)."""


def timing(name: str) -> Timing:
    """Return the paper scenario's timing of scenario `name` (a real-sky one: `DEFAULT_LIVE`'s).

    KeyError for a name not in `NAMES`.
    """
    return PAPER_SCENARIOS[DEFAULT_LIVE if name in SKY_SCENARIOS else name]


def cadence(name: str) -> float:
    """Return scenario `name`'s cadence, s (a real-sky one: of its truth samples)."""
    return SKY_SCENARIOS[name] if name in SKY_SCENARIOS else PAPER_SCENARIOS[name].cadence_s
