"""Parameter tables: each node declares its ROS parameters once, as rows of a table.

A row (`Param`) holds a parameter's name, default, unit, rule (`Check`: bounds, choices),
whether it can be set at run time, and its description; a table (`ParameterTable`) holds
a node's rows and the rules over several of them (`Rule`). `NodeParameters` declares a
table on a node, refuses an invalid value at start-up (`ParameterError`, which the node's
process reports as ``error: parameter '<name>' …`` with exit code 2) and on every later
``ros2 param set``, and keeps the values in effect. ``docs/NODES.md``'s parameter tables
are generated from the same rows (`ssa_fusion.nodes.parameter_doc`).

Values are in the parameters' units (SI: m, m/s, rad, s); `ssa_fusion.nodes.settings` is
the one translation to the core's (km, km/s).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ssa_fusion.core.stations import network_stations
from ssa_fusion.ros.interfaces import ParameterDescriptor, SetParametersResult

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
    if isinstance(value, int | float) and math.isfinite(value):
        return float(value)
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


def numbers(count: int, reason: str) -> Check:
    """Return the check of a list of `count` finite numbers >= 0 (`reason` when not)."""
    def test(v: ParamValue) -> str | None:
        return None if isinstance(v, list) and len(v) == count and all_non_negative(v) else reason

    return Check(f"{count} values, each ≥ 0", test)


def _stations(value: ParamValue) -> str | None:
    try:
        network_stations(str(value))
    except ValueError as exc:
        return str(exc)
    return None


STATIONS = Check("a station id, a network id, or station ids separated by commas", _stations)
"""Stations (`core.stations.network_stations`): a station, a network, or ids with commas."""


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
    """Every parameter of one node, in declaration order, and the rules between them.

    Attributes
    ----------
    node : str
        The node's name.
    params : tuple of Param
        Its parameters, declared in this order (a `Computed` default reads earlier ones).
    rules : tuple of Rule
        Rules over several parameters.
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


def _ros(value: Default) -> ParamValue:
    """Return a default as rclpy declares it (arrays as lists)."""
    if isinstance(value, tuple):
        items: list[Any] = list(value)
        return items
    return value


class NodeParameters:
    """A `ParameterTable` declared on a node: the values in effect, checked on every set.

    Declares every row (with its description and read-only flag), raises `ParameterError`
    for an invalid start-up value or combination, and from then on refuses an invalid
    ``ros2 param set`` (logged, with the reason; old values kept). After an accepted set of
    run-time parameters, `on_set` gets the new values of those that changed (one call per
    set, however many parameters it sets at once).
    """

    def __init__(self, node: Node, table: ParameterTable,
                 on_set: Callable[[dict[str, ParamValue]], None]) -> None:
        self.node = node
        self.table = table
        self._on_set = on_set
        self.values: dict[str, ParamValue] = {}
        for p in table:
            self.values[p.name] = self._declare(p)
        for rule in table.rules:
            reason = rule.test(self.values)
            if reason:
                first = rule.names[0]
                raise ParameterError(f"parameter '{first}' = {self.values[first]!r}: {reason}")
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    def _declare(self, p: Param) -> ParamValue:
        default = (p.default.compute(self.values) if isinstance(p.default, Computed)
                   else _ros(p.default))
        descriptor = ParameterDescriptor(description=p.description, read_only=not p.runtime,
                                         additional_constraints=p.check.text if p.check else "")
        try:
            self.node.declare_parameter(p.name, default, descriptor)
        except ParameterException as exc:  # e.g. a string given for a number
            raise ParameterError(f"parameter '{p.name}': {exc}") from exc
        value = _plain(self.node.get_parameter(p.name).value)
        reason = p.reason(value)
        if reason:
            raise ParameterError(f"parameter '{p.name}' = {value!r}: {reason}")
        return value

    def _validate(self, params: list[Parameter[ParamValue]]) -> SetParametersResult:
        """Judge a set: each value by its row, then every rule with the values it leaves."""
        ours = [p for p in params if p.name in self.values]
        for p in ours:
            reason = self.table[p.name].reason(_plain(p.value))
            if reason:
                self.node.get_logger().warning(
                    f"refused parameter '{p.name}' = {p.value!r}: {reason}")
                return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
        new = {p.name: _plain(p.value) for p in ours}
        for rule in self.table.rules:
            changed = [name for name in rule.names if name in new]
            if not changed:
                continue
            reason = rule.test({**self.values, **new})
            if reason:
                text = ", ".join(f"'{name}' = {new[name]!r}" for name in changed)
                self.node.get_logger().warning(f"refused parameter {text}: {reason}")
                return SetParametersResult(successful=False,
                                           reason=f"{', '.join(changed)}: {reason}")
        return SetParametersResult(successful=True)

    def _apply(self, params: list[Parameter[ParamValue]]) -> None:
        """Put an accepted set into effect (values first, then the node's `on_set`)."""
        changed = {p.name: _plain(p.value) for p in params
                   if p.name in self.values and self.table[p.name].runtime}
        if not changed:
            return
        self.values.update(changed)
        self._on_set(changed)
        for name, value in changed.items():
            self.node.get_logger().info(f"parameter '{name}' = {value!r} in effect")

    def __getitem__(self, name: str) -> ParamValue:
        """Return the value in effect of parameter `name`."""
        return self.values[name]

    def number(self, name: str) -> float:
        """Return the value of numeric parameter `name` as a float."""
        value = self.values[name]
        assert isinstance(value, int | float), name
        return float(value)

    def integer(self, name: str) -> int:
        """Return the value of integer parameter `name`."""
        value = self.values[name]
        assert isinstance(value, int), name
        return int(value)

    def text(self, name: str) -> str:
        """Return the value of string parameter `name`."""
        value = self.values[name]
        assert isinstance(value, str), name
        return value

    def flag(self, name: str) -> bool:
        """Return the value of bool parameter `name`."""
        value = self.values[name]
        assert isinstance(value, bool), name
        return value

    def numbers(self, name: str) -> list[float]:
        """Return the value of numeric array parameter `name` as floats."""
        value = self.values[name]
        assert isinstance(value, list), name
        return [float(v) for v in value]

    def texts(self, name: str) -> list[str]:
        """Return the value of string array parameter `name`."""
        value = self.values[name]
        assert isinstance(value, list), name
        return [str(v) for v in value]

    def subset(self, names: tuple[str, ...]) -> dict[str, ParamValue]:
        """Return the values in effect of `names`."""
        return {name: self.values[name] for name in names}

    def reject_unknown(self) -> None:
        """Raise ParameterError naming every parameter given to the node that it lacks.

        Given by ``-p`` or a params file: a misspelt name would otherwise be ignored
        silently (rclpy's default). The message lists the parameters the node takes.
        """
        declared = set(self.node._parameters)  # rclpy keeps no public list of either
        given = set(getattr(self.node, "_parameter_overrides", {}))
        unknown = sorted(p for p in given - declared if not p.startswith("qos_overrides."))
        if unknown:
            names = ", ".join(f"parameter '{p}'" for p in unknown)
            raise ParameterError(f"unknown {names}; {self.node.get_name()} takes: "
                                 f"{', '.join(sorted(declared))}")


def _plain(value: object) -> ParamValue:
    """Return a parameter value as a plain Python value (arrays may come as array.array)."""
    if isinstance(value, bool | int | float | str):
        return value
    assert isinstance(value, Iterable), value
    items: list[Any] = list(value)  # the elements of one ROS type
    return items


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
