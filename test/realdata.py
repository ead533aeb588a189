"""Where the real laser-ranging data are: ``../shared/realdata/lageos2-2016`` beside the
repository (the files stay there, never in the repository; tests that read them are skipped
without them). A git worktree one directory deeper finds them one level further up."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _find() -> Path | None:
    for base in (ROOT.parent, ROOT.parent.parent):
        d = base / "shared" / "realdata" / "lageos2-2016"
        if d.is_dir():
            return d
    return None


LAGEOS = _find()
"""The directory of the LAGEOS-2 February 2016 data (its SOURCE.md says what they are), or
None."""
needs_lageos = pytest.mark.skipif(LAGEOS is None,
                                  reason="no ../shared/realdata/lageos2-2016 beside the "
                                         "repository")


def lageos(name: str) -> Path:
    """Return the path of one of the LAGEOS-2 files (only under `needs_lageos`)."""
    assert LAGEOS is not None
    return LAGEOS / name


CRD = "lageos2_20160211-13.npt"
CPF = "lageos2_cpf_160213_5441.sgf"
STATIONS = "SLRF2014_POS+VEL_2030.0_200428.snx"
ECCENTRICITIES = "ecc_une.snx"
