//! Progress for long work, on standard error, only when it is a terminal,
//! or to a function (the web app's worker posts it to the page).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// A function told of each unit finished: the label, the units done and
/// the total. It is called on the thread that finished the unit, as often
/// as units finish: it keeps its own pace.
pub type Hook = fn(&'static str, usize, usize);

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

    /// One more unit finished.
    pub fn inc(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(hook) = self.hook {
            hook(self.label, done, self.total);
        }
        if !self.enabled {
            return;
        }
        let Ok(mut last) = self.last.lock() else { return };
        let now = Instant::now();
        if done == self.total || last.is_none_or(|t| now - t >= Duration::from_millis(100)) {
            *last = Some(now);
            let pct = (done * 100).checked_div(self.total).unwrap_or(100);
            let _ = write!(std::io::stderr(), "\r{}: {done}/{} ({pct}%)", self.label, self.total);
            if done == self.total {
                let _ = writeln!(std::io::stderr());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    static SEEN: AtomicUsize = AtomicUsize::new(0);

    fn hook(label: &'static str, done: usize, total: usize) {
        assert_eq!((label, total), ("work", 3));
        SEEN.store(done, Ordering::Relaxed);
    }

    #[test]
    fn a_hook_is_told_each_unit() {
        let p = Progress::with_hook("work", 3, hook);
        p.inc();
        p.inc();
        assert_eq!(SEEN.load(Ordering::Relaxed), 2);
        assert_eq!(p.done(), 2);
    }
}
