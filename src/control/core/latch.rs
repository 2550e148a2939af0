//! The references a session latches at its first tick (the support and the ZMP reference's
//! centre, the CoM height, the hand target), the support following the feet, and the fall
//! detector.

use nalgebra::Vector3;

use super::ControllerCore;

#[derive(Debug, Clone, Copy)]
pub(super) struct Latched {
    pub zmp_center: [f64; 2],
    /// Axis-aligned support rectangle of the sole corners, [[x_min, x_max], [y_min, y_max]].
    pub support: [[f64; 2]; 2],
    pub com_height: f64,
    pub hand_target: Vector3<f64>,
}

impl ControllerCore {
    /// The support rectangle of the sole corners where the state puts them,
    /// [[x_min, x_max], [y_min, y_max]], and the corners' centroid (the feet centre; the sole
    /// frames' midpoint on robots whose sole frame is off the sole's centre).
    fn support_now(&self) -> ([[f64; 2]; 2], [f64; 2]) {
        let mut support = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
        let mut centre = [0.0; 2];
        let corners = self.wbc.contact_frames();
        for f in corners {
            let p = self.work.data.o_m_f[f].trans;
            for a in 0..2 {
                support[a] = [support[a][0].min(p[a]), support[a][1].max(p[a])];
                centre[a] += p[a] / corners.len() as f64;
            }
        }
        (support, centre)
    }

    /// The references latched at the first tick of a session: the support and the ZMP
    /// reference's centre, the CoM height, the hand target. The support and the centre then
    /// follow the corners as measured (`controller.support_follow`): a foot that creeps or slips
    /// takes the reference with it, where a latched one would be left behind at the support's
    /// edge (MuJoCo's feet creep ~0.2 mm a push; an hour of pushes moves them by centimetres).
    pub(super) fn latch(&mut self, com_height: f64, hand_pos: Vector3<f64>) -> Latched {
        let (support, centre) = self.support_now();
        let s = &self.settings;
        let alpha = if s.support_follow > 0.0 {
            (s.dt / s.support_follow).min(1.0)
        } else {
            0.0
        };
        let l = self.state.latched.get_or_insert(Latched {
            zmp_center: centre,
            support,
            com_height,
            hand_target: hand_pos,
        });
        for a in 0..2 {
            l.zmp_center[a] += alpha * (centre[a] - l.zmp_center[a]);
            for b in 0..2 {
                l.support[a][b] += alpha * (support[a][b] - l.support[a][b]);
            }
        }
        *l
    }

    /// Whether the robot is fallen: its CoM `drop` (m) below the height latched at the
    /// session's start is more than `fall_drop` of that height. Once fallen, fallen until the
    /// plant restarts ([`Self::reset`]): a fallen humanoid does not stand up by itself, and its
    /// QP (contacts that no longer hold) is mostly infeasible and costly to try.
    pub(super) fn detect_fall(&mut self, t: f64, drop: f64, height: f64) -> bool {
        let fall_drop = self.settings.fall_drop;
        if !self.state.fallen && fall_drop > 0.0 && drop > fall_drop * height {
            self.state.fallen = true;
            self.info.falls += 1;
            tracing::error!(
                "the robot has fallen at t = {t:.3} s (CoM {:.0} mm below its height of {:.0} mm): \
                 joint damping, no balance control, until the plant restarts",
                drop * 1e3,
                height * 1e3
            );
        }
        self.state.fallen
    }
}
