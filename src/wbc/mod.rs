//! Whole-body torque control: the LQP of the paper (Salini, Padois, Bidaud 2011;
//! docs/whole_body_qp.md).
//!
//! Each tick [`WholeBodyController::solve`] turns the preview controller's CoM acceleration, the
//! hand impedance law (with the current gains) and a posture reference into joint torques, by a
//! quadratic program over the joint accelerations and the 8 sole-corner contact forces, solved
//! with clarabel. See [`controller`] for the problem, its constraints and the choices made.
//!
//! - [`controller`]: [`WholeBodyController`], its command / output / status types, the fallback.
//! - `condensed`: the same QP condensed onto the 24 contact forces (the default; the full one
//!   stays as the reference and the fallback).
//! - [`outcome`]: what both formulations share: the contact count, a tick's status and
//!   counters (the contact frames are the robot's: `crate::robot::BodyFrames`, `CORNERS`).
//! - `tasks`: the QP's tasks as data and the layout of its variables and rows, decided once
//!   and read by both formulations.
//! - `cone`: the cone solve, the condensed problem's exact optimum by Newton steps on its dual.
//! - `dense`: the condensation's small Cholesky factors and triangular solves.
//! - `low_rank`: the q̈ cost's Hessian (diagonal plus the point tasks' rank) factored in O(n r²).
//! - `qp`: one clarabel problem with a fixed sparsity pattern, updated in place each tick.
//! - [`com_bias`]: `J̇ v` drift of the CoM and of several frames from one forward pass.

pub mod com_bias;
mod condensed;
mod cone;
pub mod controller;
mod dense;
mod low_rank;
pub mod outcome;
mod pattern;
mod qp;
mod tasks;

pub use condensed::CondensedInstance;
pub use controller::{
    FallbackReason, N_CONTACTS, WbcCommand, WbcCounters, WbcError, WbcOutput, WbcStatus,
    WholeBodyController, damping_torques,
};
