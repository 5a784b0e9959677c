"""Helpers shared by the bag-reading scripts: plain JSON values and failing clearly."""

import dataclasses
import json
import sys
import traceback


def plain(value):
    """A decoded ROS message (mcap_ros2 slots object or rosbags dataclass) as JSON-able data."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # rosbags classes also carry `__msgtype__`: not a message field.
        return {
            f.name: plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.name.startswith("__")
        }
    if hasattr(value, "__slots__") and not isinstance(value, (str, bytes)):
        return {name: plain(getattr(value, name)) for name in value.__slots__}
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return plain(value.tolist())
    if isinstance(value, (bytes, bytearray, memoryview)):
        return list(bytes(value))
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def run(main):
    """Runs `main(argv)`, prints its result as one JSON line; exits 1 with the reason on failure."""
    try:
        result = main(sys.argv[1:])
    except Exception as exc:  # noqa: BLE001 - any failure fails the check, with its trace
        traceback.print_exc()
        print(f"FAILED: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
    print(json.dumps(result))
