"""Reads a bag's MCAP file(s) with the `mcap` and `mcap-ros2-support` packages.

Usage: read_bag_mcap.py BAG_DIR

Decodes every message of every topic and prints one JSON line: the file profile, and per
topic the schema name, message encoding, channel metadata and every message (log time in ns
and fields). Exits non-zero with the reason on stderr if anything does not read or decode.
"""

from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages

from bag_check_common import plain, run


def main(argv):
    (bag_dir,) = argv
    files = sorted(Path(bag_dir).glob("*.mcap"))
    if not files:
        raise RuntimeError(f"no .mcap file in {bag_dir}")
    profiles = []
    topics = {}
    for path in files:
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            profiles.append(reader.get_header().profile)
            summary = reader.get_summary()
            if summary is None:
                raise RuntimeError(f"{path}: no summary section")
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                topics.setdefault(
                    channel.topic,
                    {
                        "schema": schema.name if schema else None,
                        "schema_encoding": schema.encoding if schema else None,
                        "encoding": channel.message_encoding,
                        "metadata": dict(channel.metadata),
                        "messages": [],
                    },
                )
        for message in read_ros2_messages(str(path), log_time_order=True):
            topic = topics[message.channel.topic]
            topic["messages"].append(
                {"log_time": message.log_time_ns, "msg": plain(message.ros_msg)}
            )
    return {"reader": "mcap", "profiles": profiles, "topics": topics}


if __name__ == "__main__":
    run(main)
