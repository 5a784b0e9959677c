"""An independent ROS 2 peer on Eclipse Cyclone DDS (no ROS installation).

Reads /clock, /joint_states and /odom from the sandstep node for a while, then publishes
/gait/frequency = COMMAND_HZ for a while, and prints one JSON line with what it saw.

Usage: dds_peer.py <forward_s> <command_s> <command_hz>
Environment: ROS_DOMAIN_ID (the test's domain), CYCLONEDDS_URI (loopback only).
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
import cyclonedds.idl.types as t
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

# ROS 2 wire type names; @final so that Cyclone writes plain CDR (XCDR1), as RustDDS expects.


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@final
@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


@final
@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: t.sequence[str]
    position: t.sequence[t.float64]
    velocity: t.sequence[t.float64]
    effort: t.sequence[t.float64]


@final
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@final
@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@final
@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@final
@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: t.array[t.float64, 36]


@final
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@final
@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@final
@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: t.array[t.float64, 36]


@final
@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@final
@dataclass
class Float64(IdlStruct, typename="std_msgs::msg::dds_::Float64_"):
    data: t.float64


def stamp(h):
    return h.sec + h.nanosec * 1e-9


def main():
    forward_s, command_s, command_hz = float(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
    domain = int(os.environ["ROS_DOMAIN_ID"])
    dp = DomainParticipant(domain)
    reader_qos = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.History.KeepLast(100),
    )
    readers = {
        name: DataReader(dp, Topic(dp, "rt/" + name, ty), qos=reader_qos)
        for name, ty in [("clock", Clock), ("joint_states", JointState), ("odom", Odometry)]
    }
    writer = DataWriter(
        dp,
        Topic(dp, "rt/gait/frequency", Float64),
        qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10)),
    )
    seen = {"clock": [], "joint_states": [], "odom": []}

    def poll(seconds, publish=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if publish is not None:
                writer.write(Float64(data=publish))
            for name, reader in readers.items():
                for sample in reader.take(N=100):
                    seen[name].append(sample)
            time.sleep(0.05)

    poll(forward_s)
    marks = {name: len(samples) for name, samples in seen.items()}
    poll(command_s, publish=command_hz)

    odom = [(stamp(m.header.stamp), m.pose.pose.position.x, m.pose.pose.position.z) for m in seen["odom"]]
    joints = seen["joint_states"]
    clock = [stamp(m.clock) for m in seen["clock"]]
    before = odom[: marks["odom"]]
    after = odom[marks["odom"]:]

    def speed(samples):
        if len(samples) < 2 or samples[-1][0] <= samples[0][0]:
            return None
        return (samples[-1][1] - samples[0][1]) / (samples[-1][0] - samples[0][0])

    print(json.dumps({
        "counts": {name: len(samples) for name, samples in seen.items()},
        "clock_increasing": all(b > a for a, b in zip(clock, clock[1:])),
        "clock_last_s": clock[-1] if clock else None,
        "joint_names": list(joints[-1].name) if joints else [],
        "joint_lengths_ok": all(len(j.name) == len(j.position) == len(j.velocity) == len(j.effort) for j in joints),
        "odom_frame": seen["odom"][-1].header.frame_id if odom else None,
        "odom_child": seen["odom"][-1].child_frame_id if odom else None,
        "body_height_m": odom[-1][2] if odom else None,
        "speed_before_m_s": speed(before),
        "speed_after_m_s": speed(after[len(after) // 3:]),
    }))


if __name__ == "__main__":
    main()
