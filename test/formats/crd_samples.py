"""Small CRD files written for the tests (made-up values in the formats' layouts), and the
one-line error check every reader test shares."""

from __future__ import annotations

from pathlib import Path

from ssa_fusion.core.base.quoting import MAX_MESSAGE

V1 = """\
00 a made-up session of normal points
h1 CRD  1 2020  3  5 12
h2 TEST       7001 12 34  4
h3 lageos1     7603901 1155     8820 0 1
h4  1 2020  3  4 23 50  0 2020  3  5  0 20  0  0 0 0 0 1 0 2 0
c0 0  532.000 cfg las det tim
c1 0 las Nd:Yag     532.00       5.00     100.00  150.0 15.00    1
c3 0 tim Clock Clock Timer na   -1.0
60  cfg 4 1
20 85800.000  1001.50 290.10  55. 0
40 85790.000 0 cfg -1 -1 -1.000   105000.0   -12.0   20.0  -1.000  -1.000   -1.0 2 2 0
11 85810.000000000000 0.040000000000 cfg 2  120.0     50   40.0   0.100  -0.500  -1.0  12.00 0
30 85810.000  123.400  45.600 0 1 0
11   300.250000000000 0.045000000000 cfg 0  120.0     20   35.0   0.100  -0.500  -1.0   8.00 0
20   310.000  1001.70 289.90  56. 1
50 cfg   38.0   0.050   2.900   -1.0 0
h8
h9
"""
"""One v1 session crossing midnight (2020-03-04 23:50 .. 03-05 00:20): a normal point
before midnight (transmit epoch event 2), one after (receive epoch, event 0)."""

V2 = """\
H1 CRD  2 2021  6  1 10
H2 NEW1       7002  1  1  7 ILRS
H3 lares       1200601 5987    38077 0 1 1
H4  1 2021  6  1  9  0  0 na na na na na na  1 0 0 0 1 0 2 0
H5 1 21 060109 HTS 1
C0 0 1064.000 c2 l2 d2 t2
C5 0 sw1 Track,Tool 1.0,2.0 Proc 3.1
C6 0 met1 PMaker PM1 1 TMaker TM1 2 HMaker HM1 3
C7 0 cal1 Board 123.456 1.5 0.01 0.1 Calib 2.0
20 32400.000  950.00 280.00  70. 0
21 32400.000 2.5 180.0 na 20.0 na na 10.0 270.0
40 32390.000 0 c2 na na na 98000.0 na 15.0 na na na 2 2 0 na na
41 32391.000 0 c2 100 90 12.5 98010.0 1.0 15.5 0.1 -0.2 2.0 2 2 0 1 50.0
11 32410.100000000000     0.025000000000 c2 2  30.0     na   na   na  na      na   na 0 na
12 32410.100 c2 na na na na na
30 32410.100  10.000  30.000 1 3 1 na na
50 c2   na   na   na   na 0
H8
H9
"""
"""One v2 session: ``na`` where values may be missing, H5, C5..C7, records 21, 41, 12."""

FULL_RATE = """\
H1 CRD  2 2021  6  1 10
H2 NEW1       7002  1  1  7 ILRS
H3 lares       1200601 5987    38077 0 1 1
H4  0 2021  6  1  9  0  0 2021  6  1  9 10  0  0 0 0 0 1 0 2 0
C0 0 532.000 c1 l1
10 32410.100000000000     0.025000000000 c1 2 2 0 1 na na
10 32410.200000000000     0.025000001000 c1 2 2 0 1 120 na
H8
H9
"""
"""A v2 full-rate session (record 10)."""


def bounded(message: str, path: Path) -> str:
    """`message` is one line of at most MAX_MESSAGE characters naming `path`."""
    assert "\n" not in message and len(message) <= MAX_MESSAGE, message[:300]
    assert message.startswith(str(path)), message[:300]
    return message
