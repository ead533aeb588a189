"""What every PNG plot of `report` must have: a title, y labels with units, x labels in hours."""

from __future__ import annotations


def assert_readable(name: str, fig) -> None:
    """Assert figure `fig` (saved as `name`) has a title (the figure's or every axes'), a unit
    ("[...]") in every y label, and an x label in hours ("[h]") on its bottom axes."""
    axes = fig.get_axes()
    title = fig._suptitle.get_text() if fig._suptitle is not None else ""
    assert title or all(ax.get_title() for ax in axes), f"{name}: no title"
    for ax in axes:
        assert ax.get_ylabel(), f"{name}: an axis without a y label"
        assert "[" in ax.get_ylabel(), f"{name}: {ax.get_ylabel()!r} has no unit"
    bottom = [ax for ax in axes if ax.get_xlabel()]
    assert bottom and all("[h]" in ax.get_xlabel() for ax in bottom), name
