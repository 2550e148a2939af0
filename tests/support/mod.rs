//! Helpers shared by the integration tests (each test binary uses a part of them).
#![allow(dead_code)]

pub mod counting_alloc;
pub mod humanoid;
pub mod pd_driver;
pub mod prereq;
pub mod procs;
pub mod robots;
pub mod rrd;
pub mod starved;
pub mod upc_run;
