//! The closed loop of the reduced models behind `upc preview`: the cart-table CoM (plant and
//! model) and the hand impedance model under the scenario's hand force, driven by C0, C1 or C2
//! at the preview period T. The plants are the controllers' own models, so this isolates what
//! the controllers do from model error (the multibody simulator is the other test bed).

mod metrics;

use std::time::Instant;

use nalgebra::Vector3;

pub use metrics::{Metrics, Row};

use crate::config::{Config, ControllerKind};
use crate::preview::constrained::ConstrainedPreview;
use crate::preview::gain_search::{GainSearch, GainSearchInputs, GainSearchReport};
use crate::preview::{AxisState, GainSchedule, HandPreviewer, HandState, PreviewError, ZmpPreview};
use crate::robot::ReducedModel;
use crate::scenario::Scenario;

/// A finished run.
#[derive(Debug, Clone)]
pub struct RunResult {
    pub controller: ControllerKind,
    pub rows: Vec<Row>,
    pub metrics: Metrics,
    /// One report per step for C2 (empty otherwise).
    pub gain_search: Vec<GainSearchReport>,
}

/// Closed loop of the reduced models.
pub struct ReducedLoop<'a> {
    config: &'a Config,
    robot: ReducedModel,
    scenario: &'a Scenario,
    controller: ControllerKind,
}

impl<'a> ReducedLoop<'a> {
    /// The loop of `robot`'s reduced models ([`crate::robot::Robot::reduced`]).
    pub fn new(
        config: &'a Config,
        robot: ReducedModel,
        scenario: &'a Scenario,
        controller: ControllerKind,
    ) -> Self {
        Self {
            config,
            robot,
            scenario,
            controller,
        }
    }

    pub fn run(&self) -> Result<RunResult, PreviewError> {
        self.run_with(|_, _| {})
    }

    /// Run, calling `progress(step, steps)` after each step.
    pub fn run_with(
        &self,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<RunResult, PreviewError> {
        let c = self.config;
        let p = &c.preview;
        let (n, t) = (p.horizon, p.period);
        let r = &self.robot;
        let model = r.cart_table(t, c.robot.gravity);
        let m_e = r.effective_mass;
        let mut zmp =
            ZmpPreview::new(model, p.q_e, p.r, n, p.solver).with_terminal_cost(p.terminal_cost);
        zmp.check_holds_the_com()?;
        let constrained = p.zmp_constraints.then(|| {
            ConstrainedPreview::new(model, p.q_e, p.r, n, r.support)
                .with_terminal_cost(p.terminal_cost)
        });
        let previewer = HandPreviewer::new(t, m_e, n)?;
        let plant_hand = HandPreviewer::new(t, m_e, 1)?;
        let search = match self.controller {
            ControllerKind::C2 => Some(GainSearch::from_config(c, r)?),
            _ => None,
        };
        let mut controller = Controller {
            kind: self.controller,
            zmp,
            constrained,
            previewer,
            search,
            nominal: GainSchedule::constant(n, c.hand.kp, c.nominal_kd(c.hand.kp)),
        };

        let desired = HandState {
            pos: r.hand_position,
            ..Default::default()
        };
        let mut inputs = Horizon {
            hand_desired: vec![desired; n],
            zmp_ref: vec![self.scenario.zmp_reference; n],
            f_ext: vec![[0.0; 3]; n],
        };
        let mut com: [AxisState; 2] =
            [0, 1].map(|a| Vector3::new(self.scenario.zmp_reference[a], 0.0, 0.0));
        let mut hand = desired;
        let mut applied = [c.hand.kp, c.nominal_kd(c.hand.kp)];

        let steps = (self.scenario.duration / t).round() as usize;
        let mut rows = Vec::with_capacity(steps);
        let mut reports = Vec::new();
        for k in 0..steps {
            let now = k as f64 * t;
            let start = Instant::now();
            // The known force forecast at k+1…k+N.
            self.scenario
                .force
                .sample_into(now + t, t, &mut inputs.f_ext);
            let (u, gains) = controller.command(&com, &hand, applied, &inputs, &mut reports)?;
            let solve_time = start.elapsed().as_secs_f64();
            applied = gains;

            // Plants: the CoM follows the jerk; the hand feels the actual force.
            for a in 0..2 {
                com[a] = model.step(&com[a], u[a]);
            }
            let f_ext = inputs.f_ext[0];
            let (next_hand, f_dis) = plant_hand.step(
                &hand,
                &desired,
                applied[0],
                applied[1],
                &Vector3::from(f_ext),
            );
            hand = next_hand;
            let alpha0 = 1.0 / (model.mass * model.gravity - f_dis[2]);
            let zmp_now = [0, 1].map(|a| model.zmp(&com[a], alpha0, f_dis[a] * alpha0));
            rows.push(Row {
                t: now + t,
                com: [com[0][0], com[1][0]],
                zmp: zmp_now,
                zmp_ref: inputs.zmp_ref[0],
                hand_error: (hand.pos - desired.pos).norm(),
                kp: applied[0],
                kd: applied[1],
                f_ext,
                f_dis: f_dis.into(),
                solve_time,
            });
            progress(k + 1, steps);
        }
        let metrics = Metrics::from_rows(&rows, t, self.robot.support);
        Ok(RunResult {
            controller: self.controller,
            rows,
            metrics,
            gain_search: reports,
        })
    }
}

/// What the controller previews over the horizon (samples at k+1…k+N).
struct Horizon {
    hand_desired: Vec<HandState>,
    zmp_ref: Vec<[f64; 2]>,
    /// The known hand force forecast.
    f_ext: Vec<[f64; 3]>,
}

/// C0, C1 or C2 on the reduced models: the ZMP preview (constrained or not), the hand
/// previewer, and C2's gain search.
struct Controller {
    kind: ControllerKind,
    zmp: ZmpPreview,
    constrained: Option<ConstrainedPreview>,
    previewer: HandPreviewer,
    search: Option<GainSearch>,
    /// The hand gains without a search.
    nominal: GainSchedule,
}

impl Controller {
    /// This step's CoM jerk (x, y) and the hand gains it applies (K_p, K_d), from the CoM and
    /// hand states, the gains applied last step and the horizon. C2 searches its gains first
    /// (its report pushed on `reports`).
    fn command(
        &mut self,
        com: &[AxisState; 2],
        hand: &HandState,
        applied: [f64; 2],
        inputs: &Horizon,
        reports: &mut Vec<GainSearchReport>,
    ) -> Result<([f64; 2], [f64; 2]), PreviewError> {
        let n = inputs.zmp_ref.len();
        let gains = match self.search.as_mut() {
            Some(s) => {
                let search_inputs = GainSearchInputs {
                    com: *com,
                    zmp_ref: &inputs.zmp_ref,
                    hand: *hand,
                    hand_desired: &inputs.hand_desired,
                    f_ext: &inputs.f_ext,
                    applied,
                };
                reports.push(s.search(&search_inputs, 1)?);
                s.schedule()
            }
            None => &self.nominal,
        };
        let u = match self.kind {
            ControllerKind::C0 => self.zmp.solve_c0(com, &inputs.zmp_ref)?,
            ControllerKind::C1 | ControllerKind::C2 => {
                self.previewer
                    .predict(hand, &inputs.hand_desired, gains, &inputs.f_ext, n)?;
                match self.constrained.as_mut() {
                    Some(q) => q.solve(com, &inputs.zmp_ref, self.previewer.disturbance())?,
                    None => {
                        self.zmp
                            .solve_c1(com, &inputs.zmp_ref, self.previewer.disturbance())?
                    }
                }
            }
        };
        Ok((u, [gains.kp[0], gains.kd[0]]))
    }
}
