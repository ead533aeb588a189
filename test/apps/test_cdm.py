"""CDMs in and out (formats.ccsds.cdm, cdm_out): CARA's real CDMs and their Pc, hostile
messages refused in one line, and a written CDM read back (by us and by ccsds-ndm)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from cara_cases import cara_cdm_dir
from cdm_cases import own_conjunction
from fuzz_text import error_of, mutated
from hypothesis import HealthCheck, given, settings

from ssa_fusion.core.base.quoting import MAX_MESSAGE
from ssa_fusion.core.conjunction.probability import collision_probability
from ssa_fusion.core.conjunction.result import PcMethod, PcWarning
from ssa_fusion.formats.ccsds.cdm import COV_KEYWORDS, parse_cdm, read_cdm
from ssa_fusion.formats.ccsds.cdm_out import cdm_text, write_cdm
from ssa_fusion.formats.ccsds.common import CcsdsError, frame_bias

CARA = cara_cdm_dir()
needs_cara = pytest.mark.skipif(CARA is None, reason="shared CARA CDMs not present")


# ------------------------------------------------------------------------------------------
# CARA's real CDMs
# ------------------------------------------------------------------------------------------
@needs_cara
def test_cara_cdms_pc_within_one_percent_of_caras() -> None:
    assert CARA is not None
    files = sorted(CARA.glob("*.cdm"))
    assert len(files) >= 27
    worst = (0.0, "")
    for f in files:
        cdm = read_cdm(f)
        assert cdm.pc_method == "FOSTER-1992" and cdm.pc is not None and cdm.hbr_km
        res = collision_probability(*cdm.inputs(), cdm.hbr_km)
        rel = math.expm1((res.log10_pc - math.log10(cdm.pc)) * math.log(10))
        if cdm.pc >= 1e-10:
            assert abs(rel) <= 0.01, f"{f.name}: ours {res.pc:.5e}, CARA {cdm.pc:.4e}"
            worst = max(worst, (abs(rel), f.name))
        else:  # the tiny ones (1e-81, 1e-168): the same order, to 0.01 in log10
            assert res.log10_pc == pytest.approx(math.log10(cdm.pc), abs=0.01), f.name
        assert cdm.miss_km is not None and res.miss_km == pytest.approx(cdm.miss_km, abs=6e-4)
    print(f"worst relative difference to CARA (Pc >= 1e-10): {worst[0]:.3%} ({worst[1]})")


@needs_cara
def test_xml_of_another_writer_reads_as_the_kvn() -> None:
    """ccsds-ndm writes CARA's KVN message as XML; we read both alike."""
    assert CARA is not None
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.ndm_io import NdmIo

    f = sorted(CARA.glob("*.cdm"))[1]
    io = NdmIo()
    xml = io.to_string(io.from_path(str(f)), NDMFileFormats.XML)
    a, b = read_cdm(f), parse_cdm(xml.encode(), "x.xml")
    assert b.format == "xml" and a.format == "kvn"
    for u, v in zip(a.inputs(), b.inputs(), strict=True):
        assert u is not None and v is not None and np.allclose(u, v, rtol=1e-15, atol=0)
    assert (b.tca, b.hbr_km, b.pc, b.miss_km, b.message_id) == \
        (a.tca, a.hbr_km, a.pc, a.miss_km, a.message_id)


# ------------------------------------------------------------------------------------------
# out and back
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["kvn", "xml"])
def test_written_cdm_reads_back(tmp_path: Path, fmt: str) -> None:
    c = own_conjunction()
    path = write_cdm(c, tmp_path / f"c.{fmt}", fmt)
    back = read_cdm(path)
    x1, p1, x2, p2 = back.inputs()
    assert p1 is not None and p2 is not None and c.p1 is not None and c.p2 is not None
    assert np.allclose(x1, c.x1, rtol=0, atol=1e-12) and np.allclose(x2, c.x2, atol=1e-12)
    assert np.allclose(p1, c.p1, rtol=1e-12, atol=1e-24)
    assert np.allclose(p2, c.p2, rtol=1e-12, atol=1e-24)
    assert back.tca == pytest.approx(c.tca, abs=1e-6) and back.hbr_km == pytest.approx(0.015)
    assert back.pc == pytest.approx(c.result.pc, rel=1e-6)
    assert back.pc_method == PcMethod.FOSTER_2D.value
    assert back.objects[0].designator == "40001" and back.objects[1].object_name == "DEBRIS B"
    again = collision_probability(x1, p1, x2, p2, back.hbr_km)
    assert again.pc == pytest.approx(c.result.pc, rel=1e-9)
    # the states were written in EME2000: the frame bias, undone on reading
    assert back.objects[0].ref_frame == "EME2000"
    assert np.allclose(back.objects[0].state[:3], frame_bias() @ c.x1[:3], atol=1e-12)


@pytest.mark.parametrize("fmt", ["kvn", "xml"])
def test_written_cdm_is_read_by_ccsds_ndm(tmp_path: Path, fmt: str) -> None:
    from ccsds_ndm.ndm_io import NdmIo

    c = own_conjunction()
    doc = NdmIo().from_path(str(write_cdm(c, tmp_path / f"c.{fmt}", fmt)))
    rel = doc.body.relative_metadata_data
    assert rel.collision_probability == pytest.approx(c.result.pc, rel=1e-6)
    assert rel.miss_distance.value == pytest.approx(
        np.linalg.norm(c.x2[:3] - c.x1[:3]) * 1e3)
    cov = doc.body.segment[1].data.covariance_matrix
    assert cov.cr_r.units.value == "m**2" and cov.cndot_ndot.units.value == "m**2/s**2"


def test_missing_covariance_is_read_and_gives_an_upper_bound(tmp_path: Path) -> None:
    c = own_conjunction()
    text = cdm_text(c)
    seg2 = text.index("OBJECT                               = OBJECT2")
    cut = text[:seg2] + re.sub(r"^C[A-Z]+_[A-Z]+ .*\n", "", text[seg2:], flags=re.M)
    cdm = parse_cdm(cut.encode())
    x1, p1, x2, p2 = cdm.inputs()
    assert p1 is not None and p2 is None
    res = collision_probability(x1, p1, x2, p2, cdm.hbr_km or 0.0)
    assert res.method is PcMethod.FRISBEE_MAX and PcWarning.MISSING_COVARIANCE in res.warnings
    assert res.pc >= c.result.pc


def test_non_positive_definite_covariance_is_flagged() -> None:
    c = own_conjunction()
    bad = c.p2.copy() if c.p2 is not None else None
    assert bad is not None
    bad[0, 1] = bad[1, 0] = 2 * math.sqrt(bad[0, 0] * bad[1, 1])  # correlation 2
    cdm = parse_cdm(cdm_text(own_conjunction(bad)).encode())
    res = collision_probability(*cdm.inputs(), cdm.hbr_km or 0.0)
    assert PcWarning.NPD_SECONDARY in res.warnings and 0.0 <= res.pc <= 1.0


# ------------------------------------------------------------------------------------------
# hostile messages
# ------------------------------------------------------------------------------------------
def _sub(text: str, pattern: str, new: str) -> str:
    out, n = re.subn(pattern, new, text, count=1, flags=re.M)
    assert n == 1, pattern
    return out


GOOD = cdm_text(own_conjunction())
HOSTILE = {  # name: (text, what the one line says)
    "unit": (_sub(GOOD, r"(CR_R +=.*)\[m\*\*2\]", r"\1[km**2]"), "CR_R in [km**2], not [m**2]"),
    "state unit": (_sub(GOOD, r"^(X +=.*)\[km\]", r"\1[m]"), "X in [m], not [km]"),
    "nan": (_sub(GOOD, r"^(CT_T +=) \S+", r"\1 NaN"), "CT_T = 'NaN': not a finite number"),
    "garbage": (_sub(GOOD, r"^(Z_DOT +=) \S+", r"\1 1.2.3"), "Z_DOT = '1.2.3': not a number"),
    "negative variance": (_sub(GOOD, r"^(CN_N +=) \S+", r"\1 -4"), "CN_N = '-4' < 0"),
    "partial covariance": (_sub(GOOD, r"^CTDOT_T .*\n", ""), "covariance incomplete"),
    "no state": (_sub(GOOD, r"^Y +=.*\n", ""), "no Y: the Pc needs it"),
    "no TCA": (_sub(GOOD, r"^TCA .*\n", ""), "no TCA"),
    "bad TCA": (_sub(GOOD, r"^(TCA +=) \S+", r"\1 2025-13-45T00:00:00"), "TCA: epoch"),
    "frame": (_sub(GOOD, r"^(REF_FRAME +=) \S+", r"\1 MOON_ME"), "REF_FRAME = 'MOON_ME'"),
    "pc": (_sub(GOOD, r"^(COLLISION_PROBABILITY +=) \S+", r"\1 1.5"), "not a probability"),
    "hbr": (_sub(GOOD, r"^COMMENT HBR = \S+ \[m\]", "COMMENT HBR = 15 [ft]"),
            "HBR in [ft], not [m]"),
    "one object": (GOOD[:GOOD.index("OBJECT                               = OBJECT2")],
                   "1 OBJECT section(s)"),
    "three objects": (GOOD + GOOD[GOOD.index("OBJECT                               = "
                                             "OBJECT2"):], "a third OBJECT"),
    "twice": (_sub(GOOD, r"^(X +=.*\n)", r"\1\1"), "X given twice"),
    "not a cdm": ("CCSDS_OPM_VERS = 2.0\nX = 1\n", "not CCSDS_CDM_VERS"),
    "text": ("hello world\n", "not a KEYWORD = value line"),
    "empty": ("  \n", "empty"),
    "binary": (b"\x00\xff\xfe garbage \x80", "not UTF-8"),
    "long line": ("CCSDS_CDM_VERS = 1.0\nCOMMENT " + "x" * 10_000 + "\n", "longer than"),
    "xml": ("<cdm><header><ORIGINATOR>x</ORIGINATOR></heade></cdm>", "not well-formed XML"),
    "xml root": ("<opm version='1.0'><X>1</X></opm>", "not a CDM"),
    "entities": ('<?xml version="1.0"?><!DOCTYPE cdm [<!ENTITY a "aaaaaaaaaa">'
                 '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><cdm>&b;</cdm>', ""),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_cdm_refused_in_one_line(tmp_path: Path, name: str) -> None:
    text, says = HOSTILE[name]
    msg = error_of(read_cdm, CcsdsError, tmp_path / "h.cdm", text)
    assert says in msg and "\n" not in msg and len(msg) <= MAX_MESSAGE + 200
    assert str(tmp_path / "h.cdm") in msg


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(GOOD, ["=", "[m]", "[km]", "NaN", "OBJECT = OBJECT2", "COMMENT", "\n", "e999",
                      *COV_KEYWORDS[:4]]))
def test_mutated_cdm_reads_or_is_refused_in_one_line(text: str) -> None:
    try:
        cdm = parse_cdm(text.encode(), "m.cdm")
    except CcsdsError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("m.cdm")
        return
    x1, p1, x2, p2 = cdm.inputs()
    assert np.all(np.isfinite(x1)) and np.all(np.isfinite(x2))
    if cdm.hbr_km:
        try:
            res = collision_probability(x1, p1, x2, p2, cdm.hbr_km)
        except ValueError:
            return
        assert math.isnan(res.pc) or 0.0 <= res.pc <= 1.0
