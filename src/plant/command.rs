//! Validation of torque commands, independent of IPC so it is unit-testable: a command with the
//! wrong number of torques, a non-finite torque, a sequence number that does not increase, or
//! computed from another plant run's states (its `session`) is rejected and counted, never
//! applied. A new controller (its `controller` id changes) may start its `seq` over.

/// Why a command was rejected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Rejection {
    #[error("torque command has n = {got}, the robot has {expected} actuated joints")]
    WrongLength { expected: usize, got: usize },
    #[error("torque command has a non-finite torque at index {index}")]
    NonFinite { index: usize },
    #[error("torque command seq {seq} does not follow the last accepted seq {last}")]
    OutOfOrder { seq: u64, last: u64 },
    #[error(
        "torque command answers plant session {got:#x}, this plant run is {expected:#x} (a controller still on a previous run)"
    )]
    ForeignSession { expected: u64, got: u64 },
}

/// Counters of the command stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CommandStats {
    /// Valid commands applied (in lockstep, only answers to the state the plant waits on).
    pub accepted: u64,
    pub wrong_length: u64,
    pub non_finite: u64,
    pub out_of_order: u64,
    /// Answers to another plant run's states (a restarted plant's predecessor).
    pub foreign: u64,
    /// Times a new controller (another `TorqueMsg::controller`) took over the command stream.
    pub controller_changes: u64,
    /// Steps run without a fresh command (real-time) or answers to an older state (lockstep).
    pub stale: u64,
}

impl CommandStats {
    pub fn rejected(&self) -> u64 {
        self.wrong_length + self.non_finite + self.out_of_order + self.foreign
    }
}

/// Checks one command: `n` torques expected out of the `tau` array, `seq` strictly greater than
/// the last accepted one. Pure: the caller counts and applies.
pub fn validate_command(
    last_seq: Option<u64>,
    seq: u64,
    n: u32,
    tau: &[f64],
    expected: usize,
) -> Result<(), Rejection> {
    let got = n as usize;
    if got != expected || got > tau.len() {
        return Err(Rejection::WrongLength { expected, got });
    }
    if let Some(index) = tau[..got].iter().position(|t| !t.is_finite()) {
        return Err(Rejection::NonFinite { index });
    }
    if let Some(last) = last_seq
        && seq <= last
    {
        return Err(Rejection::OutOfOrder { seq, last });
    }
    Ok(())
}

/// A validator that remembers the last accepted sequence number and counts.
#[derive(Debug, Clone, Default)]
pub struct CommandGate {
    pub last_seq: Option<u64>,
    /// The plant run's session; 0 accepts any (tests of the other checks).
    pub session: u64,
    /// The controller whose seq `last_seq` is.
    pub controller: u64,
    pub stats: CommandStats,
}

/// Who sent a command and for which plant run (`TorqueMsg::controller`, `session`).
#[derive(Debug, Clone, Copy, Default)]
pub struct CommandOrigin {
    pub session: u64,
    pub controller: u64,
}

impl CommandGate {
    /// A gate for the plant run `session`.
    pub fn for_session(session: u64) -> Self {
        Self {
            session,
            ..Self::default()
        }
    }

    /// Validates and counts; on success the command's seq becomes the last accepted one.
    pub fn check(
        &mut self,
        origin: CommandOrigin,
        seq: u64,
        n: u32,
        tau: &[f64],
        expected: usize,
    ) -> Result<(), Rejection> {
        self.check_answer(origin, seq, n, tau, expected, true)
    }

    /// [`CommandGate::check`] for a command that `applies` or not: a valid one answering
    /// another state than the one a lockstep plant waits on (a controller's re-answer after
    /// the plant was stopped) is counted stale, not accepted. How many of those arrive depends
    /// on wall-clock timing; the accepted count is a function of the run's inputs.
    pub fn check_answer(
        &mut self,
        origin: CommandOrigin,
        seq: u64,
        n: u32,
        tau: &[f64],
        expected: usize,
        applies: bool,
    ) -> Result<(), Rejection> {
        if self.session != 0 && origin.session != self.session {
            self.stats.foreign += 1;
            return Err(Rejection::ForeignSession {
                expected: self.session,
                got: origin.session,
            });
        }
        // Another controller's seq counts from its own start.
        let last = if origin.controller == self.controller {
            self.last_seq
        } else {
            None
        };
        match validate_command(last, seq, n, tau, expected) {
            Ok(()) => {
                if origin.controller != self.controller {
                    self.stats.controller_changes += u64::from(self.last_seq.is_some());
                    self.controller = origin.controller;
                }
                self.last_seq = Some(seq);
                if applies {
                    self.stats.accepted += 1;
                } else {
                    self.stats.stale += 1;
                }
                Ok(())
            }
            Err(e) => {
                match e {
                    Rejection::WrongLength { .. } => self.stats.wrong_length += 1,
                    Rejection::NonFinite { .. } => self.stats.non_finite += 1,
                    Rejection::OutOfOrder { .. } => self.stats.out_of_order += 1,
                    Rejection::ForeignSession { .. } => self.stats.foreign += 1,
                }
                Err(e)
            }
        }
    }
}
