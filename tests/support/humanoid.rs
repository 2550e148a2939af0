//! The controller on the humanoid at its home posture, for control-loop tests.

use upc::channels::{ForecastMsg, StateMsg};
use upc::config::{Config, ControllerKind};
use upc::control::contract::read_state;
use upc::control::{ControllerCore, ForecastWindow, StampedSchedule, TickError};
use upc::robot::{Robot, RobotState};
use upc::wbc::WbcStatus;

/// A controller core with the humanoid standing at home, its state message (read into the
/// robot as measured at each tick, as the loop does), an empty forecast window and a torque
/// buffer.
pub struct Rig {
    pub core: ControllerCore,
    pub state: StateMsg,
    pub sensed: RobotState,
    pub window: ForecastWindow,
    pub tau: Vec<f64>,
}

pub fn rig(config: &Config, kind: ControllerKind) -> Rig {
    rig_of(&Robot::embedded_default().expect("robot"), config, kind)
}

/// [`rig`] for `robot` (its model, its reduced models, its frames).
pub fn rig_of(robot: &Robot, config: &Config, kind: ControllerKind) -> Rig {
    let (model, q) = (&robot.model, &robot.home);
    let mut state = StateMsg {
        nq: model.nq as u32,
        nv: model.nv as u32,
        ..Default::default()
    };
    state.q[..model.nq].copy_from_slice(q.as_slice());
    let tau = vec![0.0; model.nv - 6];
    let core =
        ControllerCore::new(robot, config, kind, 0.001, [100.0, 20.0], [0.0, 0.0]).expect("core");
    Rig {
        core,
        state,
        sensed: RobotState::new(model.nq, model.nv),
        window: ForecastWindow::new(1.0, 1.0, 0.2, 300.0),
        tau,
    }
}

impl Rig {
    /// One tick of the core on the state message, read as the loop reads it (no robot hash
    /// checked), with C2's schedule `c2`.
    pub fn tick(&mut self, c2: Option<&StampedSchedule>) -> Result<WbcStatus, TickError> {
        read_state(&self.state, 0, &mut self.sensed)?;
        self.core
            .tick(&self.sensed, &self.window, c2, &mut self.tau)
    }

    /// Offers [`push_forecast`]`(0, fx)` at t = 0.
    pub fn offer_push(&mut self, fx: f64) {
        self.window
            .offer(&push_forecast(0.0, fx), 0.0)
            .expect("valid forecast");
    }

    /// Makes the state a robot's: the base unmeasured (NaN, flagged), the IMU at rest on the
    /// home pose, each foot carrying half of `weight` (N). The controller then estimates its base.
    #[allow(dead_code)]
    pub fn without_base(&mut self, weight: f64) {
        let s = &mut self.state;
        let q: [f64; 4] = std::array::from_fn(|k| s.q[3 + k]);
        let r = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[3], q[0], q[1], q[2],
        ));
        let up = r.inverse() * nalgebra::Vector3::new(0.0, 0.0, 9.81);
        s.imu_orientation = q;
        s.imu_linear_acceleration = [up.x, up.y, up.z];
        s.foot_wrenches = [[0.0, 0.0, weight / 2.0, 0.0, 0.0, 0.0]; 2];
        s.q[..7].fill(f64::NAN);
        s.v[..6].fill(f64::NAN);
        s.flags |= upc::channels::STATE_FLAG_BASE_UNMEASURED;
    }

    /// Ticks the frozen state at t = k ms for each k of `ticks`; the ticks that returned an
    /// error. Allocation-free itself (the allocation tests count inside it).
    pub fn tick_frozen(&mut self, ticks: std::ops::Range<usize>) -> usize {
        let mut errors = 0;
        for k in ticks {
            self.state.time = k as f64 * 0.001;
            self.state.stamps = [self.state.time; 4];
            errors += usize::from(self.tick(None).is_err());
        }
        errors
    }
}

/// A forecast from `t0` (5 ms samples, 2.5 s) of a constant push `fx` starting at sample 100.
pub fn push_forecast(t0: f64, fx: f64) -> Box<ForecastMsg> {
    let mut m: Box<ForecastMsg> = Box::default();
    m.seq = 1;
    m.t0 = t0;
    m.dt = 0.005;
    m.len = 500;
    for (i, s) in m.forces.iter_mut().enumerate().take(500) {
        *s = [if i > 100 { fx } else { 0.0 }, 0.0, 0.0];
    }
    m
}
