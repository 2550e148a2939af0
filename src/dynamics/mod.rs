//! Rigid-body dynamics from URDF (Model / Data split, as in Pinocchio).
