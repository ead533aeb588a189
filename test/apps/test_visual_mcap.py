"""visual.mcap (the same visual topics as the bridge serves, in a file): `ssa-fusion report`
writes the Foxglove visual topics of a bag with foxglove-sdk's MCAP writer; read back here
with the independent `mcap` reader."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from ssa_fusion.apps import evaluate, visual_mcap
from ssa_fusion.core.earth.frames import COLUMBUS
from ssa_fusion.ros import foxglove_scene as scene

ROOT = Path(__file__).resolve().parents[2]
SAMPLE_BAG = ROOT / "bags" / "sample_iss_j2_rae"
SCHEMAS = {scene.SCENE_TOPIC: "foxglove.SceneUpdate",
           scene.TRACK_TOPIC: "foxglove.LocationFix",
           scene.TRUTH_TRACK_TOPIC: "foxglove.LocationFix",
           scene.METRICS_TOPIC: ""}
"""Schema name of each channel (metrics: JSON with the JSON schema `METRICS_SCHEMA`)."""


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory
            ) -> tuple[evaluate.BagData, Path, dict[str, int]]:
    data = evaluate.load(SAMPLE_BAG)
    path = tmp_path_factory.mktemp("visual") / "visual.mcap"
    counts = visual_mcap.write(data, path, {COLUMBUS.name: COLUMBUS})
    return data, path, counts


def _messages(path: Path) -> list[tuple[str, str, str, int, bytes]]:
    """(topic, schema name, schema encoding, log time ns, data) of every message."""
    with path.open("rb") as f:
        return [(ch.topic, sc.name if sc else "", sc.encoding if sc else "", m.log_time, m.data)
                for sc, ch, m in make_reader(f).iter_messages()]


def _wire(buf: bytes) -> dict[int, list[int | bytes]]:
    """Protobuf wire format -> {field number: [values]}: varints as int, fixed64 as the 8
    bytes, length-delimited as bytes (enough for LocationFix and descriptors; no protobuf
    package needed)."""
    out: dict[int, list[int | bytes]] = {}
    i = 0

    def varint() -> int:
        nonlocal i
        v = shift = 0
        while True:
            b = buf[i]
            i += 1
            v |= (b & 0x7F) << shift
            shift += 7
            if b < 0x80:
                return v

    while i < len(buf):
        key = varint()
        num, wt = key >> 3, key & 7
        if wt == 0:
            val: int | bytes = varint()
        elif wt == 1:
            val, i = buf[i:i + 8], i + 8
        elif wt == 2:
            n = varint()
            val, i = buf[i:i + n], i + n
        elif wt == 5:
            val, i = buf[i:i + 4], i + 4
        else:
            raise ValueError(f"wire type {wt}")
        out.setdefault(num, []).append(val)
    return out


def _field_numbers(path: Path, message: str) -> dict[str, int]:
    """Field name -> number of protobuf `message` (e.g. "LocationFix"), read from the
    FileDescriptorSet the MCAP schema record carries."""
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    sc = next(s for s in summary.schemas.values() if s.name == f"foxglove.{message}")
    for fd in _wire(sc.data)[1]:  # FileDescriptorSet.file
        for mt in _wire(bytes(fd)).get(4, []):  # FileDescriptorProto.message_type
            d = _wire(bytes(mt))
            if bytes(d[1][0]).decode() == message:  # DescriptorProto.name
                fields = [_wire(bytes(x)) for x in d[2]]  # DescriptorProto.field
                return {bytes(x[1][0]).decode(): int(x[3][0]) for x in fields}  # name, number
    raise AssertionError(f"no {message} in its schema")


def test_the_file_holds_the_four_visual_channels_with_their_schemas(written):
    data, path, counts = written
    msgs = _messages(path)
    schemas = {topic: (name, enc) for topic, name, enc, _, _ in msgs}
    assert set(schemas) == set(scene.TOPICS)
    for topic, name in SCHEMAS.items():
        if name:
            assert schemas[topic] == (name, "protobuf"), topic
        else:
            assert schemas[topic][1] == "jsonschema", topic
    n = {topic: sum(m[0] == topic for m in msgs) for topic in scene.TOPICS}
    assert n == {t: counts[t] for t in scene.TOPICS}
    assert n[scene.TRUTH_TRACK_TOPIC] == len(data.truth)
    assert n[scene.TRACK_TOPIC] == n[scene.METRICS_TOPIC] == len(data.estimates)
    span_h = (data.truth[-1].t - data.truth[0].t) / 3600.0
    # one scene per SCENE_PERIOD_S of sim time, at least
    assert n[scene.SCENE_TOPIC] >= span_h * 3600.0 / visual_mcap.SCENE_PERIOD_S


def test_log_times_are_the_sim_time_stamps_within_the_bag(written):
    data, path, _ = written
    stamps = [m.t for m in (*data.truth, *data.estimates, *data.measurements, *data.forecasts)]
    lo, hi = min(stamps) * 1e9, max(stamps) * 1e9
    msgs = _messages(path)
    assert all(lo - 1 <= m[3] <= hi + 1 for m in msgs)
    truth_ns = [m[3] for m in msgs if m[0] == scene.TRUTH_TRACK_TOPIC]
    assert truth_ns == [round(e.t * 1e9) for e in data.truth]
    metrics = [json.loads(m[4]) for m in msgs if m[0] == scene.METRICS_TOPIC]
    scored = [d for d in metrics if d["position_error_km"] is not None]
    assert len(scored) >= 0.99 * len(metrics)  # the truth of an estimate's epoch came first
    assert all(d["sigma_km"] > 0 for d in metrics)


def test_a_location_fix_agrees_with_a_direct_computation(written):
    import struct

    data, path, _ = written
    fixes = [(t, d) for topic, _, _, t, d in _messages(path) if topic == scene.TRUTH_TRACK_TOPIC]
    i = len(fixes) // 2
    num = _field_numbers(path, "LocationFix")
    raw = _wire(fixes[i][1])

    def double(name: str) -> float:
        return float(struct.unpack("<d", bytes(raw[num[name]][0]))[0])

    e = data.truth[i]
    assert bytes(raw[num["frame_id"]][0]).decode() == "truth"
    assert fixes[i][0] == round(e.t * 1e9)
    # direct: GCRF -> ITRF by ERFA's full rotation (c2t06a: IAU 2006/2000A, the same IERS
    # table's UT1 - UTC and polar motion), then the geodetic latitude by fixed point
    import erfa

    from ssa_fusion.core.earth import eop, timescales

    v = eop.default().at(np.array([e.t]))
    jd1, jd2 = 2440587.5, e.t / 86400.0
    tt = jd2 + float(timescales.tt_minus_utc(e.t)) / 86400.0
    c2t = erfa.c2t06a(jd1, tt, jd1, jd2 + v.dut1[0] / 86400.0, v.xp[0], v.yp[0])
    xe, ye, z = c2t @ e.x[:3]
    lon = math.degrees(math.atan2(ye, xe))
    f = 1 / 298.257223563
    e2 = f * (2 - f)
    p = math.hypot(xe, ye)
    lat = math.atan2(z, p * (1 - e2))
    for _ in range(10):  # Bowring-free fixed point, at the object's altitude
        n = 6378.137 / math.sqrt(1 - e2 * math.sin(lat) ** 2)
        lat = math.atan2(z + e2 * n * math.sin(lat), p)
    assert double("latitude") == pytest.approx(math.degrees(lat), abs=1e-6)
    assert (double("longitude") - lon + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-6)
    # ellipsoidal height (m) within the Earth's flattening (21 km) of the geocentric one
    assert abs(double("altitude") - 1000 * (np.linalg.norm(e.x[:3]) - 6378.137)) < 22e3
