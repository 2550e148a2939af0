//! The tick's own types, below the core and the parts that both use them: where in the tick a
//! part runs ([`Stage`]), what it reads ([`TickInputs`]) and how a tick fails ([`TickError`]).
//! The shared quantities the parts write are the frame's (`super::frame`).

use super::forecast_window::ForecastWindow;
use crate::channels::MAX_DOF;
use crate::dynamics::DynamicsError;
use crate::estimation::EstimatorError;
use crate::robot::RobotState;

/// Errors of a tick: a state the controller cannot act on.
#[derive(Debug, Clone, thiserror::Error)]
pub enum TickError {
    #[error(
        "state has nq = {nq}, nv = {nv}; the model needs {model_nq}, {model_nv} (a state holds at most {MAX_DOF} each)"
    )]
    Dimensions {
        nq: u32,
        nv: u32,
        model_nq: usize,
        model_nv: usize,
    },
    #[error(
        "the plant runs another robot (robot hash {plant:016x}, this controller's {mine:016x}): start both with the same --robot"
    )]
    Robot { plant: u64, mine: u64 },
    #[error("state is not finite")]
    NotFinite,
    #[error("dynamics: {0}")]
    Dynamics(#[from] DynamicsError),
    #[error("base estimator: {0}")]
    Estimator(#[from] EstimatorError),
    #[error(
        "the plant does not measure its floating base (its states carry STATE_FLAG_BASE_UNMEASURED) and controller.base_estimation.mode = \"off\": set it to \"auto\" (or run `upc controller --sensing realistic`)"
    )]
    BaseUnmeasured,
    /// Two parts of one stage estimated the same quantity: the pipeline is misassembled.
    #[error(
        "`{second}` estimated {slot} at the {stage:?} stage, which `{first}` already estimated there: one part per stage estimates a quantity"
    )]
    SlotTaken {
        slot: &'static str,
        stage: Stage,
        first: &'static str,
        second: &'static str,
    },
    #[error("more than {0} parts added a force on the CoM in one tick")]
    TooManyComForces(usize),
}

/// Where in the tick a part runs (in this order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    /// On the measured state, before the model's kinematics: the floating base.
    Estimate,
    /// After the kinematics: what the controller makes of the measured forces.
    Measure,
    /// The hand force over the horizon.
    Forecast,
    /// Forces on the CoM that the preview adds to its disturbance.
    Disturbance,
}

/// The tick's read-only inputs.
pub struct TickInputs<'a> {
    /// The robot as measured (the contract's state, read once at the process's edge).
    pub sensed: &'a RobotState,
    pub forecast: &'a ForecastWindow,
}
