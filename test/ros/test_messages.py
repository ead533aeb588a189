"""Message conversions: the Measurement's shard key, and bags recorded before it existed."""

from pathlib import Path

import numpy as np

from ssa_fusion.core import types
from ssa_fusion.ros import bagio, messages

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"


def test_shard_key_is_the_standard_crc32():
    """CRC-32 (IEEE 802.3)'s published check value: "123456789" -> 0xCBF43926."""
    assert messages.shard_key("123456789") == 0xCBF43926
    assert messages.shard_key("") == 0


def test_every_measurement_message_carries_its_shard_key():
    m = types.Measurement(1.7e9, np.array([7000.0, 1.0, 0.5]), np.eye(3), object_id="25544",
                          kind=types.Kind.RANGE_AZ_EL, frame_id="columbus")
    msg = messages.measurement_to_msg(m, bagio.rosbags_classes())
    assert msg.shard_key == messages.shard_key("25544")


def test_a_bag_recorded_before_the_shard_key_reads_and_recodes():
    """The sample bag holds Measurement without `shard_key`: it is read with the definition
    stored in the bag, and `recode` brings it to the current type with the key filled in."""
    m = next(iter(bagio.read_bag(SAMPLE, topics=["/ssa/measurement"])))
    assert not hasattr(m.msg, "shard_key")
    new = messages.recode(m.msg, m.msgtype, bagio.rosbags_classes())
    assert new.shard_key == messages.shard_key(m.msg.object_id) != 0
    assert np.array_equal(new.z, m.msg.z) and new.header.frame_id == m.msg.header.frame_id
    same = messages.measurement_from_msg(new)
    assert same.t == messages.measurement_from_msg(m.msg).t
