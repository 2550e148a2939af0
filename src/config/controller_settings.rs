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
}
