//! What one tick of the controller core produced ([`TickRecord`]), and its columns of the
//! tick's [`Record`] (the parts add theirs: `super::part`).

use crate::col;
use crate::record::Record;

/// What one tick produced, for logging and the summary.
#[derive(Debug, Clone, Copy, Default)]
pub struct TickRecord {
    pub time: f64,
    pub com: [f64; 3],
    pub com_vel: [f64; 3],
    pub com_acc_cmd: [f64; 3],
    pub zmp_ref: [f64; 2],
    /// ZMP the preview predicts for the next preview step.
    pub zmp_pred: [f64; 2],
    /// The centre of pressure the controller used (the ZMP on flat ground; the CSV's
    /// `zmp_meas_*`): the state's, or a part's estimate (the base estimator's from the foot
    /// wrenches, the wrench observer's) where one made it.
    pub cop: [f64; 2],
    pub hand_pos: [f64; 3],
    pub hand_err: f64,
    pub kp: f64,
    pub kd: f64,
    /// F_dis forecast at the first preview step and the hand force forecast there.
    pub f_dis: [f64; 3],
    pub f_ext: [f64; 3],
    pub wbc_solved: bool,
    pub wbc_iterations: u32,
    pub wbc_time: f64,
    /// The preview fell back to C0 this tick (invalid disturbance forecast).
    pub preview_fallback: bool,
    pub schedule_age: f64,
    /// Support rectangle (latched at the first tick, then following the feet), [[x_min, x_max],
    /// [y_min, y_max]] (world frame), so that logs can draw the ZMP against it.
    pub support: [[f64; 2]; 2],
    /// The hand force measured this tick, and the forecast as received for the first preview
    /// step (`f_ext` is the forecast the previewer used: corrected, when the correction is on).
    pub f_meas: [f64; 3],
    pub f_raw: [f64; 3],
    /// The robot is fallen: this tick held joint damping, without preview or QP.
    pub fallen: bool,
}

impl TickRecord {
    /// The core's columns.
    pub fn record(&self, out: &mut Record) {
        out.put(col!(fixed("t", 4)), self.time);
        out.put(col!(fixed("com_x", 5).plot("com/x")), self.com[0]);
        out.put(col!(fixed("com_y", 5).plot("com/y")), self.com[1]);
        out.put(col!(fixed("com_z", 5)), self.com[2]);
        out.put(
            col!(fixed("zmp_ref_x", 5).plot("zmp/reference_x")),
            self.zmp_ref[0],
        );
        out.put(
            col!(fixed("zmp_ref_y", 5).plot("zmp/reference_y")),
            self.zmp_ref[1],
        );
        out.put(
            col!(fixed("zmp_pred_x", 5).plot("zmp/predicted_x")),
            self.zmp_pred[0],
        );
        out.put(
            col!(fixed("zmp_pred_y", 5).plot("zmp/predicted_y")),
            self.zmp_pred[1],
        );
        out.put(
            col!(fixed("zmp_meas_x", 5).plot("zmp/measured_x")),
            self.cop[0],
        );
        out.put(
            col!(fixed("zmp_meas_y", 5).plot("zmp/measured_y")),
            self.cop[1],
        );
        out.put(col!(fixed("hand_err", 5).plot("hand/error")), self.hand_err);
        out.put(col!(fixed("kp", 2).plot("gains/kp")), self.kp);
        out.put(col!(fixed("kd", 2).plot("gains/kd")), self.kd);
        out.put(
            col!(fixed("f_ext_x", 3).plot("forecast/corrected_x")),
            self.f_ext[0],
        );
        out.put(
            col!(fixed("f_ext_y", 3).plot("forecast/corrected_y")),
            self.f_ext[1],
        );
        out.put(col!(fixed("f_ext_z", 3)), self.f_ext[2]);
        out.put(
            col!(fixed("f_dis_x", 3).plot("hand/f_dis_x")),
            self.f_dis[0],
        );
        out.put(col!(fixed("f_dis_y", 3)), self.f_dis[1]);
        out.put(col!(fixed("f_dis_z", 3)), self.f_dis[2]);
        out.put(col!(fixed("hand_x", 5)), self.hand_pos[0]);
        out.put(col!(fixed("hand_y", 5)), self.hand_pos[1]);
        out.put(col!(fixed("hand_z", 5)), self.hand_pos[2]);
        out.put(col!(fixed("sup_x_min", 5)), self.support[0][0]);
        out.put(col!(fixed("sup_x_max", 5)), self.support[0][1]);
        out.put(col!(fixed("sup_y_min", 5)), self.support[1][0]);
        out.put(col!(fixed("sup_y_max", 5)), self.support[1][1]);
        out.put(
            col!(fixed("wbc_us", 1).plot("timing/wbc_us")),
            self.wbc_time * 1e6,
        );
        out.flag(col!(plain("wbc_solved")), self.wbc_solved);
        // 0: the active-set check found the optimum without clarabel.
        out.put(
            col!(fixed("wbc_iterations", 0)),
            f64::from(self.wbc_iterations),
        );
        out.put(
            col!(fixed("f_meas_x", 3).plot("forecast/measured_x")),
            self.f_meas[0],
        );
        out.put(
            col!(fixed("f_meas_y", 3).plot("forecast/measured_y")),
            self.f_meas[1],
        );
        out.put(col!(fixed("f_meas_z", 3)), self.f_meas[2]);
        out.put(
            col!(fixed("f_raw_x", 3).plot("forecast/received_x")),
            self.f_raw[0],
        );
        out.put(
            col!(fixed("f_raw_y", 3).plot("forecast/received_y")),
            self.f_raw[1],
        );
        out.put(col!(fixed("f_raw_z", 3)), self.f_raw[2]);
    }
}
