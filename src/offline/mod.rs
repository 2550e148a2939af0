//! Closed loop of the reduced models.
