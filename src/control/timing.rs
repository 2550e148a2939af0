//! Fixed-rate loop timing: sleep to absolute deadlines on CLOCK_MONOTONIC, skip (never catch up)
//! missed ticks. The tick-time statistics are [`crate::realtime::LatencyHistogram`].

use std::time::{Duration, Instant};

/// Absolute-deadline ticker.
pub struct Ticker {
    period: Duration,
    next: Instant,
    /// Ticks skipped because the loop overran its deadline.
    pub missed: u64,
    /// Ticks that overran (each may skip one or more deadlines).
    pub overruns: u64,
}

impl Ticker {
    /// The summary's counts of overrun and missed deadlines.
    pub fn counts(&self) -> super::summary::DeadlineCounts {
        super::summary::DeadlineCounts {
            deadline_overruns: self.overruns,
            deadline_misses: self.missed,
        }
    }

    pub fn new(period: Duration) -> Self {
        Self {
            period,
            next: Instant::now() + period,
            missed: 0,
            overruns: 0,
        }
    }

    pub fn period(&self) -> Duration {
        self.period
    }

    /// Lock the deadlines to the plant's cycle: a state that arrived at `arrival`, during the
    /// wait after a deadline, puts the next deadline `lead` before the next one's arrival.
    pub fn lock_to(&mut self, arrival: Instant, lead: Duration) {
        self.next = arrival + self.period.saturating_sub(lead);
    }

    /// Move the next deadline earlier by `by`: a state already waiting at a deadline says the
    /// deadlines fall late in the plant's cycle.
    pub fn advance(&mut self, by: Duration) {
        self.next = self.next.checked_sub(by).unwrap_or(self.next);
    }

    /// Sleep until the next deadline. If it has already passed, count the overrun and move the
    /// deadline to the next one in the future: missed ticks are skipped, not run in a burst.
    pub fn wait(&mut self) {
        let deadline = self.deadline_after(Instant::now());
        sleep_until(deadline);
    }

    /// The deadline to sleep until for a loop ready at `now`, counting the deadlines it missed
    /// (the clock is the caller's: tests step it).
    pub fn deadline_after(&mut self, now: Instant) -> Instant {
        if now > self.next {
            let late = now - self.next;
            let skipped = (late.as_nanos() / self.period.as_nanos().max(1)) as u64;
            self.overruns += 1;
            self.missed += skipped;
            self.next += self.period * (skipped as u32 + 1);
        }
        let deadline = self.next;
        self.next += self.period;
        deadline
    }
}

/// Sleep until `deadline` with clock_nanosleep(TIMER_ABSTIME): no drift from relative sleeps.
fn sleep_until(deadline: Instant) {
    let now = Instant::now();
    if deadline <= now {
        return;
    }
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into a valid timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    let target = Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32) + (deadline - now);
    let abs = libc::timespec {
        tv_sec: target.as_secs() as libc::time_t,
        tv_nsec: target.subsec_nanos() as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &abs,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticker_skips_missed_deadlines() {
        let ms = Duration::from_millis;
        let mut t = Ticker::new(ms(2));
        let start = t.next - ms(2);
        // On time: the first deadline, then the next one period later.
        assert_eq!(t.deadline_after(start + ms(1)), start + ms(2));
        assert_eq!((t.overruns, t.missed), (0, 0));
        // Ready at 13 ms, 9 ms past the 4 ms deadline: one overrun, and the 6 to 12 ms deadlines
        // missed; the next wait is for 14 ms, in the future: no burst of catch-up ticks.
        let now = start + ms(13);
        let d = t.deadline_after(now);
        assert_eq!((t.overruns, t.missed), (1, 4));
        assert_eq!(d, start + ms(14));
        assert!(d > now && d - now <= ms(2));
        // Back on time: nothing more counted.
        assert_eq!(t.deadline_after(start + ms(15)), start + ms(16));
        assert_eq!((t.overruns, t.missed), (1, 4));
    }
}
