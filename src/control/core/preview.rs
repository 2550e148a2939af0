//! The tick's preview: the horizon's references, the gain schedule in use, and C0 / C1 on the
//! CoM with the hand previewer's disturbance and the parts' CoM forces (docs/preview_control.md,
//! docs/hand_previewer.md).

use super::ControllerCore;
use super::latch::Latched;
use crate::config::ControllerKind;
use crate::control::frame::{ComForces, MAX_COM_FORCES};
use crate::control::gain_thread::StampedSchedule;
use crate::preview::{AxisState, HandState, PreviewError};

impl ControllerCore {
    /// The horizon's references at t + (i+1)·T: the ZMP reference and the hand set-point.
    /// Returns the ZMP reference.
    pub(super) fn horizon_references(&mut self, latched: &Latched) -> [f64; 2] {
        let off = self.settings.zmp_offset;
        let zref = [
            latched.zmp_center[0] + off[0],
            latched.zmp_center[1] + off[1],
        ];
        let target = HandState {
            pos: latched.hand_target,
            ..Default::default()
        };
        let w = &mut self.work;
        for i in 0..self.settings.horizon {
            w.zmp_ref[i] = zref;
            w.hand_desired[i] = target;
        }
        zref
    }

    /// The gain schedule: C2's, shifted to now, or the nominal one. Returns C2's age (s).
    pub(super) fn take_schedule(&mut self, t: f64, c2: Option<&StampedSchedule>) -> f64 {
        let mut age = 0.0;
        let (s, schedule) = (&self.settings, &mut self.work.schedule);
        match c2.filter(|c| c.seq > 0 && s.kind == ControllerKind::C2) {
            Some(c) => {
                age = t - c.time;
                let shift = (age / s.period).round().max(0.0) as usize;
                let n = s.horizon;
                for i in 0..n {
                    let j = (i + shift).min(n - 1);
                    schedule.kp[i] = c.schedule.kp[j];
                    schedule.kd[i] = c.schedule.kd[j];
                }
            }
            None => {
                schedule.kp.copy_from_slice(&s.nominal.kp);
                schedule.kd.copy_from_slice(&s.nominal.kd);
            }
        }
        age
    }

    /// C0 / C1 on the CoM: the jerk u of each axis, and whether C1 fell back to C0.
    pub(super) fn preview(
        &mut self,
        x: &[AxisState; 2],
        hand: &HandState,
        m_e_ok: bool,
    ) -> ([f64; 2], bool) {
        let mut fallback = false;
        let w = &mut self.work;
        let forces = w.frame.com_forces;
        let zmp = &mut self.zmp;
        let u = match self.settings.kind {
            ControllerKind::C0 if forces.is_empty() => zmp.solve_c0(x, &w.zmp_ref),
            ControllerKind::C0 => {
                add_com_forces(&[], &mut w.f_dis_total, &forces);
                zmp.solve_c1(x, &w.zmp_ref, &w.f_dis_total)
                    .or_else(|_| zmp.solve_c0(x, &w.zmp_ref))
            }
            ControllerKind::C1 | ControllerKind::C2 => {
                let r: Result<[f64; 2], PreviewError> = if m_e_ok {
                    let n = self.settings.horizon;
                    let f_ext = w.frame.hand().horizon.samples();
                    self.previewer
                        .predict(hand, &w.hand_desired, &w.schedule, f_ext, n)
                        .and_then(|()| {
                            // Σ: F_dis plus the parts' CoM forces decaying over the horizon.
                            if forces.is_empty() {
                                return zmp.solve_c1(x, &w.zmp_ref, self.previewer.disturbance());
                            }
                            let f_dis = self.previewer.disturbance();
                            add_com_forces(f_dis, &mut w.f_dis_total, &forces);
                            zmp.solve_c1(x, &w.zmp_ref, &w.f_dis_total)
                        })
                } else {
                    Err(PreviewError::EffectiveMassNotSpd)
                };
                r.or_else(|_| {
                    fallback = true;
                    zmp.solve_c0(x, &w.zmp_ref)
                })
            }
        };
        // solve_c0 only fails on non-finite state, excluded above; keep the last command then.
        let u = u.unwrap_or([0.0; 2]);
        if fallback {
            self.info.preview_fallbacks += 1;
        }
        (u, fallback)
    }
}

/// `out[i]` = `base[i]` (zero past its end) plus each of the parts' CoM forces at preview step
/// i + 1, f·decay^(i+1).
fn add_com_forces(base: &[[f64; 3]], out: &mut [[f64; 3]], forces: &ComForces) {
    let terms = forces.terms();
    let mut w = [1.0; MAX_COM_FORCES];
    for (i, o) in out.iter_mut().enumerate() {
        let b = base.get(i).copied().unwrap_or([0.0; 3]);
        let mut sum = [b[0], b[1]];
        for ((f, decay), w) in terms.iter().zip(w.iter_mut()) {
            *w *= decay;
            sum[0] += f[0] * *w;
            sum[1] += f[1] * *w;
        }
        *o = [sum[0], sum[1], b[2]];
    }
}
