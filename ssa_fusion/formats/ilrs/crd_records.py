"""The records of a CRD file (ILRS Consolidated laser Ranging Data, v1.01 and v2.01).

What `crd.CrdReader` yields: a `CrdSession` (the H1..H5 headers of a session and the
wavelengths of its system configurations, C0) and the session's data records in file
order, `RangeRecord` (10 full-rate, 11 normal point), `RangeSupplement` (12),
`MeteoRecord` (20), `PointingRecord` (30), `CalibrationRecord` (40, 41) and
`SessionStatistics` (50). Epochs are Unix seconds (UTC); other values in the file's units
(s, ps, nm, mbar = hPa, K, %, deg, m), named in each field.

`FIELD_SPECS` lists every field of the records read only to be checked (C1..C7, 21, 42,
60): their names and kinds. References: R. L. Ricklefs and C. J. Moore, "Consolidated Laser
Ranging Data Format (CRD)", version 1.01 (2009) and 2.01 (2019), ILRS.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

UTC_TIME_SCALES = {3: "UTC (USNO)", 4: "UTC (GPS)", 7: "UTC (BIPM)", 10: "UTC (station)",
                   11: "UTC (SU)", 12: "UTC (NTSC)"}
"""H2 station epoch time scales, all UTC: the ones a CRD file may give its epochs in."""


class DataType(enum.IntEnum):
    """H4 data type: what the session's range records are."""

    FULL_RATE = 0
    NORMAL_POINT = 1
    SAMPLED_ENGINEERING = 2


class RangeType(enum.IntEnum):
    """H4 range type indicator."""

    NO_RANGES = 0
    ONE_WAY = 1
    TWO_WAY = 2
    RECEIVE_ONLY = 3
    MIXED = 4


class EpochEvent(enum.IntEnum):
    """What a range record's epoch is the time of (records 10 and 11)."""

    GROUND_RECEIVE = 0
    """Two-way: reception at the station's system reference point."""
    SPACECRAFT_BOUNCE = 1
    """Two-way: reflection at the spacecraft."""
    GROUND_TRANSMIT = 2
    """Two-way: transmission at the station's system reference point."""
    SPACECRAFT_RECEIVE = 3
    SPACECRAFT_TRANSMIT = 4
    GROUND_TRANSMIT_SPACECRAFT_RECEIVE = 5
    SPACECRAFT_TRANSMIT_GROUND_RECEIVE = 6


TWO_WAY_EVENTS = (EpochEvent.GROUND_RECEIVE, EpochEvent.SPACECRAFT_BOUNCE,
                  EpochEvent.GROUND_TRANSMIT)
"""The epoch events of two-way ranges."""


@dataclass
class CrdSession:
    """One session (pass) of a CRD file: its headers, and its configurations' wavelengths.

    Attributes
    ----------
    number, line
        The session's number in the file (from 1) and the line of its H4.
    version
        The CRD format version (H1): 1 or 2.
    station_name, pad, system_number, occupancy, time_scale, network
        H2: the station's name, its 4-digit CDP pad id (the SINEX site code), CDP system
        number and occupancy sequence, its epochs' time scale (`UTC_TIME_SCALES`), its
        network (v2; "" in v1).
    target_name, ilrs_id, sic, norad, target_type
        H3: the target's name and ids (the ILRS id is COSPAR-derived, 9207002 for
        1992-070B; the SIC and NORAD number None when not given: -1 or ``na``), its type.
    data_type, start, end, release
        H4: `DataType`, start and end of the session (Unix s; `end` None when not given),
        data release flag.
    troposphere_applied, com_applied, amplitude_applied, station_delay_applied,
    spacecraft_delay_applied
        H4: whether the ranges have these corrections applied.
    range_type, quality
        H4: `RangeType`, and the data quality alert (0 good, 1 suspect, 2 poor).
    wavelengths_nm
        C0: transmit wavelength (nm) of each system configuration id.
    """

    number: int
    line: int
    version: int
    station_name: str
    pad: int
    system_number: int
    occupancy: int
    time_scale: int
    network: str
    target_name: str
    ilrs_id: int
    sic: int | None
    norad: int | None
    target_type: int
    data_type: DataType
    start: float
    end: float | None
    release: int
    troposphere_applied: bool
    com_applied: bool
    amplitude_applied: bool
    station_delay_applied: bool
    spacecraft_delay_applied: bool
    range_type: RangeType
    quality: int
    wavelengths_nm: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class RangeRecord:
    """A range (record 11: a normal point; record 10: a full-rate range).

    `t` is the epoch (Unix s, UTC) of its `epoch_event`; `time_of_flight_s` the time of
    flight as the file gives it (two-way for the two-way events); `config_id` the system
    configuration (its C0 has the wavelength). Normal points only: the bin's length
    `window_s`, raw ranges in it, their RMS (ps, None if not given) and the return rate (%,
    None if not given).
    """

    session: CrdSession
    line: int
    t: float
    time_of_flight_s: float
    config_id: str
    epoch_event: EpochEvent
    normal_point: bool
    window_s: float | None = None
    raw_ranges: int | None = None
    bin_rms_ps: float | None = None
    return_rate_pct: float | None = None


@dataclass(frozen=True)
class RangeSupplement:
    """Record 12: corrections applied (troposphere ps, centre of mass m) at `t`."""

    session: CrdSession
    line: int
    t: float
    config_id: str
    troposphere_ps: float | None
    com_m: float | None


@dataclass(frozen=True)
class MeteoRecord:
    """Record 20: surface pressure (mbar = hPa), temperature (K), humidity (%) at `t`."""

    session: CrdSession
    line: int
    t: float
    pressure_hpa: float
    temperature_k: float
    humidity_pct: float
    interpolated: bool


@dataclass(frozen=True)
class PointingRecord:
    """Record 30: the telescope's azimuth and elevation (deg) at `t`."""

    session: CrdSession
    line: int
    t: float
    azimuth_deg: float
    elevation_deg: float


@dataclass(frozen=True)
class CalibrationRecord:
    """Records 40 and 41: a calibration's system delay and its RMS (ps) at `t`."""

    session: CrdSession
    line: int
    t: float
    config_id: str
    delay_ps: float | None
    rms_ps: float | None
    detail: bool


@dataclass(frozen=True)
class SessionStatistics:
    """Record 50: the session's RMS (ps) and data quality indicator."""

    session: CrdSession
    line: int
    config_id: str
    rms_ps: float | None
    quality: int


CrdItem = (CrdSession | RangeRecord | RangeSupplement | MeteoRecord | PointingRecord
           | CalibrationRecord | SessionStatistics)
"""What `crd.CrdReader` yields."""


class FieldKind(enum.Enum):
    """The kind of a field `FIELD_SPECS` checks."""

    WORD = "word"
    INT = "integer"
    NUM = "number"


W, INT, N = FieldKind.WORD, FieldKind.INT, FieldKind.NUM
FIELD_SPECS: dict[str, tuple[tuple[str, FieldKind], ...]] = {
    "C1": (("detail type", INT), ("laser configuration id", W), ("laser type", W),
           ("primary wavelength", N), ("fire rate", N), ("pulse energy", N),
           ("pulse width", N), ("beam divergence", N), ("pulses in semi-train", INT)),
    "C2": (("detail type", INT), ("detector configuration id", W), ("detector type", W),
           ("applicable wavelength", N), ("quantum efficiency", N), ("applied voltage", N),
           ("dark count", N), ("output pulse type", W), ("output pulse width", N),
           ("spectral filter", N), ("filter transmission", N), ("spatial filter", N),
           ("external signal processing", W)),
    "C3": (("detail type", INT), ("timing configuration id", W), ("time source", W),
           ("frequency source", W), ("timer", W), ("timer serial number", W),
           ("epoch delay correction", N)),
    "C4": (("detail type", INT), ("transponder configuration id", W),
           ("station UTC offset", N), ("station oscillator drift", N),
           ("transponder UTC offset", N), ("transponder oscillator drift", N),
           ("transponder clock reference time", N), ("station clock applied", INT),
           ("spacecraft clock applied", INT), ("spacecraft time simplified", INT)),
    "C5": (("detail type", INT), ("software configuration id", W), ("tracking software", W),
           ("tracking software versions", W), ("processing software", W),
           ("processing software versions", W)),
    "C6": (("detail type", INT), ("meteorological configuration id", W),
           *((f"{s} sensor {p}", W) for s in ("pressure", "temperature", "humidity")
             for p in ("manufacturer", "model", "serial number"))),
    "C7": (("detail type", INT), ("calibration target id", W), ("target name", W),
           ("surveyed distance", N), ("survey error", N), ("sum of constant delays", N),
           ("pulse energy", N), ("processing software name", W),
           ("processing software version", W)),
    "21": (("seconds of day", N), ("wind speed", N), ("wind direction", N),
           ("weather conditions", W), ("visibility", N), ("sky clarity", N),
           ("atmospheric seeing", N), ("cloud cover", N)),
    "42": (("seconds of day", N), ("time of flight", N), ("system configuration id", W)),
    "60": (("system configuration id", W), ("system change indicator", INT),
           ("system configuration indicator", INT)),
}
"""The fields (name, kind) of the records read only to be checked, in order. Extra fields
(v2 additions, C0 components) are taken as words; numbers may be ``na`` in v2."""
del W, INT, N
