"""Parameter tables: each node declares its ROS parameters once, as rows of a table.

A row (`Param`) holds a parameter's name, default, unit, rule (`Check`: bounds, choices),
whether it can be set at run time, and its description; a table (`ParameterTable`) holds
a node's rows and the rules over several of them (`Rule`). `node_parameters.NodeParameters`
declares a table on a node, refuses an invalid value at start-up (`ParameterError`, which
the node's process reports as ``error: parameter '<name>' …`` with exit code 2) and on
every later ``ros2 param set``, and keeps the values in effect. ``docs/NODES.md``'s
parameter tables are generated from the same rows (`ssa_fusion.nodes.parameter_doc`). No
rclpy here: the tables can be read without ROS.

Values are in the parameters' units (SI: m, m/s, rad, s); `ssa_fusion.nodes.settings` is
the one translation to the core's (km, km/s).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

from ssa_fusion.core.base.types import KIND_NAMES
from ssa_fusion.core.earth.stations import network_stations, station_ids
from ssa_fusion.formats.sites import load_station_map, load_stations
from ssa_fusion.nodes.defaults import CatalogFilterDefaults, FilterDefaults

ParamValue = bool | int | float | str | list[bool] | list[int] | list[float] | list[str]
"""What a ROS parameter of these nodes holds."""
Default = ParamValue | tuple[float, ...] | tuple[str, ...]
"""A default as `ssa_fusion.nodes.defaults` writes it (tuples for arrays: frozen)."""
Values = Mapping[str, ParamValue]
"""Parameter values by name."""


class ParameterError(ValueError):
    """A parameter value is invalid; the message names the parameter and the rule."""


@dataclass(frozen=True)
class Check:
    """A rule one parameter's value must follow.

    Attributes
    ----------
    text : str
        The rule as the docs state it (``> 0``, ``3..1000``, ...).
    test : callable
        ``test(value)``: None when the value follows the rule, else the reason it does not.
    """

    text: str
    test: Callable[[ParamValue], str | None]

    def __call__(self, value: ParamValue) -> str | None:
        """Return None when `value` follows the rule, else the reason."""
        return self.test(value)


def _finite(value: object) -> float | None:
    """Return an int or a finite float as a float, anything else as None."""
    try:
        if isinstance(value, int | float) and math.isfinite(value):
            return float(value)
    except OverflowError:  # an int beyond a float's range (a params file's YAML)
        pass
    return None


def _positive(value: ParamValue) -> str | None:
    v = _finite(value)
    return None if v is not None and v > 0 else "must be a finite number > 0"


def _non_negative(value: ParamValue) -> str | None:
    v = _finite(value)
    return None if v is not None and v >= 0 else "must be a finite number >= 0"


POSITIVE = Check("> 0", _positive)
"""A finite number > 0."""
NON_NEGATIVE = Check("≥ 0", _non_negative)
"""A finite number >= 0."""


def all_non_negative(values: ParamValue) -> bool:
    """Return True when every element is a finite number >= 0.

    (``min(values) >= 0`` lets a NaN through unless it comes first.)
    """
    return isinstance(values, list) and all(_non_negative(v) is None for v in values)


def at_least(low: int) -> Check:
    """Return the check of an integer >= `low`."""
    def test(v: ParamValue) -> str | None:
        return None if isinstance(v, int) and v >= low else f"must be an integer >= {low}"

    return Check(f"integer ≥ {low}", test)


def integer_in(low: int, high: int) -> Check:
    """Return the check of an integer in `low`..`high`."""
    def test(v: ParamValue) -> str | None:
        ok = isinstance(v, int) and low <= v <= high
        return None if ok else f"must be an integer in {low}..{high}"

    return Check(f"{low}..{high}", test)


def one_of(*choices: str) -> Check:
    """Return the check of one of the strings `choices`."""
    def test(v: ParamValue) -> str | None:
        return None if v in choices else f"must be one of {', '.join(choices)}"

    return Check(", ".join(f"`{c}`" for c in choices), test)


def non_negative_numbers(count: int, reason: str) -> Check:
    """Return the check of a list of `count` finite numbers >= 0 (`reason` when not)."""
    def test(v: ParamValue) -> str | None:
        return None if isinstance(v, list) and len(v) == count and all_non_negative(v) else reason

    return Check(f"{count} values, each ≥ 0", test)


def read_by(read: Callable[[str], object],
            empty_ok: bool = False) -> Callable[[ParamValue], str | None]:
    """Return a check that passes a value `read` takes, else gives `read`'s ValueError.

    `empty_ok`: '' passes unread (a parameter whose '' means "none").
    """
    def check(value: ParamValue) -> str | None:
        if empty_ok and value == "":
            return None
        if not isinstance(value, str):  # a params file's YAML: its str() may be enormous
            return f"must be a string, got {type(value).__name__}"
        try:
            read(value)
        except ValueError as exc:
            return str(exc)
        return None

    return check


STATIONS = Check("a station id, a network id, or station ids separated by commas",
                 read_by(network_stations))
"""Stations (`core.earth.stations.network_stations`): a station, a network, or ids with commas."""


def _station_ids(value: ParamValue) -> str | None:
    ok = isinstance(value, str) and station_ids(value)
    return None if ok else "must name a station, a network, or station ids separated by commas"


STATION_IDS = Check("a station id (built in, or of `sites`), a network id, or station ids "
                    "separated by commas", _station_ids)
"""Station ids, built in or of a sites file: whether they are known is the rule over
``station`` and ``sites`` (`sites_problem`)."""


SITES = Check("'' or a readable, valid sites file", read_by(load_stations))
"""A sites file (`formats.sites`), or '' for the built-in stations only."""


def sites_problem(values: Values) -> str | None:
    """Return why ``station`` names a station neither built in nor in ``sites``, or None."""
    try:
        network_stations(str(values["station"]), load_station_map(str(values["sites"])))
    except ValueError as exc:
        return str(exc)
    return None


@dataclass(frozen=True)
class Computed:
    """A default computed when the node starts from the parameters declared before it.

    Attributes
    ----------
    compute : callable
        ``compute(values)``: the default, from the values of the parameters declared earlier.
    text : str
        What the docs say the default is.
    example : ParamValue
        The default of a node started with every parameter at its default (it gives the
        docs the parameter's type).
    """

    compute: Callable[[Values], ParamValue]
    text: str
    example: ParamValue


@dataclass(frozen=True)
class Param:
    """One ROS parameter of a node: a row of its `ParameterTable`.

    Attributes
    ----------
    name : str
        The parameter's name.
    default : value or Computed
        Its default (which also fixes its ROS type).
    description : str
        What it means (``ros2 param describe`` and docs/NODES.md print it).
    unit : str
        Its unit ("–" for none).
    check : Check or None
        The rule its value must follow (None: any value of its type).
    runtime : bool
        True when ``ros2 param set`` may change it while the node runs; else it is
        read-only once the node has started.
    """

    name: str
    default: Default | Computed
    description: str
    unit: str = "–"
    check: Check | None = None
    runtime: bool = False

    def reason(self, value: ParamValue) -> str | None:
        """Return None when `value` is valid for this parameter, else the reason."""
        return self.check(value) if self.check is not None else None


@dataclass(frozen=True)
class Rule:
    """A rule over several parameters, checked at start-up and on every run-time set.

    Attributes
    ----------
    names : tuple of str
        The parameters it reads (an error at start-up names the first).
    test : callable
        ``test(values)``: None when the values of `names` go together, else the reason.
    """

    names: tuple[str, ...]
    test: Callable[[Values], str | None]


@dataclass(frozen=True)
class ParameterTable:
    """Every parameter of node `node`, and the rules between them.

    `params` are declared in their order (a `Computed` default reads earlier ones); `rules`
    read several of them.
    """

    node: str
    params: tuple[Param, ...]
    rules: tuple[Rule, ...] = ()

    def __post_init__(self) -> None:
        """Check that names are unique and that every rule reads declared parameters."""
        names = [p.name for p in self.params]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.node}: a parameter is declared twice: {names}")
        for rule in self.rules:
            if not set(rule.names) <= set(names):
                raise ValueError(f"{self.node}: a rule reads undeclared {rule.names}")

    def __iter__(self) -> Iterator[Param]:
        """Iterate over the rows in declaration order."""
        return iter(self.params)

    def __getitem__(self, name: str) -> Param:
        """Return the row of parameter `name` (KeyError if the node has none)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def names(self) -> tuple[str, ...]:
        """Return the parameters' names in declaration order."""
        return tuple(p.name for p in self.params)


# rows several nodes share ----------------------------------------------------------------
def clock_lead(default: float) -> Param:
    """Return the row of ``max_clock_lead`` (s), which every node judging stamps has."""
    return Param("max_clock_lead", default,
                 "a measurement stamped further ahead of the node's clock is refused "
                 "(`rejected_future`): a wall-time stamp in a sim-time graph",
                 unit="s", check=POSITIVE, runtime=True)


def object_filter(default: str, what: str) -> Param:
    """Return the row of ``object_id``: the node `what`s only this object ('' = any)."""
    return Param("object_id", default, f"{what} only this object; `\"\"` = any")


KINDS = {name: kind for kind, name in KIND_NAMES.items()}
"""The `kind` parameter's values: measurement kind by name."""


def measurement_stream(kind: str, station: str, sites: str,
                       verb: str) -> tuple[Param, Param, Param]:
    """Return the rows of ``kind``, ``station`` and ``sites``: the measurements a node `verb`s.

    The station is the frame_id of range/az/el and ra/dec measurements ("gcrf" for
    positions, whatever the parameter says); it names built-in stations or those of the
    sites file ``sites`` (the table's rule `sites_problem` checks which).
    """
    return (Param("kind", kind, f"measurement kind it {verb} (sets the measurement model)",
                  check=one_of(*KINDS)),
            Param("station", station,
                  "station (frame_id) of range/az/el or ra/dec measurements "
                  "(`ssa_fusion.core.earth.stations.STATIONS`, or a site of `sites`), or a "
                  "network: a `NETWORKS` id or station ids separated by commas (`columbus,` "
                  "for a network of one), whose radar and optical measurements it takes, "
                  "each with its station's model; ignored for position (frame `gcrf`)",
                  check=STATION_IDS),
            sites_row(sites))


def sites_row(default: str) -> Param:
    """Return the row of ``sites``: a sites file whose ids ``station`` may name too."""
    return Param("sites", default,
                 "sites file (YAML, docs/SITES.md: latitude, longitude, height, sensor "
                 "type, noise, cadence, mask of each station of one's own) whose ids "
                 "`station` may name besides the built-in ones; `\"\"` = built-in stations "
                 "only", unit="path", check=SITES)


STATION_RULE_NAMES = ("station", "sites")
"""The parameters `sites_problem` reads (a rule of every table with `measurement_stream`)."""


P0_SIGMA = non_negative_numbers(6, "needs 6 standard deviations, each a finite number >= 0")
"""The check of ``p0_sigma``: 3 position and 3 velocity standard deviations."""
MAX_IOD_SAMPLES = 1000
"""Most measurements one IOD batch may take (a pass of 10 s samples has at most ~100)."""
MOTION_MODELS = one_of("kepler", "j2")
"""The motion models a filter node offers (Earth orbits on the Unix clock)."""


def filter_rows(d: FilterDefaults | CatalogFilterDefaults, runtime: bool,
                unlimited_span: bool) -> tuple[Param, ...]:
    """Return the rows of a filter's settings (the object filter's and the catalog's).

    Defaults `d`; `runtime`: the tuning rows (all but ``motion_model``) can be set at run
    time; `unlimited_span`: ``iod_max_span`` 0 means no limit (else it must be > 0).
    """
    span = ("longest span of one IOD batch (one pass of one station); a later measurement, "
            "or one of another station or kind, starts a new batch")
    return (
        Param("motion_model", d.motion_model,
              "the EKF's motion model: `kepler` (analytic two-body) or `j2` (two-body + J2, "
              "integrated with its state transition matrix; ~3 ms per 30 s prediction "
              "instead of ~0.1 ms)", check=MOTION_MODELS),
        Param("p0_sigma", d.p0_sigma,
              "standard deviations added (in quadrature) to the IOD covariance (take effect "
              "at the next IOD)", unit="3 × m, 3 × m/s", check=P0_SIGMA, runtime=runtime),
        Param("q", d.q, "process noise: white-noise acceleration spectral density (0.1 "
              "m²/s³ = 1e-7 km²/s³ is sized for the J2 a Keplerian model leaves out)",
              unit="m²/s³", check=NON_NEGATIVE, runtime=runtime),
        Param("gate", d.gate, "normalized innovation squared beyond which an update is "
              "rejected; 0 = no gate", unit="NIS", check=NON_NEGATIVE, runtime=runtime),
        Param("iod_samples", d.iod_samples,
              "real measurements used by the initial orbit determination",
              check=integer_in(3, MAX_IOD_SAMPLES), runtime=runtime),
        Param("iod_max_span", d.iod_max_span, span + ("; 0 = no limit" if unlimited_span
                                                       else ""),
              unit="s", check=NON_NEGATIVE if unlimited_span else POSITIVE, runtime=runtime),
        Param("reinit_after", d.reinit_after,
              "after this many real measurements of an object in a row refused by the gate "
              "the filter has lost it: it forgets its state and initialises again "
              "(`reinitialised` on /diagnostics); 0 = never", unit="measurements",
              check=at_least(0), runtime=runtime),
        Param("sigma_bound", d.sigma_bound,
              "after each prediction, every position standard deviation is limited to "
              "`sigma_bound` × the position's norm and every velocity one to `sigma_bound` "
              "× the velocity's (rows and columns scaled, correlations kept): with 2, the "
              "orbit's diameter and twice its speed, so a gap of days cannot blow the "
              "covariance up beyond what is physically possible; 0 = no limit",
              check=NON_NEGATIVE, runtime=runtime),
    )
