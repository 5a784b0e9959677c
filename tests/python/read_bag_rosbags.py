"""Reads a bag directory with `rosbags.highlevel.AnyReader` (which uses its metadata.yaml).

Usage: read_bag_rosbags.py BAG_DIR

Prints one JSON line: the bag's message count and times, and per topic (connection) its type,
the message count metadata.yaml gives, the messages actually read (log time in ns and fields,
deserialised with the bag's own definitions), the type hash the bag records and the one rosbags
computes from its ROS 2 Jazzy definitions, and the offered QoS durabilities.
Exits non-zero with the reason on stderr if the bag does not open or a message does not decode.
"""

from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from bag_check_common import plain, run


def main(argv):
    (bag_dir,) = argv
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    topics = {}
    with AnyReader([Path(bag_dir)]) as reader:
        for conn in reader.connections:
            if conn.topic in topics:
                raise RuntimeError(f"topic {conn.topic} has several connections")
            messages = []
            for _, timestamp, raw in reader.messages(connections=[conn]):
                msg = reader.deserialize(raw, conn.msgtype)
                messages.append({"log_time": timestamp, "msg": plain(msg)})
            topics[conn.topic] = {
                "type": conn.msgtype,
                "metadata_count": conn.msgcount,
                "digest": conn.digest,
                "jazzy_digest": (
                    jazzy.hash_rihs01(conn.msgtype) if conn.msgtype in jazzy.fielddefs else None
                ),
                "durabilities": [
                    q.durability.name.lower() for q in conn.ext.offered_qos_profiles
                ],
                "messages": messages,
            }
        result = {
            "reader": "rosbags",
            "message_count": reader.message_count,
            "start_time": reader.start_time,
            "end_time": reader.end_time,
            "topics": topics,
        }
    return result


if __name__ == "__main__":
    run(main)
