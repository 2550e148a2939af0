//! The typed configuration. Defaults live in `config/default.toml` (embedded), not in code, so a
//! user reads every value in one file.

use serde::Deserialize;

use super::{ConfigError, Layers};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub robot: RobotConfig,
    pub preview: PreviewConfig,
    pub hand: HandConfig,
    pub gain_search: GainSearchConfig,
    pub wbc: WbcConfig,
    pub controller: ControllerConfig,
}

/// The world the controller believes the robot in. What follows from the robot itself (mass,
/// CoM height, support, M_e, frames) is no setting: it comes from the robot's model
/// (`crate::robot::ReducedModel`, `crate::robot::Robot`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Gravity g (m/s²): the cart-table's and the controller's whole-body dynamics'.
    pub gravity: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LqSolverKind {
    /// Backward Riccati recursion, O(N).
    Riccati,
    /// Condensed dense normal equations (docs/preview_control.md, eq. (9), (15)), O(N³): the
    /// reference.
    Dense,
}

/// ZMP preview controller parameters (docs/preview_control.md, eq. (7); docs/disturbance.md).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreviewConfig {
    /// Preview sampling period T (s).
    pub period: f64,
    /// Horizon length N (steps); the preview time is N·T.
    pub horizon: usize,
    /// ZMP tracking weight Q_e.
    pub q_e: f64,
    /// Jerk weight R.
    pub r: f64,
    pub solver: LqSolverKind,
    /// Keep the predicted ZMP inside the support bounds as hard constraints (QP, clarabel).
    pub zmp_constraints: bool,
    /// The last predicted state pays the infinite horizon's tail (PC-T,
    /// docs/preview_control.md); false: the paper's finite horizon.
    pub terminal_cost: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DampingMode {
    /// K_d = 2 ζ √K_p follows the stiffness.
    Critical,
    /// K_d is a decision variable of its own.
    Free,
}

/// Hand impedance (docs/hand_previewer.md, eq. (17), (23)).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandConfig {
    /// Nominal stiffness K_p (1/s²), the fixed gain of C0 and C1.
    pub kp: f64,
    pub damping: DampingMode,
    /// ζ for `damping = "critical"`.
    pub damping_ratio: f64,
    /// Nominal K_d (1/s) for `damping = "free"`.
    pub kd: f64,
    /// The impedance's stiffness and damping matrices: eq. (17)'s K_p M_e, K_d M_e, or those
    /// with no coupling between the held object's free direction and the directions it holds.
    pub stiffness: HandStiffness,
    /// Whether the previewer keeps a held object's handle on its path (HP-1,
    /// docs/hand_previewer.md).
    pub held_path: HeldPath,
}

/// How the hand previewer treats a held object (`hand.held_path`, HP-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeldPath {
    /// Eq. (24): the hand free in space, whatever it holds.
    Free,
    /// The hand moves along the held object's path e only; the object takes the impedance's
    /// push across e, which F_dis then carries.
    Path,
    /// The same, with the object's mass along e (a door leaf's inertia) moved with the hand.
    PathInertia,
}

/// Which hand force the whole-body QP is given (`controller.hand_force_feedback_from`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandForceSource {
    /// The hand force as measured (or estimated from the joint torques), every tick.
    Measured,
    /// The forecast correction's hand force for the horizon's first sample (FC-4), which
    /// follows the measurement through its offset observer instead of sample by sample; the
    /// measured one where no part corrects the forecast (C0).
    Corrected,
    /// The corrected push less the held object's inertia at the hand's commanded acceleration,
    /// −Λ ẍ_cmd, solved with the impedance law in the same tick: no measured acceleration, so
    /// no lag nor velocity noise in the force fed back; the measured one where no part corrects
    /// the forecast (C0).
    Modelled,
    /// `Modelled` where the hand force is estimated (`TickFrame::hand_force_estimated`),
    /// `Measured` where a sensor measures it.
    Auto,
}

impl HandForceSource {
    /// The source for a tick whose hand force is `estimated` or measured (`Auto` resolved).
    pub fn resolve(self, estimated: bool) -> Self {
        match self {
            Self::Auto if estimated => Self::Modelled,
            Self::Auto => Self::Measured,
            s => s,
        }
    }

    /// Whether the whole-body QP is given the forecast correction's force, not the measured one.
    pub fn from_correction(self) -> bool {
        matches!(self, Self::Corrected | Self::Modelled)
    }
}

/// How the hand impedance's gains are shaped (`hand.stiffness`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandStiffness {
    /// K_e = K_p M_e, C_e = K_d M_e (eq. (17)): an error along one axis pushes along every
    /// axis M_e couples it to.
    OperationalSpace,
    /// M_e split along the held object's free direction e and the plane it holds (P = e eᵀ,
    /// Q = I − P): K_e = K_p (P M_e P + Q M_e Q). An error along e then pushes along e only,
    /// not into a door's hinge. The same as eq. (17) when nothing is held
    /// (`controller.held_object = "none"`).
    Decoupled,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GainSolverKind {
    /// Bounded Gauss–Newton with exact Jacobians through the LQ solve (the default).
    GaussNewton,
    /// The paper's baseline: Nelder–Mead over a coarse gain schedule.
    NelderMead,
}

/// C2's gain search (docs/gain_search.md, eq. (26)).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainSearchConfig {
    pub solver: GainSolverKind,
    /// Q_t weights on the hand's [position, velocity, acceleration] errors.
    pub q_t: [f64; 3],
    /// S: weight on the gains themselves.
    pub s: f64,
    /// T_w: weight on gain changes between steps.
    pub t_w: f64,
    pub kp_bounds: [f64; 2],
    pub kd_bounds: [f64; 2],
    /// Knots of the piecewise-linear gain schedule searched by Gauss–Newton.
    pub knots: usize,
    /// Knots of the Nelder–Mead baseline (fewer: simplex methods scale badly).
    pub nm_knots: usize,
    pub max_iterations: usize,
    pub nm_max_iterations: usize,
    /// Relative cost decrease below which the search stops.
    pub tolerance: f64,
}

/// Whole-body torque controller: the LQP of docs/whole_body_qp.md (`src/wbc/`). Weights are those
/// of the least-squares tasks `½ w ‖A z − r‖²` (accelerations in m/s², rad/s²; forces in N).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WbcConfig {
    /// Coulomb friction coefficient μ of the friction cones.
    pub friction: f64,
    /// Fraction of the URDF effort limits the QP may use, in (0, 1].
    pub torque_limit_scale: f64,
    /// Velocity stabilisation of the contacts (1/s): J q̈ = −J̇ q̇ − k J q̇ for each sole.
    pub contact_damping: f64,
    pub w_com: f64,
    pub w_hand: f64,
    pub w_base_orientation: f64,
    pub w_posture: f64,
    /// Regularisation of q̈ and of the contact forces.
    pub w_reg_acceleration: f64,
    pub w_reg_force: f64,
    /// Orientation PD of the floating base towards the reference (1/s², 1/s).
    pub base_kp: f64,
    pub base_kd: f64,
    /// Posture PD of the joints towards the reference (1/s², 1/s).
    pub posture_kp: f64,
    pub posture_kd: f64,
    /// Joint damping of the fallback torque (N·m·s/rad).
    pub fallback_damping: f64,
    /// Interior-point iteration limit and tolerance (gap and feasibility) of clarabel.
    pub max_iterations: u32,
    pub tolerance: f64,
    /// Keep one clarabel solver and update its data every tick (fast path); `false` builds a
    /// new solver each tick (slow path, kept for comparison).
    pub reuse_solver: bool,
    /// Which form of the QP clarabel solves (same optimum): `condensed` onto the contact forces
    /// (fast; the full one decides a tick whose condensation fails), or `full`.
    #[serde(default)]
    pub formulation: WbcFormulation,
    /// Condensed formulation: solve the condensed problem by the cone solve, a semismooth
    /// Newton method on its 6-dimensional dual, to machine precision, and leave clarabel only
    /// the ticks it does not settle (docs/whole_body_qp.md, "The cone solve"); `false`:
    /// clarabel every tick (the reference).
    #[serde(default = "active_set_default")]
    pub active_set: bool,
}

fn active_set_default() -> bool {
    true
}

/// Form of the whole-body QP handed to clarabel (`src/wbc/`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WbcFormulation {
    /// 24 contact-force variables; q̈ eliminated through the equality constraints.
    #[default]
    Condensed,
    /// z = [q̈, f, e_com, e_hand] with every constraint (the reference).
    Full,
}

impl Layers {
    /// Deserialize and range-check the merged layers into a [`Config`].
    pub fn build(&self) -> Result<Config, ConfigError> {
        let c: Config = self.typed()?;
        c.validate(self)?;
        Ok(c)
    }
}

/// Range checks of values, each error naming the key and the layer that set it.
struct Check<'a>(&'a Layers);

impl Check<'_> {
    fn pos(&self, key: &str, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self
                .0
                .range_error(key, format!("must be finite and > 0, got {v}")))
        }
    }

    fn nonneg(&self, key: &str, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self
                .0
                .range_error(key, format!("must be finite and ≥ 0, got {v}")))
        }
    }

    fn interval(&self, key: &str, b: [f64; 2]) -> Result<(), ConfigError> {
        if b.iter().all(|v| v.is_finite()) && b[0] < b[1] {
            Ok(())
        } else {
            Err(self
                .0
                .range_error(key, format!("must be [min, max] with min < max, got {b:?}")))
        }
    }
}

impl Config {
    fn validate(&self, l: &Layers) -> Result<(), ConfigError> {
        let check = Check(l);
        self.validate_preview_and_hand(&check)?;
        self.validate_gain_search(&check)?;
        self.validate_wbc(&check)?;
        self.controller.validate(l)?;
        Ok(())
    }

    /// `[robot]`'s gravity, `[preview]` and `[hand]`.
    fn validate_preview_and_hand(&self, check: &Check) -> Result<(), ConfigError> {
        check.pos("robot.gravity", self.robot.gravity)?;
        check.pos("preview.period", self.preview.period)?;
        if !(2..=20_000).contains(&self.preview.horizon) {
            return Err(check.0.range_error(
                "preview.horizon",
                format!("must be in 2..=20000 steps, got {}", self.preview.horizon),
            ));
        }
        check.pos("preview.q_e", self.preview.q_e)?;
        check.pos("preview.r", self.preview.r)?;
        check.pos("hand.kp", self.hand.kp)?;
        check.pos("hand.damping_ratio", self.hand.damping_ratio)?;
        check.pos("hand.kd", self.hand.kd)
    }

    /// `[gain_search]`: its weights, its bounds (holding the nominal K_p, and a stable
    /// impedance at the stiffest gains), its knots and iterations.
    fn validate_gain_search(&self, check: &Check) -> Result<(), ConfigError> {
        let l = check.0;
        let g = &self.gain_search;
        for (i, q) in g.q_t.iter().enumerate() {
            check.nonneg(&format!("gain_search.q_t[{i}]"), *q)?;
        }
        check.nonneg("gain_search.s", g.s)?;
        check.nonneg("gain_search.t_w", g.t_w)?;
        check.interval("gain_search.kp_bounds", g.kp_bounds)?;
        check.interval("gain_search.kd_bounds", g.kd_bounds)?;
        if g.kp_bounds[0] <= 0.0 {
            return Err(l.range_error(
                "gain_search.kp_bounds",
                "the lower stiffness bound must be > 0",
            ));
        }
        if !(self.hand.kp >= g.kp_bounds[0] && self.hand.kp <= g.kp_bounds[1]) {
            return Err(l.range_error(
                "hand.kp",
                format!(
                    "nominal K_p {} lies outside gain_search.kp_bounds {:?}",
                    self.hand.kp, g.kp_bounds
                ),
            ));
        }
        // The discrete impedance of eq. (24) must stay stable at the stiffest, most damped gains:
        // the acceleration feedback factor K_p T²/2 + K_d T below 1 keeps it so.
        let t = self.preview.period;
        let kd_max = match self.hand.damping {
            DampingMode::Critical => 2.0 * self.hand.damping_ratio * g.kp_bounds[1].sqrt(),
            DampingMode::Free => g.kd_bounds[1],
        };
        if g.kp_bounds[1] * t * t / 2.0 + kd_max * t >= 1.0 {
            return Err(l.range_error("gain_search.kp_bounds", format!("upper gains too stiff for preview.period = {t} s: K_p T²/2 + K_d T must stay < 1")));
        }
        for (key, n) in [
            ("gain_search.knots", g.knots),
            ("gain_search.nm_knots", g.nm_knots),
        ] {
            if !(2..=self.preview.horizon).contains(&n) {
                return Err(l.range_error(key, format!("must be in 2..=preview.horizon, got {n}")));
            }
        }
        if g.max_iterations == 0 || g.nm_max_iterations == 0 {
            return Err(l.range_error("gain_search.max_iterations", "iteration limits must be ≥ 1"));
        }
        check.pos("gain_search.tolerance", g.tolerance)
    }

    /// `[wbc]`: friction, torque limits, weights and gains, the QP's regularisation and solver.
    fn validate_wbc(&self, check: &Check) -> Result<(), ConfigError> {
        let l = check.0;
        let w = &self.wbc;
        check.pos("wbc.friction", w.friction)?;
        if !(w.torque_limit_scale > 0.0 && w.torque_limit_scale <= 1.0) {
            return Err(l.range_error(
                "wbc.torque_limit_scale",
                format!("must be in (0, 1], got {}", w.torque_limit_scale),
            ));
        }
        for (key, v) in [
            ("wbc.contact_damping", w.contact_damping),
            ("wbc.w_com", w.w_com),
            ("wbc.w_hand", w.w_hand),
            ("wbc.w_base_orientation", w.w_base_orientation),
            ("wbc.w_posture", w.w_posture),
            ("wbc.base_kp", w.base_kp),
            ("wbc.base_kd", w.base_kd),
            ("wbc.posture_kp", w.posture_kp),
            ("wbc.posture_kd", w.posture_kd),
            ("wbc.fallback_damping", w.fallback_damping),
        ] {
            check.nonneg(key, v)?;
        }
        // Strictly positive regularisation keeps the QP strictly convex (unique q̈ and f).
        check.pos("wbc.w_reg_acceleration", w.w_reg_acceleration)?;
        check.pos("wbc.w_reg_force", w.w_reg_force)?;
        if w.max_iterations == 0 {
            return Err(l.range_error("wbc.max_iterations", "must be ≥ 1"));
        }
        check.pos("wbc.tolerance", w.tolerance)
    }

    /// The nominal damping for a stiffness, per the configured damping mode.
    pub fn nominal_kd(&self, kp: f64) -> f64 {
        match self.hand.damping {
            DampingMode::Critical => 2.0 * self.hand.damping_ratio * kp.sqrt(),
            DampingMode::Free => self.hand.kd,
        }
    }
}

/// Which balance controller runs (docs/README.md: C0, C1, C2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ControllerKind {
    /// Kajita–Wieber ZMP preview, disturbance ignored.
    C0,
    /// C0 with the hand force forecast turned into a CoM disturbance by the hand previewer.
    C1,
    /// C1 with the hand's impedance gains optimised over the horizon.
    C2,
}

impl ControllerKind {
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::C0 => "c0",
            ControllerKind::C1 => "c1",
            ControllerKind::C2 => "c2",
        }
    }
}

/// What the hand holds, whose inertia the wrist force sensor feels as the hand moves
/// (docs/forecast_correction.md, FC-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HeldObject {
    /// The scene's door (`assets/door/door.urdf`) placed at the robot's hand as the plants
    /// place it: its apparent mass at the handle is computed from its model.
    Door,
    /// Nothing (a free hand, or a push applied at the hand).
    None,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoopMode {
    /// Answer each simulator state as it arrives (the simulator waits): reproducible runs.
    Lockstep,
    /// Tick at wall-clock rate on absolute deadlines with the latest state.
    Realtime,
}

/// The control server (`upc controller`). Its unknown keys are refused by
/// [`super::PartTables::check_keys`] (`deny_unknown_fields` does not go with `flatten`).
#[derive(Debug, Clone, Deserialize)]
pub struct ControllerConfig {
    pub kind: ControllerKind,
    pub mode: LoopMode,
    /// Loop rate (Hz) in real-time mode; also the control period used by the CoM command.
    pub rate_hz: f64,
    /// Seconds without a new state after which the loop holds its safe behaviour (real time) or
    /// considers the run over (lockstep).
    pub state_timeout: f64,
    /// Lockstep: seconds to wait, beyond `state_timeout`, for a restarted simulator before the
    /// run is over (0: stop at `state_timeout`). Real time always waits, holding damping torques.
    pub reconnect_timeout: f64,
    /// Log a status line (ticks, deadline misses, stale periods) every this many seconds of
    /// wall time; 0: never. For soak tests: each line is formatted on the loop's thread.
    pub status_every: f64,
    /// Lockstep: poll for the next state this long (µs) before sleeping on its event (see
    /// `Listener::wait_until`); 0 sleeps at once.
    pub ipc_spin_us: f64,
    /// Real time: after a deadline finds no new state, wait up to this fraction of the period
    /// for the plant's, so that the loop runs in step with the plant's cycle (0: never wait).
    pub state_grace: f64,
    /// Feed the hand force measured by the simulator (a wrist force sensor on a robot) to the
    /// whole-body QP, so that the arm behaves as the hand impedance model (eq. 23) says.
    pub hand_force_feedback: bool,
    /// Which hand force is fed back (docs/whole_body_qp.md, "The hand force fed back").
    pub hand_force_feedback_from: HandForceSource,
    /// What the hand holds: its inertia is taken out of the measured hand force before the
    /// force is compared with the forecast (a forecast announces the push, not the push less
    /// what the door takes to accelerate).
    pub held_object: HeldObject,
    /// A held door turns only the push along its handle's path (its free direction e) into
    /// hinge torque; the rest goes into its hinge. The forecast is taken as that push,
    /// f ← e eᵀ f, so that a forecast pointing off the door's path announces no sideways push
    /// the door cannot give. Off, or nothing held: the forecast as received.
    pub forecast_on_free_direction: bool,
    /// With `forecast_on_free_direction`: the push along e taken where the held hand feels it,
    /// F_e K_e e / (eᵀ K_e e), the arm's reaction along K_e e and the hinge's share across e
    /// (docs/forecast_correction.md, FC-0b), the hinge's share as far as the forecast's weight
    /// (FC-5) believes it. Off: along e.
    pub forecast_felt_at_hand: bool,
    /// PD on the CoM height (1/s², 1/s).
    pub com_height_kp: f64,
    pub com_height_kd: f64,
    /// A fall: the CoM sank below its height latched at the session's start by this fraction
    /// of it. The controller then holds joint damping without the QP until the plant restarts
    /// (a fallen robot's QP is mostly infeasible and costly). 0: never.
    pub fall_drop: f64,
    /// The support and the ZMP reference's centre follow the sole corners as measured, through
    /// a first-order filter of this time constant (s), so that feet that creep or slip carry
    /// the reference with them. 0: latched at the session's first tick, never moved.
    pub support_follow: f64,
    /// Forecast windows starting more than this before / after the current time are rejected (s).
    pub forecast_max_age: f64,
    pub forecast_max_lead: f64,
    /// Decay time constant of the forecast past the end of its window (s).
    pub forecast_decay: f64,
    /// Control ticks between two C2 snapshots.
    pub c2_every: usize,
    /// Lockstep: wait this long (s, wall) for the forecast window whose period covers the
    /// state's time (what makes a rerun reproducible); past it, go on with the newest window
    /// and stop waiting until a window comes again. 0: never wait.
    pub lockstep_forecast_wait: f64,
    /// Lockstep: wait this long (s, wall) for the first window of a plant session, the plant
    /// held at its first state meanwhile: a forecaster started late is taken from t = 0.
    pub lockstep_first_forecast_wait: f64,
    /// Lockstep: wait this long (s, wall) for the C2 search started `c2_every` ticks earlier,
    /// whose schedule applies from then on. 0: never wait (asynchronous, as in real time).
    pub lockstep_c2_wait: f64,
    /// Control ticks between two rerun records (and 10× that between plan records).
    pub log_every: usize,
    pub realtime: super::RealtimeSettings,
    /// The parts' tables (`[controller.forecast_correction]`, `[controller.base_estimation]`, …), each
    /// read and checked by its part ([`super::PartSettings`], `crate::control::parts`).
    #[serde(flatten)]
    pub parts: super::PartTables,
}

impl ControllerConfig {
    pub(crate) fn validate(&self, l: &Layers) -> Result<(), ConfigError> {
        for (key, v) in [
            ("controller.rate_hz", self.rate_hz),
            ("controller.state_timeout", self.state_timeout),
            ("controller.forecast_max_age", self.forecast_max_age),
            ("controller.forecast_max_lead", self.forecast_max_lead),
            ("controller.forecast_decay", self.forecast_decay),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(l.range_error(key, format!("must be finite and > 0, got {v}")));
            }
        }
        for (key, v) in [
            ("controller.com_height_kp", self.com_height_kp),
            ("controller.com_height_kd", self.com_height_kd),
            ("controller.reconnect_timeout", self.reconnect_timeout),
            ("controller.status_every", self.status_every),
            ("controller.ipc_spin_us", self.ipc_spin_us),
            (
                "controller.lockstep_forecast_wait",
                self.lockstep_forecast_wait,
            ),
            ("controller.lockstep_c2_wait", self.lockstep_c2_wait),
            (
                "controller.lockstep_first_forecast_wait",
                self.lockstep_first_forecast_wait,
            ),
            ("controller.support_follow", self.support_follow),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(l.range_error(key, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        // Fractions: of the period (leaving time for the tick), of the CoM height.
        for (key, v, hi) in [
            ("controller.state_grace", self.state_grace, 0.8),
            ("controller.fall_drop", self.fall_drop, 1.0),
        ] {
            if !(0.0..hi).contains(&v) {
                return Err(l.range_error(key, format!("must be in [0, {hi}), got {v}")));
            }
        }
        if self.c2_every == 0 || self.log_every == 0 {
            return Err(l.range_error("controller.c2_every", "c2_every and log_every must be ≥ 1"));
        }
        if !(0..=99).contains(&self.realtime.fifo_priority) {
            return Err(l.range_error("controller.realtime.fifo_priority", "must be in 0..=99"));
        }
        self.parts.check_keys(l)?;
        Ok(())
    }
}
