"""The rules a parameter's value must follow (`Check`), and those several tables use.

A check is a function of one value (None when valid, else the reason) with the text the docs
print in a table's "range" column. `sites_problem` is a rule over two parameters
(``station`` and ``sites``, `rows.Rule`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ssa_fusion.core.earth.stations import network_stations, station_ids
from ssa_fusion.formats.sites import load_station_map, load_stations

ParamValue = bool | int | float | str | list[bool] | list[int] | list[float] | list[str]
"""What a ROS parameter of these nodes holds."""
Values = Mapping[str, ParamValue]
"""Parameter values by name."""


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
    """Return an int or a finite float as a float, anything else as None.

    A bool is not a number here (Python's True is 1; a params file's ``q: true`` is a typo or
    a wrong key, never 1.0, and ROS refuses a bool for a double parameter too).
    """
    try:
        if isinstance(value, int | float) and not isinstance(value, bool) and \
                math.isfinite(value):
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
        ok = isinstance(v, int) and not isinstance(v, bool) and v >= low
        return None if ok else f"must be an integer >= {low}"

    return Check(f"integer ≥ {low}", test)


def integer_in(low: int, high: int) -> Check:
    """Return the check of an integer in `low`..`high`."""
    def test(v: ParamValue) -> str | None:
        ok = isinstance(v, int) and not isinstance(v, bool) and low <= v <= high
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


def finite_numbers(count: int, reason: str) -> Check:
    """Return the check of a list of `count` finite numbers (`reason` when not)."""
    def test(v: ParamValue) -> str | None:
        ok = isinstance(v, list) and len(v) == count and all(_finite(x) is not None for x in v)
        return None if ok else reason

    return Check(f"{count} finite values", test)


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


OUTPUT = ">"
"""Marks a need on a node's output: 'node:>/topic' (`ros.readiness.OUTPUT`)."""


def _need_problem(need: str) -> bool:
    """Return True when `need` is not 'node:[>]/topic[=count]' (count an integer >= 1)."""
    name, _, rest = need.partition(":")
    topic, _, count = rest.partition("=")
    return (not name or "/" in name or not topic.removeprefix(OUTPUT).startswith("/")
            or ("=" in need and not (count.isdigit() and int(count) >= 1)))


def check_needs(needs: list[str]) -> str | None:
    """Return why a list of 'node:[>]/topic[=count]' entries is malformed, or None.

    The entries `ros.readiness.ReadyNodes` waits for (sensor_sim's ``wait_for_readers``).
    """
    for need in needs:
        if _need_problem(need):
            return (f"{need!r} is not 'node:/topic', 'node:>/topic' or either with '=count' "
                    f"(node: the node's name, no namespace; '/topic': publishers it has "
                    f"matched on that input, '>/topic': subscribers its output on that topic "
                    f"has matched; count: how many, at least 1)")
    return None
