"""Where the sand pushes on the legs over a gait cycle, from sandstep bags (docs/robot.md,
"Where the sand pushes on the legs").

Reads each bag's /leg_wrenches/<leg> and /body_wrench (the sand's mean force on each leg and
on the body over each 10 ms interval, in the link's frame), /tf (body pose in odom, each leg
link in base_link) and /joint_states, from START seconds on, and prints per bag:

- lift: the time mean of the legs' vertical (odom z) force, summed over the six legs, in units
  of the robot's weight W (0.085 kg x 9.81 m/s^2);
- body, body x: the same for the sand's vertical force on the body and its force along odom
  x, the walking direction (a negative one is drag) (/body_wrench, recorded since 2026-12-07;
  absent from older bags); lift + body = 1 and thrust + body x = 0 on average for a robot that
  walks steadily (Newton's second law; tests/terrain_wrenches.rs pins the first for a robot
  standing);
- thrust: the time mean of the legs' force along odom x, summed, in W;
- the mean vertical force on one leg (in W) by the leg's own joint angle, in 30 deg bins:
  angle 0 = the leg pointing straight down from its hip (docs/robot.md, leg frame), positive
  angles turn its lower half backwards, so the stance runs from about -90 (270) to +90 deg;
- roll: the root mean square and 95th percentile of the moment of the legs' forces along the
  body's z axis about its mid-plane (sum of base_link F_z times the hip's base_link y), in W x
  2.5 cm (the committed robot's hip offset), i.e. relative to the largest restoring moment of
  the body's weight over a foot 2.5 cm from the mid-plane.

Usage, with the Python readers of the tests (tests/python/setup_venv.sh prints the venv's
python):

    $(tests/python/setup_venv.sh) docs/experiment/leg_forces_by_angle.py START BAG...
"""

import collections
import glob
import math
import sys

import numpy as np
from mcap_ros2.reader import read_ros2_messages

WEIGHT_N = 0.085 * 9.81
HIP_OFFSET_M = 0.025
BINS = 12


def rotate(q, v):
    """Rotates v by the unit quaternion q = (x, y, z, w)."""
    u = np.array(q[:3])
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + q[3] * v)


def samples(bag):
    """(t, link, force along odom z and x (N), joint angle rad, hip y m, force along base_link
    z (N)) per wrench; the body's as link "base_link" with angle, hip y and the last None."""
    path = glob.glob(bag.rstrip("/") + "/*.mcap")[0]
    body_q = None
    leg_q, hip_y, angle = {}, {}, {}
    first = None
    for m in read_ros2_messages(path):
        topic, msg = m.channel.topic, m.ros_msg
        if topic == "/tf":
            for tr in msg.transforms:
                r = tr.transform.rotation
                q = (r.x, r.y, r.z, r.w)
                if tr.child_frame_id == "base_link":
                    body_q = q
                elif tr.header.frame_id == "base_link":
                    leg_q[tr.child_frame_id] = q
                    hip_y[tr.child_frame_id] = tr.transform.translation.y
        elif topic == "/joint_states":
            for name, position in zip(msg.name, msg.position):
                angle[name.removesuffix("_joint")] = position
        elif topic == "/body_wrench" and body_q is not None:
            t = m.log_time_ns * 1e-9
            first = t if first is None else first
            f = msg.wrench.force
            in_odom = rotate(body_q, [f.x, f.y, f.z])
            yield t - first, "base_link", in_odom[2], in_odom[0], None, None, None
        elif topic.startswith("/leg_wrenches/"):
            leg = topic.rsplit("/", 1)[1]
            t = m.log_time_ns * 1e-9
            first = t if first is None else first
            if body_q is None or leg not in leg_q or leg not in angle:
                continue
            f = msg.wrench.force
            in_body = rotate(leg_q[leg], [f.x, f.y, f.z])
            in_odom = rotate(body_q, in_body)
            yield t - first, leg, in_odom[2], in_odom[0], angle[leg], hip_y[leg], in_body[2]


def report(bag, start_s):
    rows = [r for r in samples(bag) if r[0] >= start_s]
    body_rows = [r for r in rows if r[1] == "base_link"]
    rows = [r for r in rows if r[1] != "base_link"]
    body, body_x = (
        (sum(r[i] for r in body_rows) / len(body_rows) / WEIGHT_N for i in (2, 3))
        if body_rows
        else (float("nan"), float("nan"))
    )
    legs = sorted({r[1] for r in rows})
    count = collections.Counter(r[1] for r in rows)
    lift = sum(r[2] / count[r[1]] for r in rows) / WEIGHT_N
    thrust = sum(r[3] / count[r[1]] for r in rows) / WEIGHT_N
    by_bin, in_bin = np.zeros(BINS), np.zeros(BINS)
    moment = collections.defaultdict(float)
    for t, _, vertical, _, joint_angle, y, body_z in rows:
        b = int((joint_angle % (2 * math.pi)) / (2 * math.pi) * BINS) % BINS
        by_bin[b] += vertical
        in_bin[b] += 1
        moment[round(t, 6)] += body_z * y
    roll = np.abs(np.array(list(moment.values()))) / (WEIGHT_N * HIP_OFFSET_M)
    profile = " ".join(
        "%+.2f" % (by_bin[i] / in_bin[i] / WEIGHT_N) if in_bin[i] else "  nan" for i in range(BINS)
    )
    print(
        "%s: %d legs, lift %.2f W, body %.2f W, thrust %.2f W, body x %+.2f W, roll rms %.2f p95 %.2f"
        % (bag, len(legs), lift, body, thrust, body_x, math.sqrt((roll**2).mean()), np.percentile(roll, 95))
    )
    print("  vertical force per leg (W) by angle from", " ".join("%5d" % (i * 30) for i in range(BINS)))
    print("  " + " " * 41 + profile)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    for bag in sys.argv[2:]:
        report(bag, float(sys.argv[1]))
