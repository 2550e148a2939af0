//! The robot's own bus: upc drives a Unitree G1 through the low-level DDS interface of its
//! firmware, reading joint and IMU state from `rt/lowstate` and writing per-joint PD + feedforward
//! targets to `rt/lowcmd`.
//!
//! This module is the wire format only (messages, their CDR encoding, Unitree's CRC), in pure
//! Rust so it can be tested without a robot or a DDS library; the DDS participant that carries
//! these bytes comes later.

pub mod unitree_hg;
