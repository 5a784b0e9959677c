#!/usr/bin/env python3
"""Soak benchmark: the node for a long simulated time on RFT ground, driven by a DDS peer.

Starts `sandstep node` on the default robot scene with `terrain.model=rft` (no particles), so an
hour of simulated time takes minutes. A Cyclone DDS peer (this script; no ROS installation)
sends `gait/frequency` commands every COMMAND_INTERVAL_S of wall time, cycling through
COMMAND_HZ, and reads `/clock`. The node's resident memory (VmRSS) is sampled every
SAMPLE_INTERVAL_S of wall time. Prints one figure: the growth of resident memory after the first
simulated minute, in % of what it was then (issue 22: flat within 5 %), with the wall time, the
simulated time, the commands sent and the commands the node reports. `--csv` writes the samples.
The first minute is of wall time (SETTLED_AFTER_WALL_S).

Usage (from the crate directory, after `cargo build --release` and
`tests/python/setup_venv.sh`):

    target/py-venv/bin/python benches/soak.py [--sim-s 3600] [--bag DIR] [--csv FILE]

The node records a bag (to a temporary directory unless --bag): the writer is part of what
must not grow. DDS traffic stays on loopback, in domain --domain.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

CRATE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The ROS 2 wire types of the tests' DDS peer.
sys.path.insert(0, os.path.join(CRATE_DIR, "tests", "python"))
from dds_peer import Clock, Float64  # noqa: E402

CYCLONE_LOOPBACK = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
    "</Interfaces></General></Domain></CycloneDDS>"
)
# Gait frequencies the peer cycles through (Hz; negative walks backward, 0 stands).
COMMAND_HZ = [2.0, 1.0, -1.5, 0.0, 3.0]
# Wall time between two commands (s): the node's command timeout (node.command_timeout_s,
# simulated time) may lapse between them, so the node also falls back to its default gait.
COMMAND_INTERVAL_S = 0.5
# Wall time between two samples of the node's resident memory (s).
SAMPLE_INTERVAL_S = 1.0
# Wall time after which the memory is taken as settled (s): issue 22's "first minute". The
# node's resident memory grows by about 4 MiB over its first 30 s of wall time (DDS discovery
# and history caches filling while the peer reads and writes; without a peer it does not) and
# is flat after it (docs/ros.md, "Soak").
SETTLED_AFTER_WALL_S = 60.0
# The bound the figure is compared with (%).
FLAT_WITHIN_PERCENT = 5.0


def resident_kib(pid):
    """VmRSS of process `pid` (KiB), or None once it has exited."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except FileNotFoundError:
        return None
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim-s", type=float, default=3600.0, help="simulated time (s)")
    parser.add_argument("--binary", default=os.path.join(CRATE_DIR, "target/release/sandstep"))
    parser.add_argument("--scene", default=os.path.join(CRATE_DIR, "config/robot_on_sand.yaml"))
    parser.add_argument("--bag", help="bag directory (default: a temporary one, removed)")
    parser.add_argument("--no-bag", action="store_true", help="record no bag")
    parser.add_argument("--csv", help="write the samples (wall s, sim s, RSS KiB) here")
    parser.add_argument("--domain", type=int, default=211, help="ROS_DOMAIN_ID")
    args = parser.parse_args()

    tmp = tempfile.TemporaryDirectory(prefix="sandstep-soak-")
    bag = args.bag or os.path.join(tmp.name, "soak")
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain), CYCLONEDDS_URI=CYCLONE_LOOPBACK)
    node = subprocess.Popen(
        [args.binary, "node", args.scene, "--set", "terrain.model=rft",
         "--set", "node.loopback_only=true", "--duration", str(args.sim_s),
         "--json"] + (["--no-bag"] if args.no_bag else ["--bag", bag]),
        cwd=CRATE_DIR, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )

    os.environ.update(env)
    participant = DomainParticipant(args.domain)
    reliable = Policy.Reliability.Reliable(duration(seconds=1))
    clock_reader = DataReader(
        participant, Topic(participant, "rt/clock", Clock),
        qos=Qos(reliable, Policy.History.KeepLast(10)),
    )
    gait_writer = DataWriter(
        participant, Topic(participant, "rt/gait/frequency", Float64),
        qos=Qos(reliable, Policy.History.KeepLast(10)),
    )

    start = time.monotonic()
    samples = []  # (wall s, sim s, RSS KiB)
    sim_s, commands_sent = 0.0, 0
    next_sample, next_command = start, start
    while node.poll() is None:
        now = time.monotonic()
        for sample in clock_reader.take(N=100):
            sim_s = max(sim_s, sample.clock.sec + sample.clock.nanosec * 1e-9)
        if now >= next_command:
            gait_writer.write(Float64(data=COMMAND_HZ[commands_sent % len(COMMAND_HZ)]))
            commands_sent += 1
            next_command += COMMAND_INTERVAL_S
        if now >= next_sample:
            rss = resident_kib(node.pid)
            if rss is not None:
                samples.append((now - start, sim_s, rss))
                print(f"\r{now - start:7.0f} s wall  {sim_s:8.1f} s simulated  "
                      f"{rss / 1024:7.1f} MiB resident", end="", file=sys.stderr, flush=True)
            next_sample += SAMPLE_INTERVAL_S
        time.sleep(0.02)
    print(file=sys.stderr)
    stdout, stderr = node.communicate()
    wall_s = time.monotonic() - start
    if node.returncode != 0:
        sys.exit(f"the node exited with {node.returncode}:\n{stderr}")
    summary = json.loads(stdout.strip().splitlines()[-1])

    settled = [s for s in samples if s[0] >= SETTLED_AFTER_WALL_S]
    if len(settled) < 2:
        sys.exit(f"too few samples after {SETTLED_AFTER_WALL_S} s of wall time: {len(settled)}"
                 " (simulate longer)")
    at_settled = settled[0][2]
    peak = max(s[2] for s in settled)
    growth_percent = 100.0 * (peak - at_settled) / at_settled
    if args.csv:
        with open(args.csv, "w") as out:
            out.write("wall_s,sim_s,rss_kib\n")
            out.writelines(f"{w:.3f},{s:.3f},{r}\n" for w, s, r in samples)
    verdict = "flat" if growth_percent <= FLAT_WITHIN_PERCENT else "GROWS"
    print(f"soak: {summary.get('sim_time_s', sim_s):.0f} s simulated on RFT ground in "
          f"{wall_s:.0f} s wall ({summary.get('sim_time_s', sim_s) / wall_s:.1f}x real time); "
          f"{commands_sent} commands sent, {summary.get('commands_received')} received")
    print(f"resident memory: {samples[0][2] / 1024:.1f} MiB at the start, "
          f"{at_settled / 1024:.1f} MiB after {settled[0][0]:.0f} s wall ({settled[0][1]:.0f} s "
          "simulated), "
          f"peak after it {peak / 1024:.1f} MiB, last {settled[-1][2] / 1024:.1f} MiB: "
          f"growth {growth_percent:+.2f} % ({verdict}; bound {FLAT_WITHIN_PERCENT:.0f} %)")
    print(json.dumps({
        "sim_time_s": summary.get("sim_time_s"), "wall_time_s": wall_s,
        "commands_sent": commands_sent, "commands_received": summary.get("commands_received"),
        "rss_start_kib": samples[0][2], "rss_settled_kib": at_settled, "rss_peak_kib": peak, "rss_last_kib": settled[-1][2],
        "rss_growth_percent": growth_percent,
    }))


if __name__ == "__main__":
    main()
