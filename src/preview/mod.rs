//! The paper's reduced models and preview controllers (docs/README.md indexes the equations; each
//! module cites its page).
//!
//! - [`CartTable`]: the CoM cart-table model (eq. 1–3) and its time-varying output row (eq. 10).
//! - [`Disturbance`]: the CoM-disturbance horizon α0, D of eq. (10)–(16), validated.
//! - [`dense`]: the condensed horizon P_x, P_u (eq. 5, 12) and the closed-form solve (eq. 9, 15).
//! - [`Riccati`]: the same finite-horizon LQ problem by backward recursion, O(N).
//! - [`ZmpPreview`]: C0 and C1, x and y, with a preallocated workspace.
//! - [`HandPreviewer`]: hand impedance over the horizon and the equivalent CoM disturbance (eq. 24–25).
//! - [`CapturePoint`]: the cart-table's capture point under a constant force (VG-1).
//! - [`gain_search`]: C2, gains as decision variables (eq. 26).
//! - [`constrained`]: the optional ZMP-bounded C1 (Wieber 2006) as a QP.
//!
//! What these models take from the robot (mass, CoM height, support, M_e) is the robot's:
//! [`crate::robot::ReducedModel`], from [`crate::robot::Robot::reduced`].

mod capture_point;
mod cart_table;
pub mod constrained;
pub mod dense;
mod disturbance;
mod error;
pub mod gain_search;
mod hand;
mod riccati;
mod zmp_preview;

pub use capture_point::CapturePoint;
pub use cart_table::CartTable;
pub use disturbance::Disturbance;
pub use error::PreviewError;
pub use hand::{GainSchedule, HandPreviewer, HandState};
pub use riccati::Riccati;
pub use zmp_preview::{AxisState, PreviewPlan, ZmpPreview};
