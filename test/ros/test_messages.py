"""Message conversions: the Measurement's shard key, and bags recorded before it existed."""

from pathlib import Path

import numpy as np

from ssa_fusion.core.base import types
from ssa_fusion.ros import bagio, messages


def test_shard_key_is_the_standard_crc32():
    """CRC-32 (IEEE 802.3)'s published check value: "123456789" -> 0xCBF43926."""
    assert messages.shard_key("123456789") == 0xCBF43926
    assert messages.shard_key("") == 0


def test_every_measurement_message_carries_its_shard_key():
    m = types.Measurement(1.7e9, np.array([7000.0, 1.0, 0.5]), np.eye(3), object_id="25544",
                          kind=types.Kind.RANGE_AZ_EL, frame_id="columbus")
    msg = messages.measurement_to_msg(m, bagio.rosbags_classes())
    assert msg.shard_key == messages.shard_key("25544")


def _bag_without_shard_key(path: Path) -> Path:
    """A bag of Measurement as it was defined before `shard_key` (its own stored definition)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    name = "ssa_fusion_msgs/msg/Measurement"
    text = "\n".join(line for line in (bagio._msg_dir() / "Measurement.msg").read_text()
                     .splitlines() if not line.startswith("uint32 shard_key"))
    store = get_typestore(Stores.ROS2_KILTED)
    store.register(get_types_from_msg(text, name))
    cls, header, stamp = (store.types[k] for k in (name, "std_msgs/msg/Header",
                                                   "builtin_interfaces/msg/Time"))
    msg = cls(header=header(stamp=stamp(sec=1735689600, nanosec=0), frame_id="columbus"),
              object_id="iss", kind=1, source=0, z=np.array([700.0e3, 1.0, 0.5]),
              covariance=np.eye(3).ravel(), horizon=0.0)
    bag = path / "old"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/ssa/measurement", name, typestore=store)
        w.write(conn, 1735689600 * 10**9, store.serialize_cdr(msg, name))
    return bag


def test_a_bag_recorded_before_the_shard_key_reads_and_recodes(tmp_path):
    """A bag of Measurement without `shard_key` is read with the definition stored in the
    bag, and `recode` brings it to the current type with the key filled in."""
    m = next(iter(bagio.read_bag(_bag_without_shard_key(tmp_path),
                                 topics=["/ssa/measurement"])))
    assert not hasattr(m.msg, "shard_key")
    new = messages.recode(m.msg, m.msgtype, bagio.rosbags_classes())
    assert new.shard_key == messages.shard_key(m.msg.object_id) != 0
    assert np.array_equal(new.z, m.msg.z) and new.header.frame_id == m.msg.header.frame_id
    same = messages.measurement_from_msg(new)
    assert same.t == messages.measurement_from_msg(m.msg).t
