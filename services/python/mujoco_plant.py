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

Before time 0 the robot settles for SETTLE_TIME onto MuJoCo's soft contacts, held at its home
posture (`Plant._settle`): upc's contacts are hard, a robot placed on MuJoCo's first sinks about
a millimetre into them.

As upc's World reports a step, forces (contacts, CoP, hand) are those of the step's constraint
solve, at the configuration it started from; geometry (CoM, penetration, loop error) and slip
are those after it, with the state's q and v.

plant.json (format 1) is written by src/sim/mujoco.rs (`PlantFile`): robot and scenario
identifiers, `sim` (step, mode, duration, prefix, timeouts), `hold` (gains per joint), the MJCF
names of the base, actuated joints (contract order), contact spheres (contract order), sites and
door hinge, the home configuration and the hinge torque sampled at the step.

Exit status: 0 done (duration reached or SIGINT/SIGTERM), 1 the run failed (lockstep timeout,
MuJoCo diverged, channels), 2 it could not start (bundle, Python packages).
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

# upc_channels.py sits beside this script, in services/python and in a bundle alike.
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

# The connect equality joining the hand to the door's handle (src/sim/mujoco.rs, CONNECT).
CONNECT = "hand_handle"

# Columns of the ground-truth CSV: those of upc sim (TRUTH_CSV_HEADER in src/sim/process.rs).
TRUTH_CSV_HEADER = (
    "t,com_x,com_y,com_z,zmp_x,zmp_y,hand_fx,hand_fy,hand_fz,door_angle,door_torque,"
    "loop_error,max_penetration,max_slip_speed,solver_iterations"
)

# What iceoryx2 raises when the channels cannot be opened or used (a prefix that is not a valid
# service name, services of another layout or settings, shared memory exhausted).
CHANNEL_ERRORS = (
    iox2.SemanticStringError, iox2.NodeCreationFailure, iox2.PublishSubscribeOpenOrCreateError,
    iox2.EventOpenOrCreateError, iox2.PublisherCreateError, iox2.SubscriberCreateError,
    iox2.NotifierCreateError, iox2.ListenerCreateError, iox2.LoanError, iox2.SendError,
    iox2.ReceiveError, iox2.NotifierNotifyError, iox2.ListenerWaitError,
)

# MuJoCo resets its data when one of these is raised in a step.
_INSTABILITY = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
                mujoco.mjtWarning.mjWARN_BADQPOS)


class Histogram:
    """Durations in 1 µs bins up to 20 ms, quantiles at the upper bin edge: upc's
    LatencyHistogram (src/control/timing.rs)."""

    BINS = 20000

    def __init__(self):
        self.bins = np.zeros(self.BINS, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def record(self, seconds: float):
        self.bins[min(self.BINS - 1, int(seconds * 1e6))] += 1
        self.n += 1
        if seconds > self.max:
            self.max = seconds

    def quantile(self, p: float) -> float:
        if self.n == 0:
            return 0.0
        target = max(1, math.ceil(p * self.n))
        return (int(np.searchsorted(np.cumsum(self.bins), target)) + 1) * 1e-6


class Gate:
    """Torque command validation, as CommandGate in src/sim/command.rs."""

    def __init__(self, session: int, n: int):
        self.session, self.n = session, n
        self.last_seq, self.controller = None, 0
        self.stats = dict(accepted=0, wrong_length=0, non_finite=0, out_of_order=0,
                          foreign=0, controller_changes=0, stale=0)
        self.last_log = None

    def rejected(self) -> int:
        s = self.stats
        return s["wrong_length"] + s["non_finite"] + s["out_of_order"] + s["foreign"]

    def check(self, msg, tau_out) -> bool:
        """Validates `msg`; on acceptance copies its torques into `tau_out`."""
        if self.session != 0 and msg.session != self.session:
            self.stats["foreign"] += 1
            reason = (f"torque command answers plant session {msg.session:#x}, this plant run is "
                      f"{self.session:#x} (a controller still on a previous run)")
        elif msg.n != self.n:
            self.stats["wrong_length"] += 1
            reason = f"torque command has n = {msg.n}, the robot has {self.n} actuated joints"
        else:
            tau = np.ctypeslib.as_array(msg.tau)[: self.n]
            # Another controller's seq counts from its own start.
            last = self.last_seq if msg.controller == self.controller else None
            # One sum, rather than a test per torque, unless it overflows or is NaN.
            bad = () if math.isfinite(tau.sum()) else np.flatnonzero(~np.isfinite(tau))
            if len(bad):
                self.stats["non_finite"] += 1
                reason = f"torque command has a non-finite torque at index {bad[0]}"
            elif last is not None and msg.seq <= last:
                self.stats["out_of_order"] += 1
                reason = (f"torque command seq {msg.seq} does not follow the last accepted seq "
                          f"{last}")
            else:
                if msg.controller != self.controller:
                    self.stats["controller_changes"] += int(self.last_seq is not None)
                    self.controller = msg.controller
                self.last_seq = msg.seq
                self.stats["accepted"] += 1
                tau_out[:] = tau
                return True
        now = time.monotonic()
        if self.last_log is None or now - self.last_log > 1.0:
            print(f"mujoco plant: rejected torque command: {reason} "
                  f"({self.rejected()} rejected so far)", file=sys.stderr)
            self.last_log = now
        return False


class Supervisor:
    """Who drives the robot in real time: the port of src/sim/hold.rs (same phases, same
    torques; the posture PD's gains are upc's, from plant.json)."""

    def __init__(self, hold: dict, safe_damping: float, q_start):
        self.pd = hold["kind"] == "posture_pd"
        self.kp, self.kd = np.array(hold["kp"], dtype=float), np.array(hold["kd"], dtype=float)
        self.handover, self.fade = hold["handover"], hold["feedforward_fade"]
        self.lost_timeout, self.safe_damping = hold["lost_timeout"], safe_damping
        self.q_ref = np.array(q_start, dtype=float)
        self.phase = "hold" if self.pd else "damping"
        self.since, self.after_loss = 0.0, False
        n = len(self.q_ref)
        self.last_cmd, self.feedforward = np.zeros(n), np.zeros(n)
        self.stats = dict(hold_steps=0, handover_steps=0, damping_steps=0, handovers=0, losses=0)

    def torques(self, t, q, v, command, out):
        """Torques at simulated time `t` into `out`; `command`: the controller's current
        torques, None while there are none. Returns (from, to) on a phase change."""
        frm = to = self.phase
        if frm in ("hold", "damping") and command is not None:
            to = "handover"
        elif frm == "handover" and command is not None and t - self.since >= self.handover:
            to = "control"
        elif frm in ("handover", "control") and command is None:
            self.stats["losses"] += int(frm == "control")
            # Hold the posture of now, the last commanded torques fading out as feed-forward.
            self.after_loss = True
            self.q_ref[:] = q
            self.feedforward[:] = self.last_cmd
            to = "hold"
        elif (frm == "hold" and command is None and self.after_loss and self.lost_timeout > 0
              and t - self.since > self.lost_timeout):
            to = "damping"
        if to == "hold" and not self.pd:
            to = "damping"  # without a PD, a hold is bare damping
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
        # The fade counts from this phase's start: the loss (a hand-over's hold has none).
        if self.fade > 0 and self.after_loss:
            f = max(0.0, 1.0 - (t - self.since) / self.fade)
            if f > 0:
                tau += f * self.feedforward
        return tau


class Plant:
    """The MuJoCo world of a bundle and its state in the contract's conventions
    (`self.state`, a StateMsg whose plant-run fields the Process fills)."""

    def __init__(self, plant_path: Path):
        try:
            cfg = json.loads(plant_path.read_text())
        except (OSError, ValueError) as e:
            raise BundleError(f"{plant_path}: {e}") from e
        if not isinstance(cfg, dict) or cfg.get("format") != 1:
            raise BundleError(f"{plant_path}: not a plant description of format 1")
        self.cfg = cfg
        try:
            self._load(plant_path.parent / cfg["scene"])
        except KeyError as e:
            raise BundleError(f"{plant_path}: no `{e.args[0]}`") from e
        except (TypeError, ValueError) as e:
            raise BundleError(f"{plant_path}: {e}") from e

    def _load(self, scene: Path):
        cfg, sim = self.cfg, self.cfg["sim"]
        try:
            self.m = m = mujoco.MjModel.from_xml_path(str(scene))
        except ValueError as e:  # MuJoCo's compiler errors, a missing file
            raise BundleError(f"{scene}: {e}") from e
        self.d = d = mujoco.MjData(m)
        if abs(m.opt.timestep - sim["dt"]) > 1e-15:
            raise BundleError(f"{scene}: timestep {m.opt.timestep} ≠ sim.dt {sim['dt']}")
        self.dt = sim["dt"]

        def ident(kind, name):
            i = mujoco.mj_name2id(m, kind, name)
            if i < 0:
                raise BundleError(f"{scene} has no {kind.name[6:].lower()} `{name}`")
            return i

        base = ident(mujoco.mjtObj.mjOBJ_JOINT, cfg["base_joint"])
        if m.jnt_type[base] != mujoco.mjtJoint.mjJNT_FREE:
            raise BundleError(f"{scene}: base joint `{cfg['base_joint']}` is not a free joint")
        self.bq, self.bv = int(m.jnt_qposadr[base]), int(m.jnt_dofadr[base])
        self.base_body = ident(mujoco.mjtObj.mjOBJ_BODY, cfg["base_body"])
        if m.jnt_bodyid[base] != self.base_body:
            raise BundleError(f"{scene}: base joint `{cfg['base_joint']}` does not move body "
                              f"`{cfg['base_body']}`")
        joints = [ident(mujoco.mjtObj.mjOBJ_JOINT, j) for j in cfg["joints"]]
        self.qadr = np.array([m.jnt_qposadr[j] for j in joints], dtype=int)
        self.dadr = np.array([m.jnt_dofadr[j] for j in joints], dtype=int)
        self.n = len(joints)
        self.nq, self.nv = 7 + self.n, 6 + self.n
        if self.nq > ch.MAX_DOF:
            raise BundleError(
                f"nq = {self.nq}: the contract carries at most {ch.MAX_DOF}; lock the joints "
                "the controller need not move (`locked` in the robot description)"
            )
        # The contract's q from MuJoCo's qpos in one gather: base position, quaternion x y z w
        # (MuJoCo's is w x y z), joints. v: the base's angular velocity (MuJoCo's is in the
        # body frame already) and the joint rates; the linear one is rotated in `_after_step`.
        b = self.bq
        self.q_from = np.concatenate([[b, b + 1, b + 2, b + 4, b + 5, b + 6, b + 3], self.qadr])
        self.v_from = np.concatenate([[self.bv + 3, self.bv + 4, self.bv + 5], self.dadr])
        effort = cfg["effort"]
        if len(effort) != self.n:
            raise BundleError(f"{len(effort)} effort limits for {self.n} joints")
        self.effort = np.array([math.inf if e is None else e for e in effort], dtype=float)
        self.clamp = bool(sim["effort_limits"])
        if len(cfg["contacts"]) != ch.N_CONTACTS:
            raise BundleError(f"{len(cfg['contacts'])} contacts, the contract has {ch.N_CONTACTS}")
        self.spheres = np.array([ident(mujoco.mjtObj.mjOBJ_GEOM, g) for g in cfg["contacts"]])
        self.slot_of = np.full(m.ngeom, -1)
        self.slot_of[self.spheres] = np.arange(ch.N_CONTACTS)
        self.radius = float(cfg["contact_radius"])
        self.hand = ident(mujoco.mjtObj.mjOBJ_SITE, cfg["hand_site"])
        self.door = cfg["door_joint"] is not None
        if self.door:
            self.handle = ident(mujoco.mjtObj.mjOBJ_SITE, cfg["handle_site"])
            hinge = ident(mujoco.mjtObj.mjOBJ_JOINT, cfg["door_joint"])
            self.hq, self.hv = int(m.jnt_qposadr[hinge]), int(m.jnt_dofadr[hinge])
            self.connect = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, CONNECT)
            if self.connect < 0:
                if m.neq != 1:
                    raise BundleError(f"{scene}: no equality `{CONNECT}` joining hand and handle")
                self.connect = 0
        self.hinge = np.array(cfg["hinge_torque"]["values"], dtype=float)
        if cfg["hinge_torque"]["dt"] != self.dt:
            raise BundleError(f"hinge torque sampled at {cfg['hinge_torque']['dt']} s, "
                              f"the step is {self.dt} s")
        self._instability = [d.warning[w] for w in _INSTABILITY]  # live views of the counters

        home = np.array(cfg["home"], dtype=float)
        if len(home) != self.nq:
            raise BundleError(f"home has {len(home)} values, the robot nq = {self.nq}")
        d.qpos[self.q_from] = home
        if self.door:
            d.qpos[self.hq] = 0.0
        kp, kd = np.array(cfg["hold"]["kp"], dtype=float), np.array(cfg["hold"]["kd"], dtype=float)
        if len(kp) != self.n or len(kd) != self.n:
            raise BundleError(f"hold gains for {len(kp)}, {len(kd)} joints, the robot has {self.n}")

        # Per-step figures. The eight spheres' are handled as Python floats: for so few
        # values a scalar loop costs half of numpy's per-call overhead.
        self.slot_list = self.slot_of.tolist()
        self.sphere_list = self.spheres.tolist()
        self.applied = np.zeros(self.n)
        self._f6 = np.zeros(6)
        self.zmp = (0.0, 0.0)
        self.door_torque = 0.0
        self.penetration = self.slip = self.loop_error = 0.0
        self.step_time = 0.0
        self.state = ch.StateMsg()
        st = self.state
        st.nq, st.nv = self.nq, self.nv
        self._q, self._v = np.ctypeslib.as_array(st.q), np.ctypeslib.as_array(st.v)
        self._contact_out = np.ctypeslib.as_array(st.contact_forces).reshape(-1)
        self.hand_force = np.ctypeslib.as_array(st.hand_force)

        self.settled = self._settle(kp, kd)
        self._after_step()

    def _settle(self, kp, kd) -> float:
        """Lets the robot settle onto its contacts, held at its home posture, then starts the
        run from there at rest, time 0. MuJoCo's contacts are soft: a robot placed with its
        contact points on the ground (as upc's hard contacts hold it) first sinks into them,
        which shakes the CoP at the start of a run. The hold is the posture PD of plant.json,
        plus gravity compensation on the joints with no contact point below them (torso, arms,
        head: what hangs on them is exactly MuJoCo's bias force); the PD alone, its gains scaled
        to each joint's inertia, lets the arms sag by up to 0.3 rad. The legs carry the body
        through the ground, which the bias force does not know: there the PD alone. Returns how
        far the base sank (m)."""
        m, d = self.m, self.d
        z0 = float(d.qpos[self.bq + 2])
        q_home = self.joint_q()
        carrying = set()  # bodies with a contact sphere on them or below them
        for g in self.sphere_list:
            b = int(m.geom_bodyid[g])
            while b > 0:
                carrying.add(b)
                b = int(m.body_parentid[b])
        hanging = np.array([m.dof_bodyid[a] not in carrying for a in self.dadr], dtype=float)
        for _ in range(round(SETTLE_TIME / self.dt)):
            mujoco.mj_forward(m, d)  # qfrc_bias (gravity, Coriolis) of this state
            d.qfrc_applied[self.dadr] = (kp * (q_home - self.joint_q()) - kd * self.joint_v()
                                         + hanging * d.qfrc_bias[self.dadr])
            mujoco.mj_step(m, d)
        if self._unstable():
            raise BundleError("the robot does not stand in the scene: MuJoCo diverged while it "
                              "settled onto its contacts, held at its home posture")
        # At rest where it settled, time 0. The forward pass has the hold's static torques, so
        # that the forces of state 0 are those of the robot held up, not collapsing.
        d.qvel[:] = 0.0
        d.time = 0.0
        mujoco.mj_forward(m, d)
        d.qfrc_applied[self.dadr] = (kp * (q_home - self.joint_q())
                                     + hanging * d.qfrc_bias[self.dadr])
        mujoco.mj_forward(m, d)
        d.qfrc_applied[:] = 0.0
        return z0 - float(d.qpos[self.bq + 2])

    def _unstable(self) -> bool:
        acc, vel, pos = self._instability
        return acc.number > 0 or vel.number > 0 or pos.number > 0

    def joint_q(self):
        return self.d.qpos[self.qadr]

    def joint_v(self):
        return self.d.qvel[self.dadr]

    def hinge_torque(self, t_scenario: float) -> float:
        if t_scenario < 0:
            return 0.0
        k = round(t_scenario / self.dt)
        return float(self.hinge[k]) if k < len(self.hinge) else 0.0

    def step(self, tau, door_torque: float):
        """One MuJoCo step under joint torques `tau` (clamped to the effort limits when the
        bundle says so) and the hinge torque; then the state of its end."""
        d = self.d
        if self.clamp:
            tau = np.clip(tau, -self.effort, self.effort, out=self.applied)
        d.qfrc_applied[self.dadr] = tau
        if self.door:
            d.qfrc_applied[self.hv] = door_torque
        self.door_torque = door_torque
        t_before, t0 = d.time, time.perf_counter()
        mujoco.mj_step(self.m, d)
        self.step_time = time.perf_counter() - t0
        if self._unstable():
            # MuJoCo has reset the state to the model's zero pose: stop rather than publish it.
            raise Diverged(f"the simulation diverged at t = {t_before:.3f} s (MuJoCo: bad "
                           "accelerations; typically a fall under torques the effort limits allow)")
        self._after_step()

    def _after_step(self):
        """The figures and the state (`self.state`, its world part) of the step just made, or
        of the forward pass of state 0."""
        m, d, st = self.m, self.d, self.state
        # Forces: MuJoCo's constraint solve of the step, at the configuration it started from
        # (d.contact, d.efc_force and the geometry in d are still those of that forward pass).
        forces = [0.0] * (3 * ch.N_CONTACTS)  # x y z of each contact point, contract order
        ncon = d.ncon
        if ncon:
            con, f, slot = d.contact, self._f6, self.slot_list
            frames = con.frame.tolist()
            for i, (g1, g2) in enumerate(con.geom.tolist()):
                # The contact frame's rows are the normal (geom1 → geom2) and two tangents; the
                # force in it acts on geom2, its opposite on geom1.
                k, sign = slot[g2], 1.0
                if k < 0:
                    k, sign = slot[g1], -1.0
                    if k < 0:
                        continue
                mujoco.mj_contactForce(m, d, i, f)
                fn, f1, f2 = f[:3].tolist()
                a, c = frames[i], 3 * k
                forces[c] += sign * (a[0] * fn + a[3] * f1 + a[6] * f2)
                forces[c + 1] += sign * (a[1] * fn + a[4] * f1 + a[7] * f2)
                forces[c + 2] += sign * (a[2] * fn + a[5] * f1 + a[8] * f2)
        self._contact_out[:] = forces
        # The CoP of the loaded points, at the spheres' lowest points: their centres in x, y.
        loaded = [k for k in range(ch.N_CONTACTS) if forces[3 * k + 2] > 0]
        if loaded:
            xy = d.geom_xpos[self.spheres, :2].tolist()
            fz = [forces[3 * k + 2] for k in loaded]
            total = sum(fz)
            self.zmp = (sum(w * xy[k][0] for w, k in zip(fz, loaded)) / total,
                        sum(w * xy[k][1] for w, k in zip(fz, loaded)) / total)
            st.zmp[0], st.zmp[1] = self.zmp
        # else: the previous CoP stays, as in upc sim.
        if self.door:
            # Equality rows come first in efc; the connect's residual is p_hand − p_handle, so
            # its force (3 rows, world frame) acts on the hand: the reaction on the handle.
            ids = d.efc_id[: d.ne].tolist()
            if self.connect in ids:
                r = ids.index(self.connect)
                self.hand_force[:] = d.efc_force[r:r + 3]
            else:
                self.hand_force[:] = 0.0

        # Geometry and velocities after the step: MuJoCo's step integrated q and v without
        # updating what depends on them.
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        # The ground is the plane z = 0.
        self.penetration = max(0.0, self.radius - float(d.geom_xpos[self.spheres, 2].min()))
        # The fastest loaded point: the velocity of a sphere's lowest point, v + ω × (−r ẑ).
        fastest, r, vel = 0.0, self.radius, self._f6
        for k in loaded:
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_GEOM, self.sphere_list[k], vel, 0)
            w0, w1, _, v0, v1, _ = vel.tolist()
            vx, vy = v0 - w1 * r, v1 + w0 * r
            fastest = max(fastest, vx * vx + vy * vy)
        self.slip = math.sqrt(fastest)
        if self.door:
            self.loop_error = math.dist(d.site_xpos[self.hand], d.site_xpos[self.handle])
            st.door_angle, st.door_velocity = float(d.qpos[self.hq]), float(d.qvel[self.hv])

        st.time = d.time
        self._q[: self.nq] = d.qpos[self.q_from]
        # MuJoCo's free joint: linear velocity in the world frame, angular in the body's.
        self._v[0:3] = d.qvel[self.bv:self.bv + 3] @ d.xmat[self.base_body].reshape(3, 3)
        self._v[3:self.nv] = d.qvel[self.v_from]

    def com(self):
        return self.d.subtree_com[self.base_body]


class Process:
    """The plant on the channels: `upc sim`'s loop (src/sim/process.rs) around a Plant."""

    def __init__(self, plant: Plant, truth_csv):
        self.p = plant
        cfg, sim = plant.cfg, plant.cfg["sim"]
        self.sim = sim
        self.lockstep = sim["mode"] == "lockstep"
        self.session = secrets.randbits(64) or 1
        # Lockstep plays the scenario from 0; real time once a controller drives the robot.
        self.scenario_start = 0.0 if self.lockstep else -1.0
        self.flags = ch.STATE_FLAG_LOCKSTEP if self.lockstep else ch.STATE_FLAG_HOLD
        self.gate = Gate(self.session, plant.n)
        self.supervisor = Supervisor(cfg["hold"], sim["safe_damping"], plant.joint_q())
        self.steps = 0
        self.timing, self.ipc = Histogram(), Histogram()
        self.max_pen = self.max_slip = self.max_loop = 0.0
        self.overruns = 0
        self.record_every = max(1, round(sim["record_period"] / sim["dt"]))
        self.truth = truth_csv
        self.error = None  # what ended the run early

        s = plant.state
        name = cfg["scenario"].encode()
        if len(name) > ch.SCENARIO_NAME_LEN:
            raise BundleError(f"scenario `{cfg['scenario']}` is longer than the "
                              f"{ch.SCENARIO_NAME_LEN} bytes a state announces")
        s.scenario[: len(name)] = name
        s.session = self.session
        s.scenario_hash = int(cfg["scenario_hash"], 16)
        s.force_scale = cfg["force_scale"]
        s.robot_hash = int(cfg["robot_hash"], 16)
        self.gt = ch.GroundTruthMsg()
        self._gt_com = np.ctypeslib.as_array(self.gt.com)

        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        node = (iox2.NodeBuilder.new()
                .name(iox2.NodeName.new(f"upc-mujoco-plant-{os.getpid()}"))
                # SIGINT/SIGTERM are this process's own (a clean stop, complete outputs).
                .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                .create(iox2.ServiceType.Ipc))
        # Resources of dead nodes (a process killed with SIGKILL) would hold their ports.
        node.try_cleanup_dead_nodes()
        self.node = node
        prefix = sim["prefix"]
        self.state_pub = ch.pubsub(node, prefix, "state", ch.StateMsg).publisher_builder().create()
        self.truth_pub = (ch.pubsub(node, prefix, "ground_truth", ch.GroundTruthMsg)
                          .publisher_builder().create())
        self.torque_service = ch.pubsub(node, prefix, "torques", ch.TorqueMsg)
        self.torques = self.torque_service.subscriber_builder().create()
        self.state_ev = ch.event(node, prefix, "state").notifier_builder().create()
        self.truth_ev = ch.event(node, prefix, "ground_truth").notifier_builder().create()
        self.torque_ev = ch.event(node, prefix, "torques").listener_builder().create()
        self.published_at = time.monotonic()

    def publish(self, step_time: float):
        p, s, gt = self.p, self.p.state, self.gt
        # Lockstep never holds: it does not step without torques.
        if not self.lockstep:
            self.flags = {"hold": ch.STATE_FLAG_HOLD, "handover": ch.STATE_FLAG_HOLD,
                          "damping": ch.STATE_FLAG_DAMPING}.get(self.supervisor.phase, 0)
        s.step = self.steps
        s.scenario_start = self.scenario_start
        s.flags = self.flags
        self.state_pub.loan_uninit().write_payload(s).send()
        gt.step, gt.time = self.steps, s.time
        self._gt_com[:] = p.com()
        gt.loop_error = p.loop_error
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
        self.steps += 1
        self.timing.record(p.step_time)  # MuJoCo's step alone
        if p.penetration > self.max_pen:
            self.max_pen = p.penetration
        if p.slip > self.max_slip:
            self.max_slip = p.slip
        if p.loop_error > self.max_loop:
            self.max_loop = p.loop_error
        self.publish(p.step_time)
        if self.truth is not None and self.steps % self.record_every == 0:
            c, z, h = p.com(), p.zmp, p.hand_force
            angle = p.state.door_angle
            self.truth.write(
                f"{p.d.time:.4f},{c[0]:.6f},{c[1]:.6f},{c[2]:.6f},{z[0]:.6f},{z[1]:.6f},"
                f"{h[0]:.4f},{h[1]:.4f},{h[2]:.4f},{angle:.6f},{p.door_torque:.4f},"
                f"{rust_exp(p.loop_error)},{rust_exp(p.penetration)},{rust_exp(p.slip)},"
                f"{int(p.d.solver_niter[0])}\n")

    def receive(self):
        """The next torque message (copied out of shared memory), or None."""
        sample = self.torques.receive()
        if sample is None:
            return None
        msg = ch.TorqueMsg.from_buffer_copy(sample.payload().contents)
        sample.delete()
        return msg

    def controller_alive(self) -> bool:
        """Whether a living process publishes torques: the ports of a SIGKILLed one are
        removed first (they stay registered until someone cleans up)."""
        try:
            self.torque_service.try_cleanup_dead_nodes()
        except Exception:  # noqa: BLE001 - cleanup is best effort; the count below decides
            pass
        return self.torque_service.dynamic_config.number_of_publishers > 0

    def lockstep_loop(self, total: int, stop) -> None:
        cmd = np.zeros(self.p.n)
        while self.steps < total and not stop["now"]:
            want = self.steps
            timeout = self.sim["first_command_timeout" if want == 0 else "lockstep_timeout"]
            deadline = time.monotonic() + timeout
            answered = waiting = False
            while not answered:
                while (msg := self.receive()) is not None:
                    if not self.gate.check(msg, cmd):
                        continue
                    if msg.state_step == want:
                        if want > 0:  # state 0 waits for the controller to start: not IPC
                            rt = time.monotonic() - self.published_at
                            self.ipc.record(max(0.0, rt - msg.compute_ns * 1e-9))
                        answered = True
                        break
                    self.gate.stats["stale"] += 1  # a valid answer to another state
                if answered:
                    break
                now = time.monotonic()
                if now >= deadline:
                    # A controller whose process is alive is slow (starved, in a debugger, or
                    # at the first state waiting for its forecaster), not gone: wait for it (as
                    # `upc sim` does).
                    if self.controller_alive():
                        if not waiting:
                            waiting = True
                            print(f"mujoco plant: no torques for state {want} within "
                                  f"{timeout:.3f} s, but the controller's process is alive: "
                                  "waiting for it", file=sys.stderr)
                        deadline = now + 0.1
                        continue
                    raise TimeoutError(
                        f"lockstep: no torques answering state {want} within {timeout:.3f} s")
                if stop["now"]:
                    return
                # The wake-ups of the samples received above, then a sample that came since
                # (its wake-up just consumed) or a wait for the next one.
                self.torque_ev.try_wait()
                if self.torques.has_samples():
                    continue
                try:
                    woken = self.torque_ev.timed_wait(
                        iox2.Duration.from_secs_f64(min(deadline - now, 0.02)))
                except iox2.ListenerWaitError as e:
                    if "Interrupt" not in str(e):
                        raise
                    continue  # a signal (SIGINT, SIGTERM): the loop checks the stop flag
                if not woken and not self.torques.has_samples():
                    # A controller that connected after this state was sent has neither the
                    # sample nor its wake-up: send the same state again (it skips duplicates).
                    self.state_pub.loan_uninit().write_payload(self.p.state).send()
                    self.state_ev.notify()
            self.step(cmd)

    def realtime_loop(self, total: int, stop) -> None:
        p, period = self.p, self.sim["dt"]
        cmd_timeout = self.sim["command_timeout"]
        commanded, applied = np.zeros(p.n), np.zeros(p.n)
        last_cmd = last_pass = None
        nxt = time.monotonic() + period
        while self.steps < total and not stop["now"]:
            # The command's age counts this plant's live time only: a pass longer than a
            # period was its own stall, with no state for the controller to answer
            # (CommandClock in src/sim/hold.rs).
            top = time.monotonic()
            if last_pass is not None and last_cmd is not None:
                last_cmd = min(last_cmd + max(0.0, top - last_pass - period), top)
            last_pass = top
            fresh = False
            while (msg := self.receive()) is not None:
                # A controller's own fallback (it has no state to control from) does not take
                # the robot from the hold; once it drives the robot, its fallbacks apply.
                holding = self.supervisor.phase in ("hold", "damping")
                if holding and msg.flags & ch.TORQUE_FLAG_FALLBACK:
                    continue
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
                self.log_transition(*tr, t)
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

    def log_transition(self, frm: str, to: str, t: float):
        """The words of upc sim (log_transition in src/sim/process.rs)."""
        hold, sim = self.p.cfg["hold"], self.sim
        text = {
            "handover": f"the controller's torques arrived; handing over from {frm} in "
                        f"{hold['handover']} s",
            "control": "the controller drives the robot",
            "hold": f"no torques for {sim['command_timeout']} s: holding the robot "
                    f"({hold['kind']}; bare damping after {hold['lost_timeout']} s)",
            "damping": f"safe behaviour, joint damping {sim['safe_damping']} N·m·s/rad (no hold)",
        }[to]
        print(f"mujoco plant: t = {t:.3f} s: {text}", file=sys.stderr)

    def summary(self, wall: float) -> dict:
        cfg = self.p.cfg
        return {
            "plant": "mujoco",
            "mujoco_version": mujoco.__version__,
            "settle_sink": self.p.settled,
            "error": self.error,
            "steps": self.steps,
            "sim_time": self.steps * self.p.dt,  # MuJoCo resets d.time when it diverges
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


def print_summary(s: dict, rejected: int):
    """The lines `upc sim` prints at its end (run_cli in src/cli/sim.rs)."""
    c, h = s["commands"], s["hold"]
    print(f"sim: {s['steps']} steps, {s['sim_time']:.3f} s simulated in {s['wall_time']:.3f} s; "
          f"step time p50 {s['step_time_p50'] * 1e6:.1f} µs, p99 {s['step_time_p99'] * 1e6:.1f} "
          f"µs, max {s['step_time_max'] * 1e6:.1f} µs; overruns {s['overruns']}; commands "
          f"accepted {c['accepted']}, rejected {rejected} (length {c['wrong_length']}, non-finite "
          f"{c['non_finite']}, order {c['out_of_order']}, foreign {c['foreign']}), stale "
          f"{c['stale']}; hold steps {h['hold_steps']}, hand-overs {h['handovers']}, controller "
          f"losses {h['losses']}, safe-mode steps {s['safe_mode_steps']}; max penetration "
          f"{s['max_penetration']:.2e} m, max slip {s['max_slip_speed']:.2e} m/s, max loop error "
          f"{s['max_loop_error']:.2e} m; rerun frames 0 written, 0 dropped", flush=True)
    if s["ipc_overhead_p50"] > 0:
        print(f"sim: IPC round-trip overhead (excluding controller compute) p50 "
              f"{s['ipc_overhead_p50'] * 1e6:.1f} µs, p99 {s['ipc_overhead_p99'] * 1e6:.1f} µs, "
              f"max {s['ipc_overhead_max'] * 1e6:.1f} µs", flush=True)


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
    try:
        plant = Plant(args.plant)
        sim = plant.cfg["sim"]
        if args.truth_csv is not None and sim["mode"] != "lockstep":
            raise BundleError("--truth-csv is written from the stepping loop: lockstep only")
        if sim["mode"] not in ("lockstep", "realtime"):
            raise BundleError(f"{args.plant}: sim.mode `{sim['mode']}`")
        total = round(sim["duration"] / sim["dt"]) if sim["duration"] > 0 else sys.maxsize
        truth = None
        if args.truth_csv is not None:
            truth = open(args.truth_csv, "w", buffering=1 << 20)
            truth.write(TRUTH_CSV_HEADER + "\n")
        proc = Process(plant, truth)
    except (BundleError, OSError) as e:
        print(f"mujoco plant: {e}", file=sys.stderr)
        return 2
    except KeyError as e:
        print(f"mujoco plant: {args.plant}: no `{e.args[0]}`", file=sys.stderr)
        return 2
    except CHANNEL_ERRORS as e:
        print(f"mujoco plant: cannot open the channels of prefix `{sim['prefix']}`: "
              f"{type(e).__name__}: {e}", file=sys.stderr)
        return 1
    print(f"mujoco plant: MuJoCo {mujoco.__version__}, robot `{plant.cfg['robot']}` "
          f"(forces × {plant.cfg['force_scale']:.3f}), {sim['mode']} mode, dt = {sim['dt']} s, "
          f"duration = {sim['duration']} s, scenario `{plant.cfg['scenario']}` (hash "
          f"{plant.cfg['scenario_hash']}), prefix `{sim['prefix']}`, door "
          f"{'on' if plant.door else 'off'}, session {proc.session:016x}, hold "
          f"{plant.cfg['hold']['kind']}; settled {plant.settled * 1e3:.2f} mm onto the contacts",
          file=sys.stderr)
    start = time.monotonic()
    status = 0
    try:
        proc.publish(0.0)  # state 0 before any step
        if proc.lockstep:
            proc.lockstep_loop(total, stop)
        else:
            proc.realtime_loop(total, stop)
    except (TimeoutError, Diverged) as e:
        proc.error = str(e)
    except CHANNEL_ERRORS as e:
        proc.error = f"channels: {type(e).__name__}: {e}"
    if proc.error is not None:
        print(f"mujoco plant: {proc.error}", file=sys.stderr)
        status = 1
    wall = time.monotonic() - start
    if truth is not None:
        truth.close()
    s = proc.summary(wall)
    if args.summary is not None:
        args.summary.write_text(json.dumps(s, indent=2) + "\n")
    print_summary(s, proc.gate.rejected())
    return status


if __name__ == "__main__":
    sys.exit(main())
