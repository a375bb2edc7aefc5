//! What the board's sample clock settles at for a picture, from the cycle
//! cost of refilling each of its half buffers: the core's [`Pacer`] fed as
//! the board feeds it, the costs repeating frame after frame.
//!
//! `scripts/firmware-bench` runs it with the estimated cycles of each half
//! refilled under QEMU, in order (`scripts/firmware-profile`).
//!
//! Usage: `cargo run -p isoscope-core --example pace -- HALF TIMER_HZ
//! CPU_HZ RATE_HZ MIN_RATE_HZ CYCLES...`; prints `key=value` lines.

use isoscope_core::beam::pace::{CALM_HALVES, PaceConfig, Pacer};
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<u64> = match std::env::args().skip(1).map(|a| a.parse::<u64>()).collect() {
        Ok(v) => v,
        Err(e) => {
            eprintln!("pace: {e} (usage: pace HALF TIMER_HZ CPU_HZ RATE_HZ MIN_RATE_HZ CYCLES...)");
            return ExitCode::from(2);
        }
    };
    let [half, timer_hz, cpu_hz, rate_hz, min_rate_hz, ref costs @ ..] = args[..] else {
        eprintln!("pace: usage: pace HALF TIMER_HZ CPU_HZ RATE_HZ MIN_RATE_HZ CYCLES...");
        return ExitCode::from(2);
    };
    if costs.is_empty() || [half, timer_hz, cpu_hz, rate_hz, min_rate_hz].contains(&0) {
        eprintln!("pace: every figure must be positive and at least one half's cycles given");
        return ExitCode::from(2);
    }
    let ticks = |hz: u64| u32::try_from(timer_hz / hz).unwrap_or(u32::MAX);
    let cfg = PaceConfig {
        half: u32::try_from(half).unwrap_or(u32::MAX),
        fastest: ticks(rate_hz),
        slowest: ticks(min_rate_hz),
    };
    let mut pacer = match Pacer::new(cfg) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("pace: {e}");
            return ExitCode::from(2);
        }
    };
    // Long enough for every slow-down and speed-up to settle; the last
    // window is reported.
    let rounds = (8 * u64::from(CALM_HALVES)).div_ceil(costs.len() as u64).max(2);
    let (mut late, mut worst_share) = (0u32, 0f64);
    for round in 0..rounds {
        let last = round + 1 == rounds;
        for &cycles in costs {
            // The refill's cost in timer ticks, and the samples of the
            // other half the DMA plays meanwhile.
            let cost = cycles.saturating_mul(timer_hz) / cpu_hz;
            let period = u64::from(pacer.period());
            let used = u32::try_from(cost.div_ceil(period)).unwrap_or(u32::MAX);
            if last {
                late += u32::from(u64::from(used) > half);
                worst_share = worst_share.max(f64::from(used) / half as f64);
            }
            pacer.filled(used);
        }
    }
    println!("sample_rate_hz={}", pacer.rate_hz(u32::try_from(timer_hz).unwrap_or(u32::MAX)));
    println!("period_ticks={}", pacer.period());
    println!("worst_half_share={worst_share:.3}");
    println!("late_halves_per_frame={late}");
    ExitCode::SUCCESS
}
