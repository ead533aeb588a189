"""Hostile text for the readers' tests: hypothesis strategies, and the error a reader gives."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pytest
from hypothesis import strategies as st


def mutated(text: str, tokens: Sequence[str]) -> st.SearchStrategy[str]:
    """`text` with one to five insertions, deletions or replacements (a token of the
    format, or up to 6 random characters, in place of up to 8 characters)."""
    edit = st.tuples(st.integers(0, len(text)), st.integers(0, 8),
                     st.one_of(st.sampled_from(list(tokens)), st.text(max_size=6)))
    return st.lists(edit, min_size=1, max_size=5).map(lambda edits: _apply(text, edits))


def _apply(text: str, edits: list[tuple[int, int, str]]) -> str:
    for at, drop, new in edits:
        at = min(at, len(text))
        text = text[:at] + new + text[at + drop:]
    return text


def error_of(read: Callable[[Path], object], error: type[Exception], path: Path,
             text: str | bytes) -> str:
    """The message of the `error` that `read` raises for `text`, written to `path`."""
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    with pytest.raises(error) as exc:
        read(path)
    return str(exc.value)
