//! The feet's soles as the foot sensors see them (each foot's centre and frame, the wrench of
//! its corner forces): the contract's plant side has them, shared with a robot's bus.

pub(super) use crate::plant::feet::{fill_foot_wrenches, sole};
