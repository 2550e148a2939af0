//! `[controller.realtime]`: the control thread's scheduling. (The settings of the controller's
//! parts live with each part: [`super::PartSettings`].)

use serde::Deserialize;

/// `[controller.realtime]` settings.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealtimeSettings {
    /// SCHED_FIFO priority (1–99) of the control thread; 0 keeps the default scheduler.
    pub fifo_priority: i32,
    /// mlockall(MCL_CURRENT | MCL_FUTURE): no page faults on the control path.
    pub lock_memory: bool,
    /// CPU to pin the control thread to; none if absent.
    pub cpu: Option<usize>,
    /// Bound the machine's CPU wake-up latency to this many µs while the process runs (a PM QoS
    /// request, `crate::realtime::cpu_latency`): 0 keeps idle CPUs polling instead of halting.
    /// None if absent; a value above every idle state's exit latency bounds nothing.
    pub cpu_latency_us: Option<u32>,
}
