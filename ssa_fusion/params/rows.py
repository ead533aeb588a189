"""Parameter tables: each node declares its ROS parameters once, as rows of a table.

A row (`Param`) holds a parameter's name, default, unit, scale to the core's unit, rule
(`checks.Check`: bounds, choices), whether it can be set at run time, and a short
description; a table (`ParameterTable`) holds a node's rows and the rules over several of
them (`Rule`). `nodes.kit.node_parameters.NodeParameters` declares a table on a node,
refuses an invalid value at start-up (`ParameterError`, which the node's process reports as
``error: parameter '<name>' …`` with exit code 2) and on every later ``ros2 param set``, and
keeps the values in effect. ``docs/NODES.md``'s parameter tables are generated from the same
rows (`ssa_fusion.params.doc`).

Values are in the parameters' units (SI: m, m/s, rad, s); `units.convert` scales them to
the core's (km, km/s) and back by each row's `Param.scale`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ssa_fusion.params.checks import Check, ParamValue, Values

Default = ParamValue | tuple[float, ...] | tuple[str, ...]
"""A default as `ssa_fusion.params.defaults` writes it (tuples for arrays: frozen)."""


class ParameterError(ValueError):
    """A parameter value is invalid; the message names the parameter and the rule."""


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
    scale : float
        Its unit per unit of the core's setting: value = core value × `scale` (1000 for
        m against the core's km, 1e6 for m²/s³ against km²/s³; 1: the same unit).
    """

    name: str
    default: Default | Computed
    description: str
    unit: str = "–"
    check: Check | None = None
    runtime: bool = False
    scale: float = 1.0

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
