#!/usr/bin/env python3
"""A Unitree G1's low-level DDS bus played with CycloneDDS 0.10.2, the other side of the wire
for upc's DDS participant (src/bus/dds.rs, rustdds) in the DDS bus tests.

An independent implementation, for tests: the IDL types are declared here with CycloneDDS's
Python binding (its own CDR), the C-struct image and the CRC are written here from Unitree's
description, and nothing comes from upc's Rust code. Run it with the robot venv's python
(scripts/setup.sh builds cyclonedds 0.10.2 there against Debian's libddsc); standard library
and cyclonedds only.

Subcommands (all on --domain, default 1):
  robot     plays the G1: publishes rt/lowstate (LowState_) at --rate, a fixed posture (q of
            joint i 0.01 i, IMU level, 9.81 up), tick n*1000/rate ms for the nth state, sealed
            with its CRC; or broken on purpose: --bad-crc-every N (the Nth states' crc
            inverted), --stale-every N (the Nth states carry the previous tick), --zero-crc
            (crc and tick 0). Takes rt/lowcmd (LowCmd_), checks every command's CRC, writes
            --report (JSON).
  listen    reads rt/joint_states (JointState_) and rt/hand_wrench (WrenchStamped_) and writes
            --report: counts, the first JointState's names and positions, the first wrench.
  talk-cmd  a second controller on rt/lowcmd: sealed LowCmd_ (every slot mode 1, kp 0, kd 1).

Network: loopback only. Unless the caller set CYCLONEDDS_URI, scripts/cyclone-loopback.xml is
used: interface 127.0.0.1, multicast off, unicast discovery of the peer 127.0.0.1. QoS is
Unitree's: writers Reliable, KeepLast(1), Volatile; readers BestEffort, KeepLast(1).

CRC: CRC-32, polynomial 0x04C11DB7, initial 0xFFFFFFFF, no reflection, no final XOR, over the
message's C-struct image (little endian, natural C alignment, nested structs aligned to 4 and
padded to a multiple of 4: LowCmd_ 1004 bytes, LowState_ 2092) read as u32 words, the last word
(the crc itself) excluded, each word fed from bit 31 down to bit 0.

Report of `robot` (JSON): domain, rate_hz, duration_s, options, states_sent, achieved_rate_hz,
commands_received, commands_crc_ok, commands_crc_bad, first_command_s, mode_machine_seen,
max_abs_tau (slots 0..28), max_abs_torque_implied (tau + kp(q-q_state) + kd(dq-dq_state) of
enabled slots), over_effort_limit (with --effort-limit), latency_ms (publish of a state to the
first command after it: count, p50, p99, max), commands (one per command: t since start, crc_ok,
mode_machine, tick of the latest state published before it, mode, q, dq, tau, kp, kd of slots
0..28). Floats are rounded to 6 decimals.
"""

import argparse
import array as pyarray
import binascii
import json
import math
import os
import struct
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.core import Listener
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int16, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

LOOPBACK_XML = Path(__file__).resolve().parent / "cyclone-loopback.xml"
SLOTS, BODY_JOINTS = 35, 29
HG = "unitree_hg::msg::dds_::"

# --- IDL ------------------------------------------------------------------------------------

@dataclass
class IMUState_(IdlStruct, typename=HG + "IMUState_"):
    quaternion: array[float32, 4]  # w x y z
    gyroscope: array[float32, 3]
    accelerometer: array[float32, 3]
    rpy: array[float32, 3]
    temperature: int16

@dataclass
class MotorState_(IdlStruct, typename=HG + "MotorState_"):
    mode: uint8
    q: float32
    dq: float32
    ddq: float32
    tau_est: float32
    temperature: array[int16, 2]
    vol: float32
    sensor: array[uint32, 2]
    motorstate: uint32
    reserve: array[uint32, 4]

@dataclass
class LowState_(IdlStruct, typename=HG + "LowState_"):
    version: array[uint32, 2]
    mode_pr: uint8
    mode_machine: uint8
    tick: uint32
    imu_state: IMUState_
    motor_state: array[MotorState_, 35]
    wireless_remote: array[uint8, 40]
    reserve: array[uint32, 4]
    crc: uint32

@dataclass
class MotorCmd_(IdlStruct, typename=HG + "MotorCmd_"):
    mode: uint8
    q: float32
    dq: float32
    tau: float32
    kp: float32
    kd: float32
    reserve: uint32

@dataclass
class LowCmd_(IdlStruct, typename=HG + "LowCmd_"):
    mode_pr: uint8
    mode_machine: uint8
    motor_cmd: array[MotorCmd_, 35]
    reserve: array[uint32, 4]
    crc: uint32

@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32

@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str

@dataclass
class JointState_(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header_
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]

@dataclass
class Vector3_(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64

@dataclass
class Wrench_(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    force: Vector3_
    torque: Vector3_

@dataclass
class WrenchStamped_(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    header: Header_
    wrench: Wrench_


# --- C-struct images and CRC ----------------------------------------------------------------

# Explicit padding ('x') where C would put it: u8 then 3 pad bytes before a float, the IMU's
# trailing i16 padded to 4, mode_pr/mode_machine padded to the u32 that follows.
MOTOR_CMD_C = "B3x" "5f" "I"                     # mode | q dq tau kp kd | reserve: 28 bytes
MOTOR_STATE_C = "B3x" "4f" "2h" "f" "2I" "I" "4I"  # 56 bytes
IMU_STATE_C = "4f" "3f" "3f" "3f" "h2x"           # 56 bytes
LOW_CMD_C = struct.Struct("<BB2x" + MOTOR_CMD_C * SLOTS + "4I" "I")
LOW_STATE_C = struct.Struct("<2I" "BB2x" "I" + IMU_STATE_C + MOTOR_STATE_C * SLOTS
                            + "40B" "4I" "I")
assert struct.calcsize("<" + MOTOR_CMD_C) == 28 and struct.calcsize("<" + MOTOR_STATE_C) == 56
assert LOW_CMD_C.size == 1004 and LOW_STATE_C.size == 2092


def low_cmd_image(m):
    v = [m.mode_pr, m.mode_machine]
    for c in m.motor_cmd:
        v += (c.mode, c.q, c.dq, c.tau, c.kp, c.kd, c.reserve)
    return LOW_CMD_C.pack(*v, *m.reserve, m.crc)


def low_state_image(m):
    i = m.imu_state
    v = [*m.version, m.mode_pr, m.mode_machine, m.tick, *i.quaternion, *i.gyroscope,
         *i.accelerometer, *i.rpy, i.temperature]
    for s in m.motor_state:
        v += (s.mode, s.q, s.dq, s.ddq, s.tau_est, *s.temperature, s.vol, *s.sensor,
              s.motorstate, *s.reserve)
    return LOW_STATE_C.pack(*v, *m.wireless_remote, *m.reserve, m.crc)


POLY = 0x04C11DB7
REV8 = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))
assert pyarray.array("I").itemsize == 4


def crc_words(data):
    """The CRC of the module docstring over data (a multiple of 4 bytes), computed with zlib's
    reflected CRC-32 (same polynomial, mirrored): fed every word bit-reversed, its register is
    ours bit-reversed; its initial value is ours and its final XOR is undone here."""
    words = pyarray.array("I", data.translate(REV8))  # every byte bit-reversed...
    words.byteswap()  # ...and the bytes of every word reversed: each word bit-reversed
    return int(f"{binascii.crc32(words.tobytes()) ^ 0xFFFFFFFF:032b}"[::-1], 2)


def crc_words_bitwise(data):
    """The same CRC bit by bit, the plain definition (checks crc_words at start-up)."""
    crc = 0xFFFFFFFF
    for (word,) in struct.iter_unpack("<I", data):
        for bit in range(31, -1, -1):
            top = (crc >> 31) ^ ((word >> bit) & 1)
            crc = (crc << 1) & 0xFFFFFFFF
            if top:
                crc ^= POLY
    return crc


_probe = bytes(range(7, 7 + 48))
assert crc_words(_probe) == crc_words_bitwise(_probe)


def image_crc(image):
    return crc_words(image[:-4])


# --- Messages, QoS, participant -------------------------------------------------------------


def low_state(mode_machine):
    def motor(i):
        q = 0.01 * i if i < BODY_JOINTS else 0.0
        return MotorState_(mode=0, q=q, dq=0.0, ddq=0.0, tau_est=0.0, temperature=[0, 0],
                           vol=0.0, sensor=[0, 0], motorstate=0, reserve=[0] * 4)
    imu = IMUState_(quaternion=[1.0, 0.0, 0.0, 0.0], gyroscope=[0.0] * 3,
                    accelerometer=[0.0, 0.0, 9.81], rpy=[0.0] * 3, temperature=0)
    return LowState_(version=[0, 0], mode_pr=0, mode_machine=mode_machine, tick=0,
                     imu_state=imu, motor_state=[motor(i) for i in range(SLOTS)],
                     wireless_remote=[0] * 40, reserve=[0] * 4, crc=0)


def writer_qos():
    return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               Policy.History.KeepLast(1), Policy.Durability.Volatile)


def reader_qos(depth=1):
    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(depth),
               Policy.Durability.Volatile)


def participant(domain):
    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK_XML.as_uri())
    return DomainParticipant(domain)


def r6(x):
    return round(x, 6) if math.isfinite(x) else str(x)


def r6s(xs):
    return [r6(x) for x in xs]


def percentile(sorted_xs, p):
    """Nearest rank."""
    return sorted_xs[max(0, math.ceil(p * len(sorted_xs)) - 1)] if sorted_xs else None


def ms(seconds):
    return None if seconds is None else r6(1e3 * seconds)


def write_json(path, doc):
    Path(path).write_text(json.dumps(doc, separators=(",", ":")) + "\n")


# --- robot ----------------------------------------------------------------------------------


class CommandLog:
    """What rt/lowcmd brought, filled from CycloneDDS's receive thread (a listener)."""

    def __init__(self, t0, q_state, effort_limit):
        self.lock = threading.Lock()
        self.t0, self.q_state, self.effort_limit = t0, q_state, effort_limit
        self.tick = None  # of the latest state published
        self.published_at = None
        self.answered = True  # whether a command came since that state
        self.closed = False
        self.records, self.latencies = [], []
        self.max_tau = [0.0] * BODY_JOINTS
        self.max_implied = [0.0] * BODY_JOINTS
        self.over_tau = self.over_implied = 0

    def published(self, tick, at):
        with self.lock:
            self.tick, self.published_at, self.answered = tick, at, False

    def on_data_available(self, reader):
        now = time.monotonic()
        for m in reader.take(N=64):
            if isinstance(m, LowCmd_):
                self.add(m, now)

    def add(self, m, now):
        crc_ok = image_crc(low_cmd_image(m)) == m.crc
        cmds = m.motor_cmd[:BODY_JOINTS]
        tau = [c.tau for c in cmds]
        implied = [c.tau + c.kp * (c.q - q) + c.kd * c.dq if c.mode else 0.0
                   for c, q in zip(cmds, self.q_state)]
        rec = {"t": r6(now - self.t0), "crc_ok": crc_ok, "mode_machine": m.mode_machine,
               "tick": None, "mode": [c.mode for c in cmds], "q": r6s(c.q for c in cmds),
               "dq": r6s(c.dq for c in cmds), "tau": r6s(tau), "kp": r6s(c.kp for c in cmds),
               "kd": r6s(c.kd for c in cmds)}
        with self.lock:
            if self.closed:
                return
            rec["tick"] = self.tick
            if not self.answered:
                self.latencies.append(now - self.published_at)
                self.answered = True
            self.records.append(rec)
            self.max_tau = [max(a, abs(b)) for a, b in zip(self.max_tau, tau)]
            self.max_implied = [max(a, abs(b)) for a, b in zip(self.max_implied, implied)]
            if self.effort_limit is not None:
                self.over_tau += any(abs(x) > self.effort_limit for x in tau)
                self.over_implied += any(abs(x) > self.effort_limit for x in implied)


def run_robot(a):
    dp = participant(a.domain)
    state = low_state(a.mode_machine)
    q_state = [s.q for s in state.motor_state[:BODY_JOINTS]]
    writer = DataWriter(dp, Topic(dp, "rt/lowstate", LowState_), qos=writer_qos())
    t0 = time.monotonic()
    log = CommandLog(t0, q_state, a.effort_limit)
    reader = DataReader(dp, Topic(dp, "rt/lowcmd", LowCmd_), qos=reader_qos(),  # noqa: F841
                        listener=Listener(on_data_available=log.on_data_available))
    step, period = max(1, round(1000 / a.rate)), 1.0 / a.rate
    n, deadline = 0, t0
    while time.monotonic() - t0 < a.duration:
        n += 1
        stale = a.stale_every and n % a.stale_every == 0
        state.tick = 0 if a.zero_crc else (n - 1 if stale else n) * step
        state.crc = 0
        if not a.zero_crc:
            state.crc = image_crc(low_state_image(state))
            if a.bad_crc_every and n % a.bad_crc_every == 0:
                state.crc ^= 0xFFFFFFFF
        log.published(state.tick, time.monotonic())
        writer.write(state)
        deadline = max(deadline + period, time.monotonic() - period)
        time.sleep(max(0.0, deadline - time.monotonic()))
    elapsed = time.monotonic() - t0
    with log.lock:
        log.closed = True  # commands arriving from now on are not counted
        recs, lat = list(log.records), sorted(log.latencies)
        report = {
            "domain": a.domain, "rate_hz": a.rate, "duration_s": a.duration,
            "options": {"bad_crc_every": a.bad_crc_every, "stale_every": a.stale_every,
                        "zero_crc": a.zero_crc, "mode_machine": a.mode_machine,
                        "effort_limit": a.effort_limit, "tick_step_ms": step},
            "states_sent": n, "achieved_rate_hz": r6(n / elapsed),
            "commands_received": len(recs),
            "commands_crc_ok": sum(r["crc_ok"] for r in recs),
            "commands_crc_bad": sum(not r["crc_ok"] for r in recs),
            "first_command_s": recs[0]["t"] if recs else None,
            "mode_machine_seen": sorted({r["mode_machine"] for r in recs}),
            "max_abs_tau": r6s(log.max_tau), "max_abs_torque_implied": r6s(log.max_implied),
            "over_effort_limit": None if a.effort_limit is None else
            {"tau": log.over_tau, "implied": log.over_implied},
            "latency_ms": {"count": len(lat), "p50": ms(percentile(lat, 0.5)),
                           "p99": ms(percentile(lat, 0.99)), "max": ms(lat[-1] if lat else None)},
            "commands": recs,
        }
    write_json(a.report, report)
    return 0


# --- listen, talk-cmd -----------------------------------------------------------------------


def stamped(m, t0, **fields):
    h = m.header
    return {"t": r6(time.monotonic() - t0), "frame_id": h.frame_id,
            "stamp": [h.stamp.sec, h.stamp.nanosec], **fields}


def run_listen(a):
    dp = participant(a.domain)
    joints = DataReader(dp, Topic(dp, "rt/joint_states", JointState_), qos=reader_qos(256))
    wrench = DataReader(dp, Topic(dp, "rt/hand_wrench", WrenchStamped_), qos=reader_qos(256))
    got = {"joint_states_received": 0, "hand_wrench_received": 0, "joint_names": None,
           "joint_positions": None, "first_joint_state": None, "first_wrench": None}
    t0 = time.monotonic()
    while time.monotonic() - t0 < a.duration:
        for m in (m for m in joints.take(N=256) if isinstance(m, JointState_)):
            got["joint_states_received"] += 1
            if got["first_joint_state"] is None:
                got["joint_names"], got["joint_positions"] = list(m.name), r6s(m.position)
                got["first_joint_state"] = stamped(m, t0, velocity=r6s(m.velocity),
                                                   effort=r6s(m.effort))
        for m in (m for m in wrench.take(N=256) if isinstance(m, WrenchStamped_)):
            got["hand_wrench_received"] += 1
            if got["first_wrench"] is None:
                f, t = m.wrench.force, m.wrench.torque
                got["first_wrench"] = stamped(m, t0, force=r6s([f.x, f.y, f.z]),
                                              torque=r6s([t.x, t.y, t.z]))
        time.sleep(0.005)
    write_json(a.report, {"domain": a.domain, "duration_s": a.duration, **got})
    return 0


def run_talk_cmd(a):
    dp = participant(a.domain)
    writer = DataWriter(dp, Topic(dp, "rt/lowcmd", LowCmd_), qos=writer_qos())
    cmd = LowCmd_(mode_pr=0, mode_machine=a.mode_machine, reserve=[0] * 4, crc=0, motor_cmd=[
        MotorCmd_(mode=1, q=0.0, dq=0.0, tau=0.0, kp=0.0, kd=1.0, reserve=0)
        for _ in range(SLOTS)])
    cmd.crc = image_crc(low_cmd_image(cmd))
    period, n = 1.0 / a.rate, 0
    t0 = deadline = time.monotonic()
    while time.monotonic() - t0 < a.duration:
        writer.write(cmd)
        n += 1
        deadline = max(deadline + period, time.monotonic() - period)
        time.sleep(max(0.0, deadline - time.monotonic()))
    print(json.dumps({"commands_sent": n, "crc": cmd.crc}))
    return 0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)

    def common(s, rate=True):
        s.add_argument("--domain", type=int, default=1, help="DDS domain (default 1)")
        s.add_argument("--duration", type=float, default=5.0, help="seconds (default 5)")
        if rate:
            s.add_argument("--rate", type=float, default=500.0, help="Hz (default 500)")

    r = sub.add_parser("robot", help="play the G1: rt/lowstate out, rt/lowcmd in")
    common(r)
    r.add_argument("--report", required=True, help="JSON report written at the end")
    r.add_argument("--bad-crc-every", type=int, metavar="N", help="every Nth state a wrong CRC")
    r.add_argument("--stale-every", type=int, metavar="N",
                   help="every Nth state repeats the previous state's tick")
    r.add_argument("--zero-crc", action="store_true", help="crc and tick left 0")
    r.add_argument("--mode-machine", type=int, default=5, help="LowState_.mode_machine")
    r.add_argument("--effort-limit", type=float, metavar="X",
                   help="count commands with |tau| (or implied torque) above X in a slot")
    l_ = sub.add_parser("listen", help="read rt/joint_states and rt/hand_wrench")
    common(l_, rate=False)
    l_.add_argument("--report", required=True, help="JSON report written at the end")
    t = sub.add_parser("talk-cmd", help="a second controller publishing on rt/lowcmd")
    common(t)
    t.add_argument("--mode-machine", type=int, default=5, help="LowCmd_.mode_machine")
    a = p.parse_args(argv)
    if getattr(a, "rate", 1.0) <= 0:
        p.error("--rate must be positive")
    return {"robot": run_robot, "listen": run_listen, "talk-cmd": run_talk_cmd}[a.command](a)


if __name__ == "__main__":
    sys.exit(main())
