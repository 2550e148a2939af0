//! The robot's motor slots and upc's joints: which joint each slot of `LowCmd_` / `LowState_`
//! drives, from the robot description's `[bus]` table, checked against the URDF at start-up.

use super::unitree_hg::MOTOR_SLOTS;
use crate::robot::Robot;

/// What one motor slot is to upc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Slot {
    /// A joint upc controls: its index in `q` and `v`, its actuated index (in the torque
    /// vector) and its effort limit (N·m; infinite when the URDF gives none).
    Joint {
        q: usize,
        v: usize,
        actuated: usize,
        effort: f64,
    },
    /// A joint the description locks: held at `q` by the drive (upc neither models nor moves it).
    Locked { q: f64 },
    /// No joint on this robot.
    Unused,
}

/// Every slot's meaning.
#[derive(Debug, Clone)]
pub struct MotorMap {
    pub slots: [Slot; MOTOR_SLOTS],
    /// The joint names, by slot (for ROS 2's JointState).
    pub names: Vec<String>,
    /// The drives' hold gains (kp, kd) by slot, from the description's `[bus]`.
    pub hold: [(f64, f64); MOTOR_SLOTS],
}

impl MotorMap {
    /// The map of `robot`, or why it cannot be driven on a Unitree bus: no `[bus]` table, a slot
    /// naming no joint of the URDF, a joint twice, a joint upc moves that no slot drives, or hold
    /// gains that are not one finite, non-negative pair per slot.
    pub fn new(robot: &Robot) -> Result<Self, String> {
        let name = robot.name();
        let spec = robot.description.bus.as_ref().ok_or_else(|| {
            format!("robot `{name}` has no `[bus]` table: upc does not know its motor slots")
        })?;
        if spec.kind != "unitree_hg" {
            return Err(format!(
                "robot `{name}`: bus kind `{}` is not one upc speaks (`unitree_hg`)",
                spec.kind
            ));
        }
        if spec.slots.len() > MOTOR_SLOTS {
            return Err(format!(
                "robot `{name}`: {} motor slots listed, the bus has {MOTOR_SLOTS}",
                spec.slots.len()
            ));
        }
        let model = &robot.model;
        let base = if model.has_floating_base() { 6 } else { 0 };
        let mut slots = [Slot::Unused; MOTOR_SLOTS];
        for (k, joint) in spec.slots.iter().enumerate() {
            if spec.slots[..k].contains(joint) {
                return Err(format!(
                    "robot `{name}`: joint `{joint}` is in two motor slots"
                ));
            }
            slots[k] = if let Some(&q) = robot.locked.get(joint) {
                Slot::Locked { q }
            } else {
                let id = model.joint_id(joint).map_err(|_| {
                    format!(
                        "robot `{name}`: motor slot {k} names `{joint}`, not a joint of its URDF"
                    )
                })?;
                let j = &model.joints[id];
                if j.nv() != 1 {
                    return Err(format!(
                        "robot `{name}`: motor slot {k} names `{joint}`, which is not a 1-DoF joint"
                    ));
                }
                Slot::Joint {
                    q: j.idx_q,
                    v: j.idx_v,
                    actuated: j.idx_v - base,
                    effort: j.limits.effort,
                }
            };
        }
        let driven = slots
            .iter()
            .filter(|s| matches!(s, Slot::Joint { .. }))
            .count();
        if driven != model.nv - base {
            let missing: Vec<&str> = model
                .joints
                .iter()
                .filter(|j| j.nv() == 1 && !spec.slots.contains(&j.name))
                .map(|j| j.name.as_str())
                .collect();
            return Err(format!(
                "robot `{name}`: joints upc moves that no motor slot drives: {missing:?}"
            ));
        }
        let mut hold = [(0.0, 0.0); MOTOR_SLOTS];
        for (key, gains) in [("hold_kp", &spec.hold_kp), ("hold_kd", &spec.hold_kd)] {
            if gains.len() != spec.slots.len() {
                return Err(format!(
                    "robot `{name}`: `[bus] {key}` has {} gains for {} motor slots (one per slot)",
                    gains.len(),
                    spec.slots.len()
                ));
            }
            if let Some((k, g)) = gains
                .iter()
                .enumerate()
                .find(|(_, g)| !(g.is_finite() && **g >= 0.0))
            {
                return Err(format!(
                    "robot `{name}`: `[bus] {key}` of slot {k} (`{}`) must be finite and ≥ 0, got {g}",
                    spec.slots[k]
                ));
            }
        }
        for (k, h) in hold.iter_mut().enumerate().take(spec.slots.len()) {
            *h = (spec.hold_kp[k], spec.hold_kd[k]);
        }
        Ok(Self {
            slots,
            names: spec.slots.clone(),
            hold,
        })
    }

    /// The slots upc drives, with their joint's indices.
    pub fn joints(&self) -> impl Iterator<Item = (usize, usize, usize, usize, f64)> + '_ {
        self.slots.iter().enumerate().filter_map(|(k, s)| match *s {
            Slot::Joint {
                q,
                v,
                actuated,
                effort,
            } => Some((k, q, v, actuated, effort)),
            _ => None,
        })
    }
}
