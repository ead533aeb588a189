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
