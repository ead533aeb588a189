"""`bagio`: reading a rosbag2 directory (topic selection, the sample bag) and writing one (a
full disk, the chunks' zstd level)."""

from pathlib import Path

from ssa_fusion.ros import bagio

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"


def test_topics_select_and_a_topic_the_bag_lacks_gives_nothing():
    every = {m.topic for m in bagio.read_bag(SAMPLE)}
    assert {"/clock", "/ssa/estimate"} <= every
    assert {m.topic for m in bagio.read_bag(SAMPLE, topics=["/ssa/estimate"])} == \
        {"/ssa/estimate"}
    # rosbags reads every connection when given none: asking for a topic the bag lacks
    # must not return the others
    assert list(bagio.read_bag(SAMPLE, topics=["/ssa/estimate_batch"])) == []


def test_a_disk_too_full_for_the_next_message_leaves_a_whole_bag(tmp_path, monkeypatch):
    """The writer asks the disk (statvfs) before a message would leave too little room to
    close the bag: it raises BagFullError (ENOSPC) with nothing of that message written, and the
    bag then closes whole: metadata.yaml, the MCAP summary, every message before, readable
    by `rosbags`' own Reader without any repair."""
    import errno
    import os

    import pytest
    from rosbags.rosbag2 import Reader

    real = os.statvfs
    free = {"bytes": 400_000}

    class Fs:
        f_frsize = 4096

        @property
        def f_bavail(self) -> int:
            return free["bytes"] // 4096

    monkeypatch.setattr(bagio.os, "statvfs", lambda p: Fs())
    bag = tmp_path / "bag"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/raw", "std_msgs/msg/String")
    text = bagio.typestore().types["std_msgs/msg/String"]
    payload = os.urandom(6000).hex()  # 12 kB that zstd cannot shrink much
    written = 0
    with pytest.raises(bagio.BagFullError) as full:
        for k in range(1000):
            writer.write_msg("/ssa/raw", 1_000_000_000 * (k + 1), text(data=payload))
            written += 1
            used = sum(f.stat().st_size for f in bag.iterdir())
            free["bytes"] = 400_000 - used - 12_000 * len(writer._writer.storage.chunk.msgs.get(
                writer._connections["/ssa/raw"].id, []))  # the chunk held in memory too
    assert full.value.errno == errno.ENOSPC
    assert "No space left on device" in str(full.value)
    # the room kept for closing: less than the disk's 400 kB went to messages
    assert 10 < written < 400_000 // 12_000, written
    assert writer.counts["/ssa/raw"] == written
    writer.close()
    monkeypatch.setattr(bagio.os, "statvfs", real)
    with Reader(bag) as reader:  # a whole bag: rosbags opens it as it is
        assert reader.message_count == written
        assert [ts for _, ts, _ in reader.messages()] == [
            1_000_000_000 * (k + 1) for k in range(written)]
    assert sum(1 for _ in bagio.read_bag(bag)) == written


def test_a_recording_short_of_what_was_heard_is_an_error(tmp_path, capsys):
    """`ros.processes.recorded_short` counts the bag's messages per topic against a probe's."""
    from ssa_fusion.ros.processes import recorded_short

    bag = tmp_path / "bag"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/raw", "std_msgs/msg/String")
    text = bagio.typestore().types["std_msgs/msg/String"]
    for k in range(3):
        writer.write_msg("/ssa/raw", 1_000_000_000 * (k + 1), text(data="ab" * k))
    writer.close()
    assert not recorded_short(bag, {"/ssa/raw": 3})
    assert not recorded_short(bag, {"/ssa/raw": 2})  # a probe that joined late
    assert capsys.readouterr().err == ""
    assert recorded_short(bag, {"/ssa/raw": 4})
    assert "/ssa/raw: 3 recorded of 4 published" in capsys.readouterr().err
    assert not recorded_short(bag, {"/ssa/raw": 6}, rows=lambda m: len(m.data))  # 0+2+4 rows
    assert recorded_short(bag, {"/ssa/raw": 7}, rows=lambda m: len(m.data))
    assert "6 recorded of 7" in capsys.readouterr().err


def test_chunks_are_zstd_at_the_writers_level(tmp_path):
    """Every chunk of a written bag is its records compressed by zstd at `ZSTD_LEVEL` (not
    the library's default 3), and `mcap`'s own reader reads the messages back."""
    from mcap.reader import make_reader
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    from rosbags.rosbag2.storage_mcap import zstd

    bag = tmp_path / "bag"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/raw", "std_msgs/msg/String")
    text = bagio.typestore().types["std_msgs/msg/String"]
    for k in range(200):
        writer.write_msg("/ssa/raw", k + 1, text(data=f"object {k % 7} at {k * 0.37:.3f} km"))
        if k % 50 == 49:
            writer.flush()
    writer.close()
    (path,) = bag.glob("*.mcap")
    with path.open("rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    assert len(chunks) == 4 and all(c.compression == "zstd" for c in chunks)
    for c in chunks:
        records = zstd.decompress(c.data)
        assert c.data == zstd.compress(records, level=bagio.ZSTD_LEVEL)
        assert c.data != zstd.compress(records)  # the default level's frame differs
    with path.open("rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == 200
