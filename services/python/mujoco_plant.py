#!/usr/bin/env python3
"""The MuJoCo plant of upc: MuJoCo in `upc sim`'s place on the channel contract.

    python mujoco_plant.py BUNDLE/plant.json [--summary FILE] [--truth-csv FILE]

`upc sim --plant mujoco` (and `upc run --plant mujoco`) generates the bundle with `upc mjcf`
(the MJCF `scene.xml` and `plant.json`, from the robot description, the scenario and the
simulator's config) and runs this script beside it. It behaves as src/sim/process.rs does:

- every step it publishes `upc::StateMsg` (contract conventions: base quaternion x y z w, base
  velocities in the base frame, ground force on each sole corner, CoP, the door's force on the
  hand) and `upc::GroundTruthMsg`, each followed by its event;
- it gates every `upc::TorqueMsg` as `CommandGate` does (wrong length, non-finite, seq not
  increasing per controller run, another plant session: rejected, counted, logged once a
  second) and clamps accepted torques to the effort limits;
- lockstep: publishes state k, waits for the torques answering it, steps; the same inputs give
  the same bytes (MuJoCo is deterministic on one machine and build);
- real time: steps on absolute deadlines under the supervisor of src/sim/hold.rs (hold until the
  first torques, hand over, hold again when they stop, damping after the lost timeout).

plant.json (format 1) is written by src/sim/mujoco.rs (`PlantFile`): robot and scenario
identifiers, `sim` (step, mode, duration, prefix, timeouts), `hold` (gains per joint), the MJCF
names of the base, actuated joints (contract order), contact spheres (contract order), sites and
door hinge, the home configuration and the hinge torque sampled at the step.
"""

import argparse
import json
import math
import os
import secrets
import signal
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

try:
    import numpy as np
    import mujoco
    import iceoryx2 as iox2
    import upc_channels as ch
except ImportError as e:  # a Python without the packages of scripts/setup.sh
    print(f"mujoco plant: {e} (run scripts/setup.sh, or give upc sim --python)", file=sys.stderr)
    sys.exit(2)


def _warn(text: str) -> None:
    # MuJoCo's own handler appends to MUJOCO_LOG.TXT in the working directory: stderr instead.
    print(f"mujoco plant: MuJoCo: {text}", file=sys.stderr)


mujoco.set_mju_user_warning(_warn)


class Diverged(Exception):
    """MuJoCo found the simulation unstable (and reset its data): the run cannot go on."""


class BundleError(Exception):
    """A bundle that cannot be run, with the reason."""


# Simulated time the robot settles onto its soft contacts before a run starts (s).
SETTLE_TIME = 0.5

# Columns of the ground-truth CSV: those of upc sim (TRUTH_CSV_HEADER in src/sim/process.rs).
TRUTH_CSV_HEADER = (
    "t,com_x,com_y,com_z,zmp_x,zmp_y,hand_fx,hand_fy,hand_fz,door_angle,door_torque,"
    "loop_error,max_penetration,max_slip_speed,solver_iterations"
)


class Histogram:
    """Durations in 1 µs bins up to 20 ms (as upc's LatencyHistogram): fixed memory."""

    def __init__(self):
        self.bins = np.zeros(20001, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def record(self, seconds: float):
        self.bins[min(20000, max(0, int(seconds * 1e6)))] += 1
        self.n += 1
        self.max = max(self.max, seconds)

    def quantile(self, p: float) -> float:
        if self.n == 0:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.bins), math.ceil(p * self.n)))
        return k * 1e-6


class Gate:
    """Torque command validation, as CommandGate in src/sim/command.rs."""

    def __init__(self, session: int, n: int):
        self.session, self.n = session, n
        self.last_seq, self.controller = None, 0
        self.stats = dict(accepted=0, wrong_length=0, non_finite=0, out_of_order=0,
                          foreign=0, controller_changes=0, stale=0)
        self.last_log = 0.0

    def rejected(self) -> int:
        s = self.stats
        return s["wrong_length"] + s["non_finite"] + s["out_of_order"] + s["foreign"]

    def check(self, msg, tau_out) -> bool:
        """Validates `msg`; on acceptance copies its torques into `tau_out`."""
        reason = None
        if self.session != 0 and msg.session != self.session:
            self.stats["foreign"] += 1
            reason = (f"torque command answers plant session {msg.session:#x}, this plant run is "
                      f"{self.session:#x} (a controller still on a previous run)")
        else:
            last = self.last_seq if msg.controller == self.controller else None
            tau = np.ctypeslib.as_array(msg.tau)
            if msg.n != self.n:
                self.stats["wrong_length"] += 1
                reason = f"torque command has n = {msg.n}, the robot has {self.n} actuated joints"
            elif not np.all(np.isfinite(tau[: self.n])):
                self.stats["non_finite"] += 1
                index = int(np.flatnonzero(~np.isfinite(tau[: self.n]))[0])
                reason = f"torque command has a non-finite torque at index {index}"
            elif last is not None and msg.seq <= last:
                self.stats["out_of_order"] += 1
                reason = f"torque command seq {msg.seq} does not follow the last accepted seq {last}"
            else:
                if msg.controller != self.controller:
                    self.stats["controller_changes"] += int(self.last_seq is not None)
                    self.controller = msg.controller
                self.last_seq = msg.seq
                self.stats["accepted"] += 1
                tau_out[:] = tau[: self.n]
                return True
        now = time.monotonic()
        if now - self.last_log > 1.0:
            print(f"mujoco plant: rejected torque command: {reason} "
                  f"({self.rejected()} rejected so far)", file=sys.stderr)
            self.last_log = now
        return False


class Supervisor:
    """Who drives the robot in real time: the port of src/sim/hold.rs (same phases, same
    torques; the gains are upc's, from plant.json)."""

    def __init__(self, hold: dict, safe_damping: float, q_start):
        self.pd = hold["kind"] == "posture_pd"
        self.kp, self.kd = np.array(hold["kp"]), np.array(hold["kd"])
        self.handover, self.fade = hold["handover"], hold["feedforward_fade"]
        self.lost_timeout, self.safe_damping = hold["lost_timeout"], safe_damping
        self.q_ref = np.array(q_start, dtype=float)
        self.phase = "hold" if self.pd else "damping"
        self.since, self.after_loss = 0.0, False
        n = len(self.q_ref)
        self.last_cmd, self.feedforward = np.zeros(n), np.zeros(n)
        self.stats = dict(hold_steps=0, handover_steps=0, damping_steps=0, handovers=0, losses=0)

    def torques(self, t, q, v, command, out):
        """Torques at `t` into `out`; `command`: current commanded torques or None. Returns
        (from, to) on a phase change."""
        frm = self.phase
        to = frm
        if frm in ("hold", "damping") and command is not None:
            to = "handover"
        elif frm == "handover" and command is not None and t - self.since >= self.handover:
            to = "control"
        elif frm in ("handover", "control") and command is None:
            self.stats["losses"] += int(frm == "control")
            self.after_loss = True  # hold the posture of now, the last torques fading out
            self.q_ref[:] = q
            self.feedforward[:] = self.last_cmd
            to = "hold"
        elif (frm == "hold" and command is None and self.after_loss and self.lost_timeout > 0
              and t - self.since > self.lost_timeout):
            to = "damping"
        if to == "hold" and not self.pd:
            to = "damping"
        if to != frm:
            self.phase, self.since = to, t
            self.stats["handovers"] += int(to == "handover")
        if self.phase == "control":
            out[:] = command
            self.last_cmd[:] = command
        elif self.phase == "handover":
            self.stats["handover_steps"] += 1
            s = min(1.0, max(0.0, (t - self.since) / self.handover)) if self.handover > 0 else 1.0
            out[:] = (1.0 - s) * self._hold(t, q, v) + s * command
            self.last_cmd[:] = command
        elif self.phase == "hold":
            self.stats["hold_steps"] += 1
            out[:] = self._hold(t, q, v)
        else:
            self.stats["damping_steps"] += 1
            out[:] = -self.safe_damping * v
        return (frm, to) if to != frm else None

    def _hold(self, t, q, v):
        if not self.pd:
            return -self.safe_damping * v
        tau = self.kp * (self.q_ref - q) - self.kd * v
        if self.fade > 0 and self.after_loss:
            f = max(0.0, 1.0 - (t - self.since) / self.fade)
            if f > 0:
                tau = tau + f * self.feedforward
        return tau


class Plant:
    """The MuJoCo world of a bundle and its state in the contract's conventions."""

    def __init__(self, plant_path: Path):
        try:
            cfg = json.loads(plant_path.read_text())
        except (OSError, ValueError) as e:
            raise BundleError(f"{plant_path}: {e}") from e
        if cfg.get("format") != 1:
            raise BundleError(f"{plant_path}: format {cfg.get('format')}, this plant reads 1")
        self.cfg = cfg
        scene = plant_path.parent / cfg["scene"]
        try:
            self.m = mujoco.MjModel.from_xml_path(str(scene))
        except ValueError as e:
            raise BundleError(f"{scene}: {e}") from e
        m = self.m
        self.d = mujoco.MjData(m)
        sim = cfg["sim"]
        if abs(m.opt.timestep - sim["dt"]) > 1e-15:
            raise BundleError(f"{scene}: timestep {m.opt.timestep} ≠ sim.dt {sim['dt']}")
        self.dt = sim["dt"]

        def ident(kind, name):
            i = mujoco.mj_name2id(m, kind, name)
            if i < 0:
                raise BundleError(f"{scene} has no {kind.name[6:].lower()} `{name}`")
            return i

        base = ident(mujoco.mjtObj.mjOBJ_JOINT, cfg["base_joint"])
        self.bq, self.bv = int(m.jnt_qposadr[base]), int(m.jnt_dofadr[base])
        self.base_body = ident(mujoco.mjtObj.mjOBJ_BODY, cfg["base_body"])
        joints = [ident(mujoco.mjtObj.mjOBJ_JOINT, j) for j in cfg["joints"]]
        self.qadr = np.array([m.jnt_qposadr[j] for j in joints])
        self.dadr = np.array([m.jnt_dofadr[j] for j in joints])
        self.n = len(joints)
        self.nq, self.nv = 7 + self.n, 6 + self.n
        if self.nq > ch.MAX_DOF:
            raise BundleError(f"nq = {self.nq}: the contract carries at most {ch.MAX_DOF}")
        self.effort = np.array([math.inf if e is None else e for e in cfg["effort"]])
        self.clamp = bool(sim["effort_limits"])
        if len(cfg["contacts"]) != ch.N_CONTACTS:
            raise BundleError(f"{len(cfg['contacts'])} contacts, the contract has {ch.N_CONTACTS}")
        self.spheres = [ident(mujoco.mjtObj.mjOBJ_GEOM, g) for g in cfg["contacts"]]
        self.slot_of = np.full(m.ngeom, -1)
        self.slot_of[self.spheres] = np.arange(ch.N_CONTACTS)
        self.radius = cfg["contact_radius"]
        self.hand = ident(mujoco.mjtObj.mjOBJ_SITE, cfg["hand_site"])
        self.door = cfg["door_joint"] is not None
        if self.door:
            self.handle = ident(mujoco.mjtObj.mjOBJ_SITE, cfg["handle_site"])
            hinge = ident(mujoco.mjtObj.mjOBJ_JOINT, cfg["door_joint"])
            self.hq, self.hv = int(m.jnt_qposadr[hinge]), int(m.jnt_dofadr[hinge])
            self.connect = ident(mujoco.mjtObj.mjOBJ_EQUALITY, "hand_handle")
        self.hinge = np.array(cfg["hinge_torque"]["values"])

        home = np.array(cfg["home"], dtype=float)
        if len(home) != self.nq:
            raise BundleError(f"home has {len(home)} values, the robot nq = {self.nq}")
        d = self.d
        d.qpos[self.bq:self.bq + 3] = home[0:3]
        d.qpos[self.bq + 3:self.bq + 7] = [home[6], home[3], home[4], home[5]]  # xyzw → wxyz
        d.qpos[self.qadr] = home[7:]
        mujoco.mj_forward(m, d)

        self.settled = self.settle(cfg["hold"], SETTLE_TIME)
        self.tau = np.zeros(self.n)
        self.contact = np.zeros((ch.N_CONTACTS, 3))
        self.zmp = np.zeros(2)
        self.hand_force = np.zeros(3)
        self.door_torque = 0.0
        self.penetration = self.slip = 0.0
        self.step_time = 0.0
        self._f6 = np.zeros(6)
        self._vel6 = np.zeros(6)
        self.measure()

    def settle(self, hold: dict, seconds: float) -> float:
        """Lets the robot settle onto its contacts under the hold's posture PD, then starts the
        run from there at rest, time 0. MuJoCo's contacts are soft: a robot placed with its
        contact points on the ground (as upc's hard contacts hold it) first sinks into them,
        which shakes the CoP at the start of a run. Returns how far the base sank (m)."""
        d = self.d
        z0 = float(d.qpos[self.bq + 2])
        kp, kd = np.array(hold["kp"]), np.array(hold["kd"])
        q_ref = self.joint_q().copy()
        for _ in range(round(seconds / self.dt)):
            d.qfrc_applied[self.dadr] = kp * (q_ref - self.joint_q()) - kd * self.joint_v()
            mujoco.mj_step(self.m, d)
        d.qfrc_applied[:] = 0.0
        d.qvel[:] = 0.0
        d.time = 0.0
        mujoco.mj_forward(self.m, d)
        return z0 - float(d.qpos[self.bq + 2])

    def joint_q(self):
        return self.d.qpos[self.qadr]

    def joint_v(self):
        return self.d.qvel[self.dadr]

    def hinge_torque(self, t_scenario: float) -> float:
        if t_scenario < 0:
            return 0.0
        k = int(round(t_scenario / self.dt))
        return float(self.hinge[k]) if k < len(self.hinge) else 0.0

    def step(self, tau, door_torque: float):
        d = self.d
        applied = np.clip(tau, -self.effort, self.effort) if self.clamp else tau
        d.qfrc_applied[self.dadr] = applied
        if self.door:
            d.qfrc_applied[self.hv] = door_torque
        self.door_torque = door_torque
        t_before, t0 = d.time, time.perf_counter()
        mujoco.mj_step(self.m, d)
        self.step_time = time.perf_counter() - t0
        if d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0:
            # MuJoCo has reset the state to the model's zero pose: stop rather than publish it.
            raise Diverged(f"the simulation diverged at t = {t_before:.3f} s (MuJoCo: bad "
                           "accelerations; typically a fall under torques the effort limits allow)")
        self.measure()

    def measure(self):
        """Contact forces on the soles' corners, CoP, the door's force on the hand, contact
        figures: what the state and the ground truth report after a step."""
        m, d = self.m, self.d
        self.contact[:] = 0.0
        self.penetration = 0.0
        self.slip = 0.0
        ncon = d.ncon
        if ncon:
            con = d.contact
            geoms, frames, dists = con.geom[:ncon], con.frame[:ncon], con.dist[:ncon]
            slots = self.slot_of[geoms]  # (ncon, 2): contact slot of each geom, −1 if none
            for i in np.flatnonzero((slots >= 0).any(axis=1)):
                mujoco.mj_contactForce(m, d, int(i), self._f6)
                # The contact frame's rows are the normal (geom1 → geom2) and two tangents; the
                # force acts on geom2.
                f = frames[i].reshape(3, 3).T @ self._f6[:3]
                if slots[i, 1] >= 0:
                    self.contact[slots[i, 1]] += f
                else:
                    self.contact[slots[i, 0]] -= f
                self.penetration = max(self.penetration, -float(dists[i]))
        fz = self.contact[:, 2]
        touching = np.flatnonzero(fz > 0)
        if len(touching):
            bottoms = d.geom_xpos[self.spheres][:, :2]
            self.zmp[:] = (bottoms[touching] * fz[touching, None]).sum(axis=0) / fz[touching].sum()
        for k in touching:
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_GEOM, self.spheres[k],
                                     self._vel6, 0)
            w, v = self._vel6[:3], self._vel6[3:]
            # The velocity of the sphere's lowest point: v + ω × (−r ẑ).
            vx, vy = v[0] - w[1] * self.radius, v[1] + w[0] * self.radius
            self.slip = max(self.slip, math.hypot(vx, vy))
        if self.door:
            rows = np.flatnonzero((d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
                                  & (d.efc_id == self.connect))
            # connect: residual p_hand − p_handle (world), so its force acts on the hand.
            self.hand_force[:] = d.efc_force[rows] if len(rows) == 3 else 0.0

    def loop_error(self) -> float:
        if not self.door:
            return 0.0
        return float(np.linalg.norm(self.d.site_xpos[self.hand] - self.d.site_xpos[self.handle]))

    def door_state(self):
        if not self.door:
            return 0.0, 0.0
        return float(self.d.qpos[self.hq]), float(self.d.qvel[self.hv])

    def fill(self, msg):
        """The contract's state: q (base quaternion x y z w), v (base velocities in the base
        frame), contact forces, CoP, door, hand force."""
        d = self.d
        q = np.ctypeslib.as_array(msg.q)
        v = np.ctypeslib.as_array(msg.v)
        q[0:3] = d.qpos[self.bq:self.bq + 3]
        w, x, y, z = d.qpos[self.bq + 3:self.bq + 7]
        q[3:7] = (x, y, z, w)
        q[7:self.nq] = d.qpos[self.qadr]
        rot = d.xmat[self.base_body].reshape(3, 3)
        # MuJoCo's free joint: linear velocity in the world frame, angular in the body's.
        v[0:3] = rot.T @ d.qvel[self.bv:self.bv + 3]
        v[3:6] = d.qvel[self.bv + 3:self.bv + 6]
        v[6:self.nv] = d.qvel[self.dadr]
        msg.time = d.time
        msg.nq, msg.nv = self.nq, self.nv
        np.ctypeslib.as_array(msg.contact_forces)[:] = self.contact
        msg.zmp[0], msg.zmp[1] = self.zmp
        msg.door_angle, msg.door_velocity = self.door_state()
        msg.hand_force[0], msg.hand_force[1], msg.hand_force[2] = self.hand_force


class Process:
    """The plant on the channels: `upc sim`'s loop (src/sim/process.rs) around a Plant."""

    def __init__(self, plant: Plant, truth_csv):
        self.p = plant
        cfg, sim = plant.cfg, plant.cfg["sim"]
        self.sim = sim
        self.lockstep = sim["mode"] == "lockstep"
        self.session = secrets.randbits(64) or 1
        self.scenario_start = 0.0 if self.lockstep else -1.0
        self.flags = ch.STATE_FLAG_LOCKSTEP if self.lockstep else ch.STATE_FLAG_HOLD
        self.gate = Gate(self.session, plant.n)
        self.supervisor = Supervisor(cfg["hold"], sim["safe_damping"], plant.joint_q().copy())
        self.steps = 0
        self.timing, self.ipc = Histogram(), Histogram()
        self.max_pen = self.max_slip = self.max_loop = 0.0
        self.overruns = 0
        self.record_every = max(1, round(sim["record_period"] / sim["dt"]))
        self.truth = truth_csv

        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
        self.node = node
        prefix = sim["prefix"]
        self.state_pub = ch.pubsub(node, prefix, "state", ch.StateMsg).publisher_builder().create()
        self.truth_pub = (ch.pubsub(node, prefix, "ground_truth", ch.GroundTruthMsg)
                          .publisher_builder().create())
        self.torques = (ch.pubsub(node, prefix, "torques", ch.TorqueMsg)
                        .subscriber_builder().create())
        self.state_ev = ch.event(node, prefix, "state").notifier_builder().create()
        self.truth_ev = ch.event(node, prefix, "ground_truth").notifier_builder().create()
        self.torque_ev = ch.event(node, prefix, "torques").listener_builder().create()

        self.msg = ch.StateMsg()
        name = cfg["scenario"].encode()[: ch.SCENARIO_NAME_LEN]
        self.msg.scenario[: len(name)] = name
        self.msg.session = self.session
        self.msg.scenario_hash = int(cfg["scenario_hash"], 16)
        self.msg.force_scale = cfg["force_scale"]
        self.msg.robot_hash = int(cfg["robot_hash"], 16)
        self.gt = ch.GroundTruthMsg()
        self.published_at = time.monotonic()
        self.error = None  # what ended the run early

    def publish(self, step_time: float):
        p, msg = self.p, self.msg
        if not self.lockstep:
            self.flags = {"hold": ch.STATE_FLAG_HOLD, "handover": ch.STATE_FLAG_HOLD,
                          "damping": ch.STATE_FLAG_DAMPING}.get(self.supervisor.phase, 0)
        p.fill(msg)
        msg.step = self.steps
        msg.scenario_start = self.scenario_start
        msg.flags = self.flags
        self.state_pub.loan_uninit().write_payload(msg).send()
        gt = self.gt
        gt.step, gt.time = self.steps, p.d.time
        gt.com[0], gt.com[1], gt.com[2] = p.d.subtree_com[p.base_body]
        gt.loop_error = p.loop_error()
        gt.max_penetration, gt.max_slip_speed = p.penetration, p.slip
        gt.door_torque, gt.step_time = p.door_torque, step_time
        gt.solver_iterations = int(p.d.solver_niter[0])
        gt.rejected_commands = min(self.gate.rejected(), 2**32 - 1)
        gt.stale_commands = self.gate.stats["stale"]
        gt.flags, gt.hold_steps = self.flags, self.supervisor.stats["hold_steps"]
        self.truth_pub.loan_uninit().write_payload(gt).send()
        self.state_ev.notify()
        self.published_at = time.monotonic()
        self.truth_ev.notify()

    def step(self, tau):
        p = self.p
        door = p.hinge_torque(p.d.time - self.scenario_start) if self.scenario_start >= 0 else 0.0
        p.step(tau, door)
        dt_step = p.step_time  # MuJoCo's step alone, as upc sim times its World::step
        self.steps += 1
        self.timing.record(dt_step)
        self.max_pen = max(self.max_pen, p.penetration)
        self.max_slip = max(self.max_slip, p.slip)
        loop = p.loop_error()
        self.max_loop = max(self.max_loop, loop)
        self.publish(dt_step)
        if self.truth is not None and self.steps % self.record_every == 0:
            d = p.d
            c = d.subtree_com[p.base_body]
            h = p.hand_force
            angle, _ = p.door_state()
            self.truth.write(
                f"{d.time:.4f},{c[0]:.6f},{c[1]:.6f},{c[2]:.6f},{p.zmp[0]:.6f},{p.zmp[1]:.6f},"
                f"{h[0]:.4f},{h[1]:.4f},{h[2]:.4f},{angle:.6f},{p.door_torque:.4f},"
                f"{rust_exp(loop)},{rust_exp(p.penetration)},{rust_exp(p.slip)},"
                f"{int(d.solver_niter[0])}\n")

    def receive(self):
        """The next torque message (copied out), or None."""
        sample = self.torques.receive()
        if sample is None:
            return None
        msg = ch.TorqueMsg.from_buffer_copy(sample.payload().contents)
        sample.delete()
        return msg

    def lockstep_loop(self, total: int, stop) -> None:
        cmd = np.zeros(self.p.n)
        while self.steps < total and not stop["now"]:
            want = self.steps
            timeout = self.sim["first_command_timeout" if want == 0 else "lockstep_timeout"]
            deadline = time.monotonic() + timeout
            answered = False
            while not answered:
                while (msg := self.receive()) is not None:
                    if not self.gate.check(msg, cmd):
                        continue
                    if msg.state_step == want:
                        if want > 0:  # state 0 waits for the controller to start
                            rt = time.monotonic() - self.published_at
                            self.ipc.record(max(0.0, rt - msg.compute_ns * 1e-9))
                        answered = True
                        break
                    self.gate.stats["stale"] += 1  # a valid answer to another state
                if answered:
                    break
                now = time.monotonic()
                if now >= deadline:
                    raise TimeoutError(
                        f"lockstep: no torques answering state {want} within {timeout:.3f} s")
                if stop["now"]:
                    return
                woken = self.torque_ev.timed_wait(
                    iox2.Duration.from_secs_f64(min(deadline - now, 0.02)))
                if not woken and not self.torques.has_samples():
                    # A controller that connected after this state was sent has neither the
                    # sample nor its wake-up: send the same state again (it skips duplicates).
                    self.p.fill(self.msg)
                    self.state_pub.loan_uninit().write_payload(self.msg).send()
                    self.state_ev.notify()
            self.step(cmd)

    def realtime_loop(self, total: int, stop) -> None:
        p, period = self.p, self.sim["dt"]
        cmd_timeout = self.sim["command_timeout"]
        commanded, applied = np.zeros(p.n), np.zeros(p.n)
        last_cmd = None
        nxt = time.monotonic() + period
        while self.steps < total and not stop["now"]:
            fresh = False
            while (msg := self.receive()) is not None:
                holding = self.supervisor.phase in ("hold", "damping")
                if holding and msg.flags & ch.TORQUE_FLAG_FALLBACK:
                    continue  # a controller's fallback does not take the robot from the hold
                if self.gate.check(msg, commanded):
                    fresh = True
            now = time.monotonic()
            if fresh:
                last_cmd = now
            else:
                self.gate.stats["stale"] += 1
            current = last_cmd is not None and now - last_cmd <= cmd_timeout
            t = p.d.time
            tr = self.supervisor.torques(t, p.joint_q(), p.joint_v(),
                                         commanded if current else None, applied)
            if tr is not None:
                print(f"mujoco plant: t = {t:.3f} s: {tr[0]} → {tr[1]}", file=sys.stderr)
                if tr[1] == "control" and self.scenario_start < 0:
                    self.scenario_start = t
                    print(f"mujoco plant: t = {t:.3f} s: scenario `{p.cfg['scenario']}` starts",
                          file=sys.stderr)
            self.step(applied)
            now = time.monotonic()
            if now > nxt:
                self.overruns += 1
                if now - nxt > 10 * period:
                    nxt = now  # far behind: resynchronise instead of bursting
            else:
                time.sleep(nxt - now)
            nxt += period

    def summary(self, wall: float) -> dict:
        p, cfg = self.p, self.p.cfg
        return {
            "plant": "mujoco",
            "mujoco_version": mujoco.__version__,
            "settle_sink": p.settled,
            "error": self.error,
            "steps": self.steps,
            "sim_time": self.steps * p.dt,  # MuJoCo resets d.time when it diverges
            "wall_time": wall,
            "step_time_p50": self.timing.quantile(0.5),
            "step_time_p99": self.timing.quantile(0.99),
            "step_time_max": self.timing.max,
            "overruns": self.overruns,
            "commands": self.gate.stats,
            "safe_mode_steps": self.supervisor.stats["damping_steps"],
            "hold": self.supervisor.stats,
            "mode": self.sim["mode"],
            "robot": cfg["robot"],
            "force_scale": cfg["force_scale"],
            "scenario": cfg["scenario"],
            "scenario_hash": cfg["scenario_hash"],
            "session": f"{self.session:016x}",
            "scenario_start": self.scenario_start,
            "max_penetration": self.max_pen,
            "max_slip_speed": self.max_slip,
            "max_loop_error": self.max_loop,
            "recorder": {"written": 0, "dropped": 0},
            "ipc_overhead_p50": self.ipc.quantile(0.5),
            "ipc_overhead_p99": self.ipc.quantile(0.99),
            "ipc_overhead_max": self.ipc.max,
        }


def rust_exp(x: float) -> str:
    """`{:.3e}` of Rust (`1.234e-5`, `0.000e0`), so that both plants write the same format."""
    mantissa, exponent = f"{x:.3e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def main() -> int:
    a = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    a.add_argument("plant", type=Path, help="plant.json of a bundle written by `upc mjcf`")
    a.add_argument("--summary", type=Path, help="write the run's figures as JSON here")
    a.add_argument("--truth-csv", type=Path, help="lockstep: the ground truth as CSV here")
    args = a.parse_args()

    stop = {"now": False}
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.update(now=True))
    truth = None
    try:
        plant = Plant(args.plant)
        sim = plant.cfg["sim"]
        if args.truth_csv is not None:
            if sim["mode"] != "lockstep":
                raise BundleError("--truth-csv is written from the stepping loop: lockstep only")
            truth = open(args.truth_csv, "w", buffering=1 << 20)
            truth.write(TRUTH_CSV_HEADER + "\n")
        proc = Process(plant, truth)
    except (BundleError, OSError) as e:
        print(f"mujoco plant: {e}", file=sys.stderr)
        return 2
    total = round(sim["duration"] / sim["dt"]) if sim["duration"] > 0 else sys.maxsize
    print(f"mujoco plant: MuJoCo {mujoco.__version__}, robot `{plant.cfg['robot']}` "
          f"(forces × {plant.cfg['force_scale']:.3f}), {sim['mode']} mode, dt = {sim['dt']} s, "
          f"duration = {sim['duration']} s, scenario `{plant.cfg['scenario']}`, prefix "
          f"`{sim['prefix']}`, session {proc.session:016x}", file=sys.stderr)
    start = time.monotonic()
    proc.publish(0.0)  # state 0 before any step
    status = 0
    try:
        if proc.lockstep:
            proc.lockstep_loop(total, stop)
        else:
            proc.realtime_loop(total, stop)
    except (TimeoutError, Diverged) as e:
        print(f"mujoco plant: {e}", file=sys.stderr)
        proc.error = str(e)
        status = 1
    wall = time.monotonic() - start
    if truth is not None:
        truth.close()
    s = proc.summary(wall)
    if args.summary is not None:
        args.summary.write_text(json.dumps(s, indent=2))
    c = s["commands"]
    print(f"mujoco plant: {s['steps']} steps, {s['sim_time']:.3f} s simulated in {wall:.3f} s; "
          f"step time p50 {s['step_time_p50'] * 1e6:.1f} µs, p99 {s['step_time_p99'] * 1e6:.1f} µs; "
          f"overruns {s['overruns']}; commands accepted {c['accepted']}, rejected "
          f"{proc.gate.rejected()} (length {c['wrong_length']}, non-finite {c['non_finite']}, "
          f"order {c['out_of_order']}, foreign {c['foreign']}), stale {c['stale']}; hold steps "
          f"{s['hold']['hold_steps']}, hand-overs {s['hold']['handovers']}, controller losses "
          f"{s['hold']['losses']}; max penetration {s['max_penetration']:.2e} m, max slip "
          f"{s['max_slip_speed']:.2e} m/s, max loop error {s['max_loop_error']:.2e} m",
          file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
