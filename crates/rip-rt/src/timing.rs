//! Periodic scheduling on absolute deadlines, latency statistics, and best-effort real-time
//! settings (SCHED_FIFO, CPU pinning, locked memory).
//!
//! Sleeping until an absolute deadline (`clock_nanosleep(TIMER_ABSTIME)` on `CLOCK_MONOTONIC`)
//! instead of for a relative interval keeps the period exact on average: the time spent in an
//! iteration and any wake-up latency do not accumulate as drift.

use std::io;

/// Nanoseconds on `CLOCK_MONOTONIC`.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid out-pointer and CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until `deadline_ns` on `CLOCK_MONOTONIC` (returns at once if it has passed).
pub fn sleep_until(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        // EINTR (a signal such as SIGINT): sleep on to the same absolute deadline; the loop
        // checks its stop flag right after waking.
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Which clock a [`Periodic`] grid runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ClockMode {
    /// `CLOCK_MONOTONIC`: every deadline is waited for (the rig, and the emulator in real
    /// time).
    #[default]
    RealTime,
    /// Simulated time against an emulator in lockstep (`rip-rt emulate --lockstep`): the
    /// device advances its plant by exactly one period per sample request, so the loop waits
    /// for no deadline, the clock moves by one period per [`Periodic::wait`] and stands still
    /// within a period (compute, stall and lateness rules see no time pass).
    Lockstep,
}

/// How long (ns of wall time) a lockstep exchange waits for the emulator's answer before it
/// counts the period as without a measurement. The emulator answers every request, a lost
/// reply with a [`STATUS_NO_SAMPLE`](crate::protocol::STATUS_NO_SAMPLE) marker, so this bound
/// is reached only by an emulator that hangs or is starved of the CPU: long, so that a loaded
/// machine never turns a reply into a lost one.
pub const LOCKSTEP_REPLY_WAIT_NS: u64 = 5_000_000_000;

/// A grid of absolute deadlines `t₀ + k·period` on a [`ClockMode`]'s clock: the one clock of
/// a run, from which every phase of the loop (rest check, sign check, control, the stop)
/// takes its deadlines and its "now".
#[derive(Debug, Clone)]
pub struct Periodic {
    period_ns: u64,
    next_ns: u64,
    missed: u64,
    mode: ClockMode,
}

/// What [`Periodic::wait`] observed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    /// The deadline that was waited for.
    pub deadline_ns: u64,
    /// How late the wake-up was (`now − deadline`, ≥ 0).
    pub lateness_ns: u64,
    /// Deadlines that had already passed when waiting began (the previous iteration overran
    /// them); they are skipped and counted as misses.
    pub skipped: u64,
}

impl Periodic {
    /// A schedule whose first deadline is `start_ns`.
    pub fn new(period_ns: u64, start_ns: u64) -> Self {
        assert!(period_ns > 0, "period must be positive");
        Self {
            period_ns,
            next_ns: start_ns,
            missed: 0,
            mode: ClockMode::RealTime,
        }
    }

    /// A grid on `mode`'s clock whose first deadline is one period from now.
    pub fn starting(period_ns: u64, mode: ClockMode) -> Self {
        let mut grid = Self::new(period_ns, now_ns() + period_ns);
        grid.mode = mode;
        grid
    }

    /// The clock this grid runs on.
    pub fn mode(&self) -> ClockMode {
        self.mode
    }

    /// Now on this grid's clock (ns): `CLOCK_MONOTONIC` in real time; in lockstep the
    /// deadline of the current period (the grid's clock stands still within a period).
    pub fn now_ns(&self) -> u64 {
        match self.mode {
            ClockMode::RealTime => now_ns(),
            ClockMode::Lockstep => self.next_ns - self.period_ns,
        }
    }

    /// Starts the grid afresh with its first deadline one period from now (after a phase
    /// that may have taken longer than a period, such as the probe); the deadlines in
    /// between are not misses.
    pub fn restart(&mut self) {
        if self.mode == ClockMode::RealTime {
            self.next_ns = now_ns() + self.period_ns;
        }
    }

    /// The period.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The deadline [`wait`](Self::wait) will wait for next (before any skipping).
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_ns
    }

    /// Deadline misses so far: iterations that ended after the next deadline had passed.
    pub fn missed(&self) -> u64 {
        self.missed
    }

    /// Sleeps until the next deadline on the grid and advances the grid. Deadlines that have
    /// already passed (the previous iteration overran them) are counted as misses and skipped,
    /// so the loop stays on the grid instead of bursting to catch up.
    pub fn wait(&mut self) -> Tick {
        if self.mode == ClockMode::Lockstep {
            let deadline = self.next_ns;
            self.next_ns = deadline + self.period_ns;
            return Tick {
                deadline_ns: deadline,
                lateness_ns: 0,
                skipped: 0,
            };
        }
        let now = now_ns();
        let mut skipped = 0;
        if now > self.next_ns {
            skipped = (now - self.next_ns) / self.period_ns + 1;
            self.next_ns += skipped * self.period_ns;
            self.missed += skipped;
        }
        let deadline = self.next_ns;
        sleep_until(deadline);
        let woke = now_ns();
        self.next_ns = deadline + self.period_ns;
        Tick {
            deadline_ns: deadline,
            lateness_ns: woke.saturating_sub(deadline),
            skipped,
        }
    }
}

/// A fixed-size histogram of durations with 1 µs bins up to [`Histogram::RANGE_US`], plus the
/// exact maximum. Recording never allocates, so it can run inside the loop for any duration.
#[derive(Debug, Clone)]
pub struct Histogram {
    bins: Vec<u32>,
    overflow: u64,
    count: u64,
    sum_ns: u128,
    max_ns: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    /// Durations at or above this many microseconds land in one overflow bin.
    pub const RANGE_US: usize = 100_000;

    /// An empty histogram.
    pub fn new() -> Self {
        Self {
            bins: vec![0; Self::RANGE_US],
            overflow: 0,
            count: 0,
            sum_ns: 0,
            max_ns: 0,
        }
    }

    /// Adds one duration.
    pub fn record(&mut self, ns: u64) {
        let us = (ns / 1000) as usize;
        match self.bins.get_mut(us) {
            Some(bin) => *bin = bin.saturating_add(1),
            None => self.overflow += 1,
        }
        self.count += 1;
        self.sum_ns += ns as u128;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Number of recorded durations.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest recorded duration (ns), 0 when empty.
    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// Mean (ns), 0 when empty.
    pub fn mean_ns(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64
        }
    }

    /// The `q`-quantile (`0 ≤ q ≤ 1`) in nanoseconds, resolved to the upper edge of its 1 µs
    /// bin (capped at the maximum); 0 when empty.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (us, &n) in self.bins.iter().enumerate() {
            seen += n as u64;
            if seen >= rank {
                return ((us as u64 + 1) * 1000).min(self.max_ns);
            }
        }
        self.max_ns
    }
}

/// Timing figures of a run, as printed at the end and written into the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimingSummary {
    /// Loop iterations.
    pub iterations: u64,
    /// Wake-up lateness relative to the deadline (period jitter), µs.
    pub jitter_p50_us: f64,
    /// 99th percentile of the jitter, µs.
    pub jitter_p99_us: f64,
    /// Largest jitter, µs.
    pub jitter_max_us: f64,
    /// Compute time (measurement decoded → command encoded), median, µs.
    pub compute_p50_us: f64,
    /// 99th percentile of the compute time, µs.
    pub compute_p99_us: f64,
    /// Largest compute time, µs.
    pub compute_max_us: f64,
    /// Deadline misses.
    pub deadline_misses: u64,
}

impl TimingSummary {
    /// Summarises the two histograms.
    pub fn from_histograms(jitter: &Histogram, compute: &Histogram, misses: u64) -> Self {
        let us = |ns: u64| ns as f64 / 1000.0;
        Self {
            iterations: jitter.count(),
            jitter_p50_us: us(jitter.quantile_ns(0.5)),
            jitter_p99_us: us(jitter.quantile_ns(0.99)),
            jitter_max_us: us(jitter.max_ns()),
            compute_p50_us: us(compute.quantile_ns(0.5)),
            compute_p99_us: us(compute.quantile_ns(0.99)),
            compute_max_us: us(compute.max_ns()),
            deadline_misses: misses,
        }
    }
}

impl std::fmt::Display for TimingSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "iterations={} jitter_us(p50/p99/max)={:.0}/{:.0}/{:.0} \
             compute_us(p50/p99/max)={:.0}/{:.0}/{:.0} deadline_misses={}",
            self.iterations,
            self.jitter_p50_us,
            self.jitter_p99_us,
            self.jitter_max_us,
            self.compute_p50_us,
            self.compute_p99_us,
            self.compute_max_us,
            self.deadline_misses
        )
    }
}

/// Switches the calling thread to `SCHED_FIFO` at `priority` (1–99). Needs `CAP_SYS_NICE` or
/// an `rtprio` limit; the error says so when it is refused.
pub fn set_realtime_priority(priority: i32) -> io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: pid 0 is the calling thread; `param` is valid for the call.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Pins the calling thread to one CPU.
pub fn pin_to_cpu(cpu: usize) -> io::Result<()> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("cpu {cpu} is out of range"),
        ));
    }
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET writes inside it (index checked).
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    Ok(())
}

/// Locks current and future memory so page faults cannot stall the loop.
pub fn lock_memory() -> io::Result<()> {
    // SAFETY: plain system call without pointers.
    if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles() {
        let mut h = Histogram::new();
        for us in 1..=100u64 {
            h.record(us * 1000 + 500);
        }
        assert_eq!(h.count(), 100);
        // 50th smallest is 50.5 µs, in bin 50 → upper edge 51 µs.
        assert_eq!(h.quantile_ns(0.5), 51_000);
        assert_eq!(h.quantile_ns(0.99), 100_000);
        assert_eq!(h.max_ns(), 100_500);
        assert_eq!(h.quantile_ns(1.0), 100_500);
        h.record(1_000_000_000);
        assert_eq!(h.max_ns(), 1_000_000_000);
        assert_eq!(h.quantile_ns(1.0), 1_000_000_000);
    }

    #[test]
    fn empty_histogram_is_zero() {
        let h = Histogram::new();
        assert_eq!(h.quantile_ns(0.5), 0);
        assert_eq!(h.mean_ns(), 0.0);
    }

    #[test]
    fn a_lockstep_grid_moves_one_period_per_wait_and_never_sleeps() {
        let mut p = Periodic::starting(10_000_000, ClockMode::Lockstep);
        let first = p.next_deadline_ns();
        assert_eq!(p.now_ns(), first - 10_000_000);
        let wall = now_ns();
        for k in 0..1000u64 {
            let tick = p.wait();
            assert_eq!(tick.deadline_ns, first + k * 10_000_000);
            assert_eq!((tick.lateness_ns, tick.skipped), (0, 0));
            // The clock stands still within the period, whatever the wall clock does.
            assert_eq!(p.now_ns(), tick.deadline_ns);
        }
        // Ten simulated seconds took no ten seconds of wall time.
        assert!(now_ns() - wall < 1_000_000_000);
        assert_eq!(p.missed(), 0);
        // A restart keeps the lockstep grid where it is (no period passes unexchanged).
        let next = p.next_deadline_ns();
        p.restart();
        assert_eq!(p.next_deadline_ns(), next);
    }

    #[test]
    fn overrun_skips_whole_periods_and_counts_misses() {
        let start = now_ns() + 1_000_000;
        let mut p = Periodic::new(1_000_000, start);
        p.wait();
        let before = p.missed();
        // Pretend the iteration overran by 3.5 periods.
        sleep_until(start + 4_500_000);
        let tick = p.wait();
        // Deadlines at +1, +2, +3 and +4 ms passed during the overrun.
        assert!(tick.skipped >= 4, "skipped {}", tick.skipped);
        assert!(tick.deadline_ns >= start + 5_000_000);
        assert_eq!((tick.deadline_ns - start) % 1_000_000, 0);
        assert_eq!(p.missed(), before + tick.skipped);
    }
}
