//! Pacing the sample clock to what the refill keeps up with.
//!
//! A board plays its samples from a double buffer: the DMA reads one half
//! while the CPU refills the other from the beam scheduler. The scheduler's
//! work is mostly per command, so a dense picture (many short segments) can
//! take longer to refill a half than a half lasts at the configured sample
//! rate; the DMA then plays a stale half again, which the scope shows as
//! stray lines. A [`Pacer`] slows the sample clock instead, as far as the
//! refill needs, and speeds it up again once the refill has room: the
//! picture is the same samples, drawn at a lower refresh rate (as any vector
//! display slows down with the complexity of its picture).
//!
//! The board reports, for every half it refills, how many samples of the
//! other half the DMA had played when the refill ended ([`Pacer::filled`]):
//! the share of a half that the refill and whatever else the main loop did
//! before it took. Periods are in ticks of the sample timer (`ARR + 1` on an
//! STM32), so the pacer needs no clock of its own.
//!
//! - A half that took more than 7/8 of a half slows the clock at once, to
//!   the period at which it would have taken 3/4.
//! - After [`CALM_HALVES`] halves, the clock speeds up to the period at
//!   which the slowest of them would have taken 3/4 (never beyond the
//!   configured rate), if that is at least 1/8 faster: so a picture whose
//!   cost wavers a little does not make the clock hunt.
//!
//! ```
//! use isoscope_core::beam::pace::{PaceConfig, Pacer};
//!
//! // 512-sample halves; 168 ticks a sample (1 MS/s on a 168 MHz timer) at
//! // best, 672 (250 kS/s) at worst.
//! let mut pacer = Pacer::new(PaceConfig { half: 512, fastest: 168, slowest: 672 }).unwrap();
//! // A refill that ended when the DMA had played 500 samples of the other
//! // half (late soon): slow down so that it would take 3/4 of a half.
//! assert_eq!(pacer.filled(500), Some(219));
//! assert_eq!(pacer.period(), 219);
//! assert_eq!(pacer.rate_hz(168_000_000), 767_123);
//! ```

use core::fmt;

/// Halves watched before the clock speeds up (about a quarter of a second
/// with 512-sample halves at 1 MS/s).
pub const CALM_HALVES: u32 = 512;

/// The output the pacer paces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PaceConfig {
    /// Samples in a half buffer.
    pub half: u32,
    /// The shortest period, in timer ticks a sample: the configured sample
    /// rate, which the pacer never exceeds.
    pub fastest: u32,
    /// The longest period the pacer may choose: the slowest rate.
    pub slowest: u32,
}

/// Why a [`PaceConfig`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PaceError {
    /// A half of no samples.
    EmptyHalf,
    /// A period of no ticks.
    ZeroPeriod,
    /// The slowest period is shorter than the fastest.
    SlowestBelowFastest,
}

impl fmt::Display for PaceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::EmptyHalf => "a half buffer needs at least one sample",
            Self::ZeroPeriod => "the fastest sample period must be at least one timer tick",
            Self::SlowestBelowFastest => "the slowest sample period is shorter than the fastest",
        })
    }
}

impl core::error::Error for PaceError {}

/// What [`Pacer::filled`] takes, from a circular DMA's position: the
/// samples of the other half played once half `filled` (0 or 1) of a buffer
/// of two halves of `half` samples is refilled, when the DMA reads slot
/// `next` next (`2 * half - NDTR` on an STM32). From `half` up: the DMA
/// was reading the half being refilled (it was late). Out-of-range
/// arguments are taken modulo the buffer.
pub fn played(next: usize, filled: usize, half: usize) -> u32 {
    let len = 2 * half.max(1);
    let other = (1 - filled % 2) * half.max(1);
    let used = (next % len + len - other) % len;
    u32::try_from(used).unwrap_or(u32::MAX)
}

/// Chooses the sample clock's period. See the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pacer {
    cfg: PaceConfig,
    period: u32,
    /// The costliest half since the window began, in timer ticks.
    worst: u64,
    /// Halves reported since the window began.
    halves: u32,
}

impl Pacer {
    /// A pacer at the fastest period.
    ///
    /// # Errors
    /// [`PaceError`] for an empty half, a zero period, or a slowest period
    /// shorter than the fastest.
    pub fn new(cfg: PaceConfig) -> Result<Self, PaceError> {
        if cfg.half == 0 {
            return Err(PaceError::EmptyHalf);
        }
        if cfg.fastest == 0 {
            return Err(PaceError::ZeroPeriod);
        }
        if cfg.slowest < cfg.fastest {
            return Err(PaceError::SlowestBelowFastest);
        }
        Ok(Self { cfg, period: cfg.fastest, worst: 0, halves: 0 })
    }

    /// The configuration.
    pub fn config(&self) -> &PaceConfig {
        &self.cfg
    }

    /// The period in force, in timer ticks a sample.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// The sample rate in force on a timer of `timer_hz`.
    pub fn rate_hz(&self, timer_hz: u32) -> u32 {
        timer_hz / self.period
    }

    /// A half was refilled: the DMA had played `used` samples of the other
    /// half when the refill ended (more than a half: it was late). Returns
    /// the new period when it changes, to be set on the timer.
    pub fn filled(&mut self, used: u32) -> Option<u32> {
        // Products of two u32s fit a u64; their multiples saturate, which
        // only periods and halves of billions would reach (no u128: its
        // division is a large software routine on the MCU).
        let cost = u64::from(used) * u64::from(self.period);
        let budget = u64::from(self.cfg.half) * u64::from(self.period);
        if cost.saturating_mul(8) > budget.saturating_mul(7) {
            return self.set(self.aim(cost));
        }
        self.worst = self.worst.max(cost);
        self.halves += 1;
        if self.halves < CALM_HALVES {
            return None;
        }
        let faster = self.aim(self.worst);
        self.worst = 0;
        self.halves = 0;
        if u64::from(faster) * 8 <= u64::from(self.period) * 7 { self.set(faster) } else { None }
    }

    /// The refill's cost changed for good (the picture's frame is now
    /// replayed from memory, a few cycles a sample): back to the fastest
    /// period, a new window begun, rather than waiting [`CALM_HALVES`] to
    /// speed up. A half that needs it still slows the clock at once.
    /// Returns the new period when it changes, to be set on the timer.
    pub fn restart(&mut self) -> Option<u32> {
        self.set(self.cfg.fastest)
    }

    /// The period at which a half costing `cost` ticks takes 3/4 of it,
    /// within the configured range.
    fn aim(&self, cost: u64) -> u32 {
        let quarters = 3 * u64::from(self.cfg.half);
        let period = cost.saturating_mul(4).div_ceil(quarters);
        u32::try_from(period).unwrap_or(u32::MAX).clamp(self.cfg.fastest, self.cfg.slowest)
    }

    /// Change to `period` (a new window begins); `Some` if it differs.
    fn set(&mut self, period: u32) -> Option<u32> {
        self.worst = 0;
        self.halves = 0;
        if period == self.period {
            return None;
        }
        self.period = period;
        Some(period)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const CFG: PaceConfig = PaceConfig { half: 512, fastest: 168, slowest: 672 };

    /// A board whose refill of a half costs `cost` timer ticks (and the
    /// main loop nothing else): the samples the DMA plays meanwhile.
    fn during(cost: u64, period: u32) -> u32 {
        u32::try_from(cost.div_ceil(u64::from(period))).unwrap_or(u32::MAX)
    }

    /// Run `halves` halves of refills costing `cost(k)` ticks; the halves
    /// that were late (more than a half played).
    fn run(pacer: &mut Pacer, halves: u32, cost: impl Fn(u32) -> u64) -> u32 {
        let mut late = 0;
        for k in 0..halves {
            let used = during(cost(k), pacer.period());
            if used > CFG.half {
                late += 1;
            }
            pacer.filled(used);
        }
        late
    }

    #[test]
    fn played_counts_from_the_start_of_the_other_half() {
        // Exhaustive over a small buffer: halves of 4 slots.
        for filled in 0..2 {
            for next in 0..8 {
                let other_start = (1 - filled) * 4;
                let expect = (next + 8 - other_start) % 8;
                assert_eq!(played(next, filled, 4), expect as u32, "filled {filled} next {next}");
            }
        }
        // The DMA just entered the other half: nothing played yet.
        assert_eq!(played(512, 0, 512), 0);
        assert_eq!(played(0, 1, 512), 0);
        // About to leave it: all but one.
        assert_eq!(played(1023, 0, 512), 511);
        // Already back in the half just refilled: late.
        assert_eq!(played(3, 0, 512), 515);
        // Nonsense in, no panic.
        assert_eq!(played(usize::MAX, 7, 0), 1);
    }

    #[test]
    fn config_errors_are_plain() {
        let bad = |c| Pacer::new(c).unwrap_err();
        assert_eq!(bad(PaceConfig { half: 0, ..CFG }), PaceError::EmptyHalf);
        assert_eq!(bad(PaceConfig { fastest: 0, ..CFG }), PaceError::ZeroPeriod);
        assert_eq!(bad(PaceConfig { slowest: 100, ..CFG }), PaceError::SlowestBelowFastest);
        assert_eq!(
            PaceError::SlowestBelowFastest.to_string(),
            "the slowest sample period is shorter than the fastest"
        );
        assert!(Pacer::new(PaceConfig { slowest: 168, ..CFG }).is_ok());
    }

    #[test]
    fn a_light_refill_keeps_the_configured_rate() {
        let mut pacer = Pacer::new(CFG).unwrap();
        // 70% of a half at 168 ticks a sample.
        let late = run(&mut pacer, 5 * CALM_HALVES, |_| 512 * 168 * 7 / 10);
        assert_eq!((late, pacer.period()), (0, 168));
    }

    #[test]
    fn a_dense_picture_slows_the_clock_after_one_half_and_is_never_late_again() {
        let mut pacer = Pacer::new(CFG).unwrap();
        // 1.6 halves' worth at the configured rate (hydrogen 24^3 at 1 MS/s).
        let cost = 512 * 168 * 16 / 10;
        let late = run(&mut pacer, 1, |_| cost);
        assert_eq!(late, 1);
        // 3/4 of a half at the new period.
        assert_eq!(pacer.period(), 359);
        assert_eq!(run(&mut pacer, 4 * CALM_HALVES, |_| cost), 0);
        assert_eq!(pacer.period(), 359);
    }

    #[test]
    fn a_nearly_late_half_slows_the_clock_before_it_is_late() {
        let mut pacer = Pacer::new(CFG).unwrap();
        // 90% of a half: not late, but over 7/8.
        assert_eq!(run(&mut pacer, 1, |_| 512 * 168 * 9 / 10), 0);
        assert!(pacer.period() > 168);
        // 85%: left alone.
        let mut pacer = Pacer::new(CFG).unwrap();
        run(&mut pacer, 1, |_| 512 * 168 * 85 / 100);
        assert_eq!(pacer.period(), 168);
    }

    /// A pacer slowed by one half that cost two at the configured rate:
    /// to 448 ticks, where that refill takes 3/4 of a half.
    fn slowed() -> Pacer {
        let mut pacer = Pacer::new(CFG).unwrap();
        run(&mut pacer, 1, |_| 512 * 168 * 2);
        assert_eq!(pacer.period(), 448);
        pacer
    }

    #[test]
    fn a_restart_goes_back_to_the_fastest_period_at_once() {
        let mut pacer = slowed();
        assert!(pacer.period() > CFG.fastest);
        assert_eq!(pacer.restart(), Some(CFG.fastest));
        assert_eq!(pacer.restart(), None, "already there");
        // A light refill keeps it; a heavy one slows it again at once.
        assert_eq!(run(&mut pacer, 10, |_| 20_000), 0);
        assert_eq!(pacer.period(), CFG.fastest);
        assert!(pacer.filled(500).is_some());
    }

    #[test]
    fn the_clock_speeds_up_again_once_the_picture_is_lighter() {
        let mut pacer = slowed();
        // A light picture: after a window of calm halves, straight to the
        // configured rate (its cost is far below 3/4 there).
        run(&mut pacer, CALM_HALVES - 1, |_| 512 * 100);
        assert_eq!(pacer.period(), 448, "a window is watched first");
        run(&mut pacer, 1, |_| 512 * 100);
        assert_eq!(pacer.period(), 168);
    }

    #[test]
    fn speeding_up_needs_the_worst_half_of_the_window_to_allow_it() {
        let mut pacer = slowed();
        // One costly half in each window (80% of a half: below the
        // slow-down bound) holds the clock where it is.
        let costly = |k: u32| if k % CALM_HALVES == 7 { 512 * 448 * 8 / 10 } else { 512 * 50 };
        assert_eq!(run(&mut pacer, 3 * CALM_HALVES, costly), 0);
        assert_eq!(pacer.period(), 448);
    }

    #[test]
    fn a_cost_that_wavers_a_little_does_not_make_the_clock_hunt() {
        let mut pacer = slowed();
        let settled = pacer.period();
        let mut changes = 0;
        let mut last = settled;
        for k in 0..20 * CALM_HALVES {
            // 90% to 96% of the cost it settled for: a little faster would
            // do, but not 1/8 faster.
            let cost = u64::from(512 * settled * 3 / 4) * (90 + u64::from(k % 7)) / 100;
            pacer.filled(during(cost, pacer.period()));
            if pacer.period() != last {
                changes += 1;
                last = pacer.period();
            }
        }
        assert_eq!(changes, 0, "settled at {settled}, now {}", pacer.period());
    }

    #[test]
    fn the_slowest_period_bounds_a_refill_that_can_never_keep_up() {
        let mut pacer = Pacer::new(CFG).unwrap();
        let late = run(&mut pacer, 100, |_| 512 * 1000);
        assert_eq!(pacer.period(), 672);
        // Late every half: the board can do no better at its slowest rate.
        assert_eq!(late, 100);
    }

    proptest! {
        #[test]
        fn the_period_stays_in_range_for_any_reports(
            half in 1u32..=u32::MAX,
            fastest in 1u32..=u32::MAX,
            spread in 0u32..=u32::MAX,
            used in proptest::collection::vec(any::<u32>(), 0..2000),
        ) {
            let slowest = fastest.saturating_add(spread);
            let mut pacer = Pacer::new(PaceConfig { half, fastest, slowest }).unwrap();
            for u in used {
                let before = pacer.period();
                let changed = pacer.filled(u);
                prop_assert!((fastest..=slowest).contains(&pacer.period()));
                prop_assert_eq!(changed.is_some(), pacer.period() != before);
                if let Some(p) = changed {
                    prop_assert_eq!(p, pacer.period());
                }
            }
        }

        #[test]
        fn after_a_slow_down_the_same_cost_fits_in_seven_eighths(
            cost in 1u64..(512 * 672 * 7 / 8),
        ) {
            let mut pacer = Pacer::new(CFG).unwrap();
            pacer.filled(during(cost, pacer.period()));
            let again = during(cost, pacer.period());
            prop_assert!(u64::from(again) * 8 <= u64::from(CFG.half) * 7 + 8, "cost {} used {} at {}", cost, again, pacer.period());
        }
    }
}
