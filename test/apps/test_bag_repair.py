"""`ssa-fusion bag repair`: a bag whose recorder was killed (SIGKILL:
no metadata.yaml, no MCAP summary, a torn last chunk) becomes one that plain rosbags and the
mcap reader open, with every message of its complete chunks, byte for byte. No ROS needed.
"""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from ssa_fusion.apps import cli
from ssa_fusion.core.base import types
from ssa_fusion.ros import bagio, bagrepair, messages

CHUNKS, PER_CHUNK = 6, 90
KEPT = 3  # the cut falls inside chunk 4: chunks 1-3 survive
TOPICS = {"/ssa/measurement": "ssa_fusion_msgs/msg/Measurement",
          "/clock": "rosgraph_msgs/msg/Clock", "/ssa/config": "std_msgs/msg/String"}


def _message(i: int, classes, store) -> tuple[str, object]:
    """Message i: a measurement, a clock or a config string, in turn."""
    t = 1000.0 + 30.0 * i
    if i % 3 == 0:
        m = types.Measurement(t, np.array([7000.0 + i, 0.1, 0.2]), 1e-4 * np.eye(3),
                              kind=types.Kind.RANGE_AZ_EL, frame_id="columbus")
        return "/ssa/measurement", messages.measurement_to_msg(m, classes)
    if i % 3 == 1:
        stamp = classes.time(sec=int(t), nanosec=0)
        return "/clock", store.types["rosgraph_msgs/msg/Clock"](clock=stamp)
    return "/ssa/config", store.types["std_msgs/msg/String"](data=f"{{\"n\": {i}}}")


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict:
    """A complete bag and the same recording killed inside chunk KEPT + 1: its .mcap as the
    recorder leaves it (chunks flushed, no summary, no metadata.yaml), cut there."""
    root = tmp_path_factory.mktemp("bags")
    complete, killed = root / "complete", root / "killed"
    classes, store = bagio.rosbags_classes(), bagio.typestore()
    writer = bagio.BagWriter(complete)
    for topic, msgtype in TOPICS.items():
        writer.add_topic(topic, msgtype)
    written: list[tuple[str, int, bytes]] = []
    ends = []
    for i in range(CHUNKS * PER_CHUNK):
        topic, msg = _message(i, classes, store)
        cdr = bytes(store.serialize_cdr(msg, TOPICS[topic]))
        t_ns = 1_700_000_000_000_000_000 + i * 1_000_000
        writer.write(topic, t_ns, cdr)
        written.append((topic, t_ns, cdr))
        if i % PER_CHUNK == PER_CHUNK - 1:
            writer.flush()  # what the recorder does every flush_period
            ends.append(next(complete.glob("*.mcap")).stat().st_size)
    killed.mkdir()
    flushed = next(complete.glob("*.mcap")).read_bytes()  # SIGKILL now: no summary
    writer.close()
    start = ends[KEPT - 1]  # chunk KEPT + 1: opcode 0x06, record length, record
    assert flushed[start] == 0x06
    cut = start + 9 + struct.unpack_from("<Q", flushed, start + 1)[0] // 2
    (killed / "killed.mcap").write_bytes(flushed[:cut])
    return {"complete": complete, "killed": killed, "written": written, "root": root}


def _plain(bag: Path) -> tuple[dict, list[tuple[str, int, bytes]]]:
    """What plain rosbags reads: {topic: (type, definition, hash)}, messages."""
    with Reader(bag) as reader:
        conns = {c.topic: (c.msgtype, c.msgdef.data, c.digest) for c in reader.connections}
        msgs = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    return conns, msgs


def test_a_killed_bag_is_unreadable_by_rosbags_and_repaired(bags, capsys):
    killed, out = bags["killed"], bags["root"] / "fixed"
    with pytest.raises(Exception, match="metadata"):
        Reader(killed).open()
    assert cli.main(["bag", "repair", str(killed), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    kept = bags["written"][:KEPT * PER_CHUNK]  # every message of the complete chunks
    n = {t: sum(m[0] == t for m in kept) for t in TOPICS}
    assert len(lines) == 1
    assert f"recovered {len(kept)} messages" in lines[0]
    assert all(f"{t} {n[t]}" in lines[0] for t in TOPICS)
    conns, msgs = _plain(out)
    assert msgs == kept  # same topics, log times and CDR bytes, in order
    assert conns == _plain(bags["complete"])[0]  # same types, definitions and RIHS01 hashes
    with Reader(out) as reader:
        assert reader.message_count == len(kept) and reader.ros_distro == bagio.ROS_DISTRO
    with next(out.glob("*.mcap")).open("rb") as f:  # the mcap reader, through its index
        mcap = make_reader(f)
        assert mcap.get_summary() is not None
        got = [(c.topic, m.log_time, m.data) for _, c, m in mcap.iter_messages()]
    assert got == kept
    # the project's reader decodes the repaired bag as it decodes the killed one
    decoded = [(m.topic, m.t_ns) for m in bagio.read_bag(out)]
    assert decoded == [(m.topic, m.t_ns) for m in bagio.read_bag(killed)]


def test_default_output_is_next_to_the_bag_and_never_overwritten(bags, tmp_path, capsys):
    bag = tmp_path / "run"
    shutil.copytree(bags["killed"], bag)
    assert cli.main(["bag", "repair", str(bag)]) == 0
    assert (tmp_path / "run_repaired" / "metadata.yaml").is_file()
    capsys.readouterr()
    assert cli.main(["bag", "repair", str(bag)]) == 2  # like ros2 bag record
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "exists already" in err[0]
    # a bare .mcap works too, and a closed bag is copied whole
    mcap = next(bag.glob("*.mcap"))
    assert bagrepair.repaired_path(mcap) == bag / "killed_repaired"
    assert cli.main(["bag", "repair", str(bags["complete"]), "--out",
                     str(tmp_path / "copy")]) == 0
    assert "complete already" in capsys.readouterr().out
    assert _plain(tmp_path / "copy")[1] == bags["written"]


def _junk_mcap(d: Path) -> Path:
    d.mkdir()
    (d / "x.mcap").write_text("not an mcap file\n")
    return d


@pytest.mark.parametrize("make, says", [
    (lambda d: d / "nope", "no such bag"),
    (lambda d: (d / "empty").mkdir() or d / "empty", "no .mcap file"),
    (lambda d: (d / "a.txt").write_text("x") and d / "a.txt", "not a rosbag2 directory"),
    (lambda d: _junk_mcap(d / "junk"), "not an MCAP file"),
])
def test_errors_are_one_line_and_exit_2(tmp_path, capsys, make, says):
    assert cli.main(["bag", "repair", str(make(tmp_path))]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and says in err[0], err
    assert captured.out == ""
    assert not list(tmp_path.glob("*_repaired"))


def test_a_bag_killed_before_its_first_chunk_has_nothing_to_recover(bags, tmp_path, capsys):
    bag = tmp_path / "early"
    bag.mkdir()
    data = next(bags["killed"].glob("*.mcap")).read_bytes()
    (bag / "early.mcap").write_bytes(data[:200])  # header and part of the first chunk
    assert cli.main(["bag", "repair", str(bag)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no complete message to recover" in err[0]
    assert not (tmp_path / "early_repaired").exists()


def _chunk_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) offsets of the top-level chunk records of an MCAP file, in order."""
    spans, pos = [], 8
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            spans.append((pos, pos + 9 + length))
        pos += 9 + length
        if op == 0x02:
            break
    return spans


def _damaged(bags, tmp_path: Path, name: str, damage) -> tuple[Path, list[tuple[int, int]]]:
    """A copy of the complete bag with `damage(data, spans)` applied to its .mcap."""
    bag = tmp_path / name
    shutil.copytree(bags["complete"], bag)
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    spans = _chunk_spans(data)
    assert len(spans) == CHUNKS
    mcap.write_bytes(damage(data, spans))
    return bag, spans


def _kept_but(bags, lost_chunks: set[int]) -> list[tuple[str, int, bytes]]:
    """The messages written, without those of chunks `lost_chunks` (0-based)."""
    return [m for i, m in enumerate(bags["written"]) if i // PER_CHUNK not in lost_chunks]


ZSTD_AT = 9 + 28 + 4 + len("zstd") + 8
"""Offset of a chunk's compressed records from the chunk record's start (the zstd frame)."""


def _flip(data: bytes, spans: list[tuple[int, int]]) -> bytes:
    start, _ = spans[2]  # a byte of chunk 3's zstd frame header: zstd refuses the frame
    assert data[start + ZSTD_AT:start + ZSTD_AT + 4] == b"\x28\xb5\x2f\xfd"
    out = bytearray(data)
    out[start + ZSTD_AT + 1] ^= 0xFF
    return bytes(out)


def _insert(data: bytes, spans: list[tuple[int, int]]) -> bytes:
    at = len(data) // 3
    return data[:at] + np.random.default_rng(7).bytes(4096) + data[at:]


def _overwrite(data: bytes, spans: list[tuple[int, int]]) -> bytes:
    at = len(data) // 3
    return data[:at] + np.random.default_rng(8).bytes(4096) + data[at + 4096:]


@pytest.mark.parametrize("damage", [_flip, _insert, _overwrite])
def test_a_damaged_middle_loses_only_the_damaged_chunks(bags, tmp_path, capsys, damage):
    bag, spans = _damaged(bags, tmp_path, damage.__name__, damage)
    at = len(next(bags["complete"].glob("*.mcap")).read_bytes()) // 3
    hit = ({2} if damage is _flip else
           {i for i, (s, e) in enumerate(spans) if s <= at + 4096 and at < e})
    assert 1 <= len(hit) <= 2
    out = tmp_path / f"{damage.__name__}_fixed"
    assert cli.main(["bag", "repair", str(bag), "--out", str(out)]) == 0
    line = capsys.readouterr().out.strip()
    assert "\n" not in line and "lost" in line and "bytes" in line
    _, msgs = _plain(out)
    intact = _kept_but(bags, hit)
    assert set(intact) <= set(msgs)  # every message of every intact chunk, byte for byte
    assert set(msgs) <= set(bags["written"])  # and nothing made up
    assert len(msgs) < len(bags["written"])
    # the damaged chunk's time range is named (its header survives a flipped data byte)
    if damage is _flip:
        t0 = bags["written"][2 * PER_CHUNK][1] * 1e-9
        assert types_iso(t0)[:16] in line


def types_iso(t: float) -> str:
    from ssa_fusion.core.earth.timescales import iso

    return iso(t)


def test_a_flipped_byte_in_the_sample_bag_never_traces_back(tmp_path, capsys):
    """The sample bag with its middle byte flipped: repaired with every undamaged chunk.

    The writer stores no CRCs (rosbags writes 0), so a flip inside a chunk is found only
    when zstd refuses the data; either way the repair exits 0 and says what it lost.
    """
    sample = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
    bag = tmp_path / "sample"
    shutil.copytree(sample, bag)
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[len(data) // 2] ^= 0x01
    mcap.write_bytes(bytes(data))
    total = sum(1 for _ in bagio.read_bag(sample))
    assert cli.main(["bag", "repair", str(bag), "--out", str(tmp_path / "fixed")]) == 0
    line = capsys.readouterr().out.strip()
    assert "\n" not in line
    with Reader(tmp_path / "fixed") as reader:
        kept = reader.message_count
    largest_chunk = max(e - s for s, e in _chunk_spans(bytes(data)))
    assert kept >= total - largest_chunk  # at most one chunk's messages lost (a bound)
    assert kept > 0.9 * total


def test_a_flush_before_the_first_message_keeps_the_topics(tmp_path):
    """The recorder flushes on a timer: its first chunk may hold the schemas and channels
    and no message (no time range: rosbags writes start 2**63 - 1, end 0). A kill later
    must still give every topic back, with its messages."""
    classes, store = bagio.rosbags_classes(), bagio.typestore()
    writer = bagio.BagWriter(tmp_path / "quiet")
    for topic, msgtype in TOPICS.items():
        writer.add_topic(topic, msgtype)
    writer.flush()  # nothing heard yet
    written = []
    for i in range(PER_CHUNK):
        topic, msg = _message(i, classes, store)
        writer.write(topic, 1_700_000_000_000_000_000 + i, bytes(store.serialize_cdr(
            msg, TOPICS[topic])))
        written.append(topic)
    writer.flush()
    mcap = next((tmp_path / "quiet").glob("*.mcap"))
    killed = tmp_path / "killed"
    killed.mkdir()
    (killed / "killed.mcap").write_bytes(mcap.read_bytes())  # SIGKILL: no summary
    writer.close()
    assert [m.topic for m in bagio.read_bag(killed)] == written
