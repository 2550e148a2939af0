//! The tick's command to the whole-body QP (docs/whole_body_qp.md): the hand's impedance law
//! with the hand force fed back, the CoM acceleration, and the QP's torques; a fallen robot's
//! joint damping instead.

use nalgebra::{Matrix3, Vector3};

use super::ControllerCore;
use super::latch::Latched;
use crate::config::HandForceSource;
use crate::control::TickRecord;
use crate::control::held_object::held_object_force;
use crate::preview::HandState;
use crate::robot::RobotState;
use crate::wbc::{FallbackReason, WbcCommand, WbcStatus};

impl ControllerCore {
    /// The whole-body QP for the tick's CoM acceleration and hand impedance law; the torques in
    /// `tau`. Returns the status, the solver's iterations and the QP's time (s).
    pub(super) fn whole_body(
        &mut self,
        sensed: &RobotState,
        latched: &Latched,
        hand: &HandState,
        m_e_ok: bool,
        tau: &mut [f64],
    ) -> (WbcStatus, u32, f64) {
        let (s, w) = (&self.settings, &mut self.work);
        let (kp, kd) = (w.schedule.kp[0], w.schedule.kd[0]);
        // The measured hand force, when fed back: the QP's equations of motion account for it
        // and the hand task asks for the impedance law's own response to it, eq. (23):
        // M_e ẍ = F_ext + M_e ẍ_cmd, i.e. ẍ = ẍ_cmd + M_e⁻¹ F_ext. Without it the QP ignores the
        // force, which then folds the arm's lightest joints instead of acting through M_e.
        // The corrected force (FC-4's first sample): an estimate's drive friction, which moves
        // with the arm, then does not come back as force at the arm's own speed (negative
        // friction; docs/whole_body_qp.md, "The hand force fed back").
        // `"modelled"`: the same, less the held object's inertia at the hand's own acceleration
        // (below).
        let h = w.frame.hand();
        let source = s.force_source.resolve(h.force_estimated());
        let corrected = source.from_correction() && h.horizon.produced_by().is_some();
        let f_hand = Vector3::from(if corrected {
            h.horizon.samples()[0]
        } else {
            h.force_used(&sensed.hand_force)
        });
        // Only a force the parts vouch for (the wrist tare: not while it is taken, nor after a
        // refused one).
        let fed_back = s.force_feedback && h.trusted && f_hand.iter().all(|x| x.is_finite());
        let f_hand = if fed_back { f_hand } else { Vector3::zeros() };
        let law = (latched.hand_target - hand.pos) * kp - hand.vel * kd;
        // `hand.stiffness = "decoupled"`: the arm's force M_d ẍ_law with M_d = P M_e P + Q M_e Q
        // instead of M_e ẍ_law, i.e. ẍ = M_e⁻¹ M_d ẍ_law; the QP's own law is corrected through
        // its acceleration feed-forward.
        let coupling = match s.held.stiffness_projector {
            Some(p) if m_e_ok => {
                let q = Matrix3::identity() - p;
                let m_e = w.op.m_e;
                w.op.lambda_inv * (p * m_e * p + q * m_e * q) * law - law
            }
            _ => Vector3::zeros(),
        };
        let f_hand = if source == HandForceSource::Modelled && corrected && fed_back && m_e_ok {
            self.info.hand_force_modelled_ticks += 1;
            held_object_force(&f_hand, &w.op.m_e, &s.held.mass, &(law + coupling))
        } else {
            f_hand
        };
        let acc_ext = if m_e_ok {
            w.op.lambda_inv * f_hand
        } else {
            Vector3::zeros()
        };
        self.state.hand_acc_cmd = law + coupling + acc_ext;

        // Whole-body QP.
        let cmd = WbcCommand {
            com_acc: self.state.com_acc_cmd,
            hand_pos_des: latched.hand_target,
            hand_vel_des: Vector3::zeros(),
            hand_acc_des: acc_ext + coupling,
            kp,
            kd,
            hand_force: f_hand,
            posture_ref: None,
        };
        let (q, v) = (w.frame.q.or(&sensed.q), w.frame.v.or(&sensed.v));
        let out = self.wbc.solve(&self.model, &mut w.data, q, v, &cmd);
        let n = out.tau.len().min(tau.len());
        tau[..n].copy_from_slice(&out.tau.as_slice()[..n]);
        (out.status, out.iterations, out.tick_time.as_secs_f64())
    }

    /// A fallen robot's tick: joint damping toward rest (`wbc.fallback_damping`), no preview,
    /// no QP; the record keeps what was measured.
    pub(super) fn hold_fallen(
        &mut self,
        sensed: &RobotState,
        [com, vcom]: [Vector3<f64>; 2],
        hand: &HandState,
        latched: &Latched,
        tau: &mut [f64],
    ) -> WbcStatus {
        self.info.fallen_ticks += 1;
        // Within the drives' limits as every other command: a falling robot's joints move fast
        // (a bus clamped these on a G1 that fell, `tests/bus.rs`).
        let f = &self.work.frame;
        let qd = f.v.or(&sensed.v).as_slice().get(6..).unwrap_or(&[]);
        let limits = self.wbc.torque_limits().as_slice();
        crate::wbc::damping_torques(self.settings.fallen_damping, qd, limits, tau);
        self.last = TickRecord {
            time: sensed.time,
            com: com.into(),
            com_vel: vcom.into(),
            cop: *f.cop.or(&sensed.cop),
            hand_pos: hand.pos.into(),
            hand_err: (hand.pos - latched.hand_target).norm(),
            support: latched.support,
            f_meas: f.hand().force_used(&sensed.hand_force),
            fallen: true,
            ..TickRecord::default()
        };
        WbcStatus::Fallback(FallbackReason::Fallen)
    }
}
