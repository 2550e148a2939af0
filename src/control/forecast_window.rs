//! The controller's copy of the latest valid force forecast. Incoming messages are validated
//! (rejected, counted and reported, never applied when bad) and copied into preallocated storage
//! so the loop reads a stable window. Past its end, the forecast decays to zero.

use crate::channels::{ForecastMsg, MAX_FORECAST};

/// Why a forecast message was rejected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ForecastRejection {
    #[error("forecast length {0} is 0 or beyond the capacity {MAX_FORECAST}")]
    BadLength(u32),
    #[error("forecast step dt = {0} s is not a positive finite number")]
    BadStep(f64),
    #[error("forecast sample {0} is not finite")]
    NotFinite(usize),
    #[error("forecast starts at t0 = {t0} s, too far from the current time {now} s")]
    OutOfTime { t0: f64, now: f64 },
    #[error("forecast seq {got} does not follow {last}")]
    OutOfOrder { got: u64, last: u64 },
    #[error("forecast lifts the robot: M g − F_z ≤ 0 at sample {0}")]
    LiftOff(usize),
}

/// Rejected forecast messages by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RejectionCounts {
    pub bad_length: u64,
    pub bad_step: u64,
    pub not_finite: u64,
    pub out_of_time: u64,
    pub out_of_order: u64,
    pub lift_off: u64,
}

impl RejectionCounts {
    fn count(&mut self, r: &ForecastRejection) {
        *match r {
            ForecastRejection::BadLength(_) => &mut self.bad_length,
            ForecastRejection::BadStep(_) => &mut self.bad_step,
            ForecastRejection::NotFinite(_) => &mut self.not_finite,
            ForecastRejection::OutOfTime { .. } => &mut self.out_of_time,
            ForecastRejection::OutOfOrder { .. } => &mut self.out_of_order,
            ForecastRejection::LiftOff(_) => &mut self.lift_off,
        } += 1;
    }
}

pub struct ForecastWindow {
    forces: Vec<[f64; 3]>,
    t0: f64,
    dt: f64,
    len: usize,
    last_seq: u64,
    /// The accepted window's promise (`ForecastMsg::period`, 0: none) and scenario hash.
    period: f64,
    scenario_hash: u64,
    /// Accepted and rejected messages so far.
    pub accepted: u64,
    pub rejected: u64,
    pub rejections: RejectionCounts,
    /// Accepted windows whose seq went back: a restarted forecaster.
    pub restarts: u64,
    /// Limits: how far before / after the current time a window may start (s).
    max_age: f64,
    max_lead: f64,
    /// Time constant of the decay to zero past the window's end (s).
    decay: f64,
    /// M g: a forecast force with F_z ≥ M g would lift the robot.
    weight: f64,
    /// The held object's free direction e (unit), if the forecast is taken along it.
    free_dir: Option<[f64; 3]>,
    /// Where the hand feels a push along e (FC-0b): d with eᵀd = 1; e itself when unset.
    felt_dir: Option<[f64; 3]>,
}

impl ForecastWindow {
    pub fn new(max_age: f64, max_lead: f64, decay: f64, weight: f64) -> Self {
        Self {
            forces: vec![[0.0; 3]; MAX_FORECAST],
            t0: 0.0,
            dt: 1.0,
            len: 0,
            last_seq: 0,
            period: 0.0,
            scenario_hash: 0,
            accepted: 0,
            rejected: 0,
            rejections: RejectionCounts::default(),
            restarts: 0,
            max_age,
            max_lead,
            decay,
            weight,
            free_dir: None,
            felt_dir: None,
        }
    }

    /// Takes each accepted sample as the push along `e` alone, f ← e eᵀ f (FC-0,
    /// `controller.forecast_on_free_direction`): a held door turns only that into hinge
    /// torque, its hinge takes the rest. `e` need not be unit; a zero or non-finite `e` leaves
    /// the forecast as received.
    pub fn with_free_direction(mut self, e: [f64; 3]) -> Self {
        let n = e.iter().map(|x| x * x).sum::<f64>().sqrt();
        self.free_dir = (n.is_finite() && n > 0.0).then(|| e.map(|x| x / n));
        self
    }

    /// FC-0b: a push of F_e along the path reaches the held hand as F_e d, d = K_e e / (eᵀ K_e e)
    /// (the arm's stiffness K_e pushes back along K_e e, the hinge takes the rest). Windows
    /// accepted from now on are taken so. `None`, a non-finite `d` or one with eᵀd away from 1
    /// (a d of another path) takes them along e.
    pub fn set_felt_direction(&mut self, d: Option<[f64; 3]>) {
        self.felt_dir = match (self.free_dir, d) {
            (Some(e), Some(d))
                if d.iter().all(|x| x.is_finite())
                    && (e[0] * d[0] + e[1] * d[1] + e[2] * d[2] - 1.0).abs() < 1e-9 =>
            {
                Some(d)
            }
            _ => None,
        };
    }

    /// Validate `msg` at time `now` and take it if good.
    pub fn offer(&mut self, msg: &ForecastMsg, now: f64) -> Result<(), ForecastRejection> {
        let r = self.check(msg, now);
        match r {
            Ok(()) => {
                if self.len > 0 && msg.seq <= self.last_seq {
                    self.restarts += 1;
                }
                let n = msg.len as usize;
                self.forces[..n].copy_from_slice(&msg.forces[..n]);
                if let Some(e) = self.free_dir {
                    let d = self.felt_dir.unwrap_or(e);
                    for f in &mut self.forces[..n] {
                        let along = e[0] * f[0] + e[1] * f[1] + e[2] * f[2];
                        *f = d.map(|x| x * along);
                    }
                }
                self.t0 = msg.t0;
                self.dt = msg.dt;
                self.len = n;
                self.last_seq = msg.seq;
                self.period = if msg.period.is_finite() && msg.period > 0.0 {
                    msg.period
                } else {
                    0.0
                };
                self.scenario_hash = msg.scenario_hash;
                self.accepted += 1;
            }
            Err(e) => {
                self.rejected += 1;
                self.rejections.count(&e);
            }
        }
        r
    }

    /// Drop the window (its times belong to a simulator that restarted) and accept the next
    /// valid message whatever its seq. Counters are kept.
    pub fn reset(&mut self) {
        self.len = 0;
        self.last_seq = 0;
    }

    fn check(&self, msg: &ForecastMsg, now: f64) -> Result<(), ForecastRejection> {
        let n = msg.len as usize;
        if n == 0 || n > MAX_FORECAST {
            return Err(ForecastRejection::BadLength(msg.len));
        }
        if !(msg.dt.is_finite() && msg.dt > 0.0) {
            return Err(ForecastRejection::BadStep(msg.dt));
        }
        if !msg.t0.is_finite() || msg.t0 < now - self.max_age || msg.t0 > now + self.max_lead {
            return Err(ForecastRejection::OutOfTime { t0: msg.t0, now });
        }
        // A seq that goes back is a replayed old window, unless the window also starts later
        // than the current one: then it is a restarted forecaster counting from 1 again.
        if self.len > 0 && msg.seq <= self.last_seq && msg.t0 <= self.t0 {
            return Err(ForecastRejection::OutOfOrder {
                got: msg.seq,
                last: self.last_seq,
            });
        }
        for (i, f) in msg.forces[..n].iter().enumerate() {
            if !f.iter().all(|v| v.is_finite()) {
                return Err(ForecastRejection::NotFinite(i));
            }
            if self.weight - f[2] <= 0.0 {
                return Err(ForecastRejection::LiftOff(i));
            }
        }
        Ok(())
    }

    /// Whether the window is its forecaster's word at `t`: it promised a period and `t` lies
    /// within it (see [`crate::channels::window_covers`]). False without a promise.
    pub fn promised_at(&self, t: f64) -> bool {
        self.len > 0 && self.period > 0.0 && crate::channels::window_covers(self.t0, self.period, t)
    }

    /// Whether the window came with a period promise (`ForecastMsg::period` > 0).
    pub fn has_promise(&self) -> bool {
        self.len > 0 && self.period > 0.0
    }

    /// The scenario hash of the accepted window (0: unknown, or no window).
    pub fn scenario_hash(&self) -> u64 {
        if self.len > 0 { self.scenario_hash } else { 0 }
    }

    /// Whether a window covers time `t`.
    #[inline]
    pub fn covers(&self, t: f64) -> bool {
        self.len > 0 && t >= self.t0 && t <= self.end()
    }

    fn end(&self) -> f64 {
        self.t0 + (self.len.max(1) - 1) as f64 * self.dt
    }

    /// The forecast force at `t`: linear interpolation inside the window, the first sample
    /// before it, an exponential decay from the last sample after it, zero with no window.
    // Always inlined: called per horizon sample, out of line its call was a third of its cost
    // (perf, `control/c1_tick`).
    #[inline(always)]
    pub fn at(&self, t: f64) -> [f64; 3] {
        if self.len == 0 {
            return [0.0; 3];
        }
        let x = (t - self.t0) / self.dt;
        if x <= 0.0 {
            return self.forces[0];
        }
        // x > 0 here, so truncation is floor (and no libm call: the build targets baseline
        // x86-64, which has no rounding instruction).
        let i = x as usize;
        if i + 1 >= self.len {
            let last = self.forces[self.len - 1];
            let k = (-(t - self.end()).max(0.0) / self.decay).exp();
            return last.map(|v| v * k);
        }
        let w = x - i as f64;
        let (a, b) = (self.forces[i], self.forces[i + 1]);
        [0, 1, 2].map(|c| a[c] + w * (b[c] - a[c]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(seq: u64, t0: f64, dt: f64, len: u32, f: f64) -> Box<ForecastMsg> {
        let mut m: Box<ForecastMsg> = Box::default();
        m.seq = seq;
        m.t0 = t0;
        m.dt = dt;
        m.len = len;
        for (i, s) in m.forces.iter_mut().enumerate() {
            *s = [f * i as f64, 0.0, 0.0];
        }
        m
    }

    /// FC-0: with a held door's free direction each accepted sample is its component along
    /// it (a push turned 30° off the path keeps cos 30° of itself, along the path); without
    /// one, or with a zero direction, the forecast is as received.
    #[test]
    fn a_forecast_is_taken_along_the_held_objects_path() {
        let mut m = msg(1, 0.0, 0.01, 10, 0.0);
        for s in m.forces[..10].iter_mut() {
            *s = [-40.0 * 30f64.to_radians().cos(), 20.0, 3.0];
        }
        let e = [0.99f64, 0.1, 0.0];
        let n = e.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0).with_free_direction(e);
        w.offer(&m, 0.0).unwrap();
        let f = w.at(0.045);
        let along = (e[0] * m.forces[0][0] + e[1] * m.forces[0][1]) / n;
        for c in 0..3 {
            assert!((f[c] - along * e[c] / n).abs() < 1e-12, "{f:?}");
        }
        // Across the path: nothing.
        let across = -e[1] * f[0] + e[0] * f[1];
        assert!(across.abs() < 1e-12, "{f:?}");
        for mut w in [
            ForecastWindow::new(1.0, 1.0, 0.1, 300.0),
            ForecastWindow::new(1.0, 1.0, 0.1, 300.0).with_free_direction([0.0; 3]),
        ] {
            w.offer(&m, 0.0).unwrap();
            assert_eq!(w.at(0.045), m.forces[4]);
        }
    }

    /// FC-0b: with a felt direction d (eᵀd = 1) each accepted sample is d (eᵀf); a d that
    /// does not belong to e (eᵀd ≠ 1), or none, leaves FC-0's e (eᵀf).
    #[test]
    fn a_forecast_is_felt_where_the_held_hand_pushes_back() {
        let mut m = msg(1, 0.0, 0.01, 10, 0.0);
        for s in m.forces[..10].iter_mut() {
            *s = [-40.0, 20.0, 3.0];
        }
        let e = [1.0f64, 0.0, 0.0];
        let d = [1.0, -0.3, 0.25];
        let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0).with_free_direction(e);
        w.set_felt_direction(Some(d));
        w.offer(&m, 0.0).unwrap();
        assert_eq!(w.at(0.045), [-40.0, 12.0, -10.0]);
        for bad in [Some([0.9, -0.3, 0.25]), Some([f64::NAN, 0.0, 0.0]), None] {
            let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0).with_free_direction(e);
            w.set_felt_direction(bad);
            w.offer(&m, 0.0).unwrap();
            assert_eq!(w.at(0.045), [-40.0, 0.0, 0.0], "{bad:?}");
        }
        // Nothing held: no felt direction either.
        let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0);
        w.set_felt_direction(Some(d));
        w.offer(&m, 0.0).unwrap();
        assert_eq!(w.at(0.045), m.forces[4]);
    }

    #[test]
    fn validates_and_interpolates() {
        let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0);
        assert_eq!(w.at(0.3), [0.0; 3]);
        w.offer(&msg(1, 0.0, 0.01, 100, 1.0), 0.0).unwrap();
        assert!((w.at(0.055)[0] - 5.5).abs() < 1e-9);
        // Past the end: decays from the last sample.
        assert!(w.at(0.99 + 0.1)[0] < 99.0 * 0.37 && w.at(0.99 + 0.1)[0] > 0.0);
        assert_eq!(
            w.offer(&msg(2, 0.0, 0.0, 10, 1.0), 0.0),
            Err(ForecastRejection::BadStep(0.0))
        );
        assert_eq!(
            w.offer(&msg(2, 0.0, -1.0, 10, 1.0), 0.0),
            Err(ForecastRejection::BadStep(-1.0))
        );
        assert!(matches!(
            w.offer(&msg(2, 0.0, 0.01, 0, 1.0), 0.0),
            Err(ForecastRejection::BadLength(0))
        ));
        assert!(matches!(
            w.offer(&msg(2, 0.0, 0.01, MAX_FORECAST as u32 + 1, 1.0), 0.0),
            Err(ForecastRejection::BadLength(_))
        ));
        assert!(matches!(
            w.offer(&msg(2, -5.0, 0.01, 10, 1.0), 0.0),
            Err(ForecastRejection::OutOfTime { .. })
        ));
        assert!(matches!(
            w.offer(&msg(2, 50.0, 0.01, 10, 1.0), 0.0),
            Err(ForecastRejection::OutOfTime { .. })
        ));
        assert!(matches!(
            w.offer(&msg(1, 0.0, 0.01, 10, 1.0), 0.0),
            Err(ForecastRejection::OutOfOrder { .. })
        ));
        assert!(matches!(
            w.offer(&msg(1, -0.5, 0.01, 10, 1.0), 0.0),
            Err(ForecastRejection::OutOfOrder { .. })
        ));
        let mut nan = msg(3, 0.0, 0.01, 10, 1.0);
        nan.forces[4][1] = f64::NAN;
        assert_eq!(w.offer(&nan, 0.0), Err(ForecastRejection::NotFinite(4)));
        let mut lift = msg(3, 0.0, 0.01, 10, 1.0);
        lift.forces[2][2] = 400.0;
        assert_eq!(w.offer(&lift, 0.0), Err(ForecastRejection::LiftOff(2)));
        let mut inf_t0 = msg(3, f64::INFINITY, 0.01, 10, 1.0);
        inf_t0.t0 = f64::INFINITY;
        assert!(matches!(
            w.offer(&inf_t0, 0.0),
            Err(ForecastRejection::OutOfTime { .. })
        ));
        assert_eq!(
            w.offer(&msg(3, 0.0, f64::NAN, 10, 1.0), 0.0)
                .map_err(|e| e.to_string()),
            Err("forecast step dt = NaN s is not a positive finite number".into())
        );
        assert_eq!((w.accepted, w.rejected), (1, 12));
        assert_eq!(
            w.rejections,
            RejectionCounts {
                bad_length: 2,
                bad_step: 3,
                not_finite: 1,
                out_of_time: 3,
                out_of_order: 2,
                lift_off: 1,
            }
        );
        // The rejected ones changed nothing.
        assert!((w.at(0.055)[0] - 5.5).abs() < 1e-9);
    }

    #[test]
    fn restarts_of_forecaster_and_simulator() {
        let mut w = ForecastWindow::new(1.0, 1.0, 0.1, 300.0);
        w.offer(&msg(40, 5.0, 0.01, 100, 1.0), 5.0).unwrap();
        // A restarted forecaster counts from 1 again with a later window: taken.
        w.offer(&msg(1, 5.2, 0.01, 100, 1.0), 5.2).unwrap();
        assert_eq!(w.restarts, 1);
        assert!(w.covers(5.3));
        // A restarted simulator starts over at t = 0: the old window is dropped, any seq goes.
        w.reset();
        assert!(!w.covers(5.3) && w.at(5.3) == [0.0; 3]);
        w.offer(&msg(2, 0.0, 0.01, 100, 1.0), 0.0).unwrap();
        assert_eq!((w.accepted, w.rejected, w.restarts), (3, 0, 1));
    }
}
