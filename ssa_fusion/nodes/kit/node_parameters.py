"""A node's `ParameterTable` declared on it: values in effect, checked on every set."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ssa_fusion.params.checks import ParamValue
from ssa_fusion.params.rows import Computed, Default, Param, ParameterError, ParameterTable
from ssa_fusion.ros.interfaces import ParameterDescriptor, SetParametersResult


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
        try:
            value = _plain(self.node.get_parameter(p.name).value)
        except ParameterUninitializedException:  # `-p name:=[]`: a list of no type
            raise ParameterError(
                f"parameter '{p.name}' = []: an empty list has no type; give at least one "
                f"value (default: {default!r})") from None
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
