//! Progress for long work, on standard error, only when it is a terminal,
//! or to a function (the web app's worker posts it to the page).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// A function told of the work done: the label, the units done and the
/// total. It is called on the thread that finished the units, when the
/// count passes each of [`HOOK_STEPS`] even steps of the total and when it
/// reaches the total (every unit when the total is smaller): at most a few
/// hundred calls for any amount of work (the web app's worker crosses from
/// WebAssembly to JavaScript for each, with its label as a new string).
pub type Hook = fn(&'static str, usize, usize);

/// Steps of the total at which a [`Hook`] is told.
pub const HOOK_STEPS: usize = 256;

/// A shared counter that redraws one status line at most ten times a second.
#[derive(Debug)]
pub struct Progress {
    label: &'static str,
    total: usize,
    done: AtomicUsize,
    last: Mutex<Option<Instant>>,
    enabled: bool,
    hook: Option<Hook>,
}

impl Progress {
    /// Progress over `total` units; silent unless stderr is a terminal.
    pub fn new(label: &'static str, total: usize) -> Self {
        Self::with_output(label, total, std::io::stderr().is_terminal())
    }

    /// As [`Progress::new`], shown or not as `enabled` says.
    pub fn with_output(label: &'static str, total: usize, enabled: bool) -> Self {
        Self { label, total, done: AtomicUsize::new(0), last: Mutex::new(None), enabled, hook: None }
    }

    /// Progress over `total` units told to `hook` (and not shown).
    pub fn with_hook(label: &'static str, total: usize, hook: Hook) -> Self {
        Self { hook: Some(hook), ..Self::with_output(label, total, false) }
    }

    /// Units finished so far.
    pub fn done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }

    /// Units in all.
    pub fn total(&self) -> usize {
        self.total
    }

    /// One more unit finished.
    pub fn inc(&self) {
        self.add(1);
    }

    /// `n` more units finished.
    pub fn add(&self, n: usize) {
        let before = self.done.fetch_add(n, Ordering::Relaxed);
        let done = before.saturating_add(n);
        // This call took the count to the total.
        let finished = done >= self.total && before < self.total;
        if let Some(hook) = self.hook {
            let step = (self.total / HOOK_STEPS).max(1);
            if finished || done / step != before / step {
                hook(self.label, done, self.total);
            }
        }
        if !self.enabled || n == 0 {
            return;
        }
        let Ok(mut last) = self.last.lock() else { return };
        let now = Instant::now();
        if finished || last.is_none_or(|t| now - t >= Duration::from_millis(100)) {
            *last = Some(now);
            let _ = write!(std::io::stderr(), "\r{}", status(self.label, done, self.total));
            if finished {
                let _ = writeln!(std::io::stderr());
            }
        }
    }

    /// The same work begins again from nothing (done over, e.g. with more
    /// memory): the count starts again at 0, so it never passes the total.
    pub fn restart(&self) {
        self.done.store(0, Ordering::Relaxed);
        if let Ok(mut last) = self.last.lock() {
            *last = None;
        }
    }
}

/// The status line of `done` units of `total`: `label: done/total (pct%)`,
/// the percentage rounded down (100 when there is nothing to do), without
/// overflow.
pub fn status(label: &str, done: usize, total: usize) -> String {
    let pct = (done as u128 * 100).checked_div(total as u128).unwrap_or(100);
    format!("{label}: {done}/{total} ({pct}%)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_line_counts_to_the_total() {
        assert_eq!(status("contouring", 0, 7), "contouring: 0/7 (0%)");
        assert_eq!(status("contouring", 3, 7), "contouring: 3/7 (42%)");
        assert_eq!(status("contouring", 7, 7), "contouring: 7/7 (100%)");
        assert_eq!(status("nothing", 0, 0), "nothing: 0/0 (100%)");
        // No overflow where `done * 100` passes the word.
        assert_eq!(
            status("writing", usize::MAX / 2, usize::MAX),
            format!("writing: {}/{} (49%)", usize::MAX / 2, usize::MAX)
        );
    }

    #[test]
    fn counts_add_up_and_start_again() {
        let p = Progress::with_output("work", 10, false);
        p.inc();
        p.add(4);
        assert_eq!((p.done(), p.total()), (5, 10));
        p.restart();
        assert_eq!(p.done(), 0);
        (0..10).for_each(|_| p.inc());
        assert_eq!(p.done(), 10);
    }

    static SEEN: AtomicUsize = AtomicUsize::new(0);

    fn hook(label: &'static str, done: usize, total: usize) {
        assert_eq!((label, total), ("work", 3));
        SEEN.store(done, Ordering::Relaxed);
    }

    #[test]
    fn a_hook_is_told_each_unit_of_a_little_work() {
        let p = Progress::with_hook("work", 3, hook);
        p.inc();
        p.inc();
        assert_eq!(SEEN.load(Ordering::Relaxed), 2);
        assert_eq!(p.done(), 2);
    }

    static CALLS: AtomicUsize = AtomicUsize::new(0);
    static LAST: AtomicUsize = AtomicUsize::new(0);

    fn counted(_: &'static str, done: usize, total: usize) {
        assert_eq!(total, 100_003);
        assert!(done > LAST.swap(done, Ordering::Relaxed) || done <= total / HOOK_STEPS, "counts go on");
        CALLS.fetch_add(1, Ordering::Relaxed);
    }

    #[test]
    fn a_hook_is_told_of_much_work_in_steps_and_at_its_end() {
        let p = Progress::with_hook("work", 100_003, counted);
        (0..100_002).for_each(|_| p.inc());
        let calls = CALLS.load(Ordering::Relaxed);
        assert!((HOOK_STEPS - 1..=HOOK_STEPS).contains(&calls), "{calls} calls");
        p.inc();
        assert_eq!(LAST.load(Ordering::Relaxed), 100_003, "told of the last unit");
        // Begun again: told again from the first step.
        p.restart();
        p.add(100_003 / HOOK_STEPS);
        assert_eq!(LAST.load(Ordering::Relaxed), 100_003 / HOOK_STEPS);
        assert_eq!(CALLS.load(Ordering::Relaxed), calls + 2);
    }
}
