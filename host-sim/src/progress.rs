//! Progress for long work, on standard error, only when it is a terminal.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// A shared counter that redraws one status line at most ten times a second.
#[derive(Debug)]
pub struct Progress {
    label: &'static str,
    total: usize,
    done: AtomicUsize,
    last: Mutex<Option<Instant>>,
    enabled: bool,
}

impl Progress {
    /// Progress over `total` units; silent unless stderr is a terminal.
    pub fn new(label: &'static str, total: usize) -> Self {
        Self::with_output(label, total, std::io::stderr().is_terminal())
    }

    /// As [`Progress::new`], shown or not as `enabled` says.
    pub fn with_output(label: &'static str, total: usize, enabled: bool) -> Self {
        Self { label, total, done: AtomicUsize::new(0), last: Mutex::new(None), enabled }
    }

    /// Units finished so far.
    pub fn done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }

    /// One more unit finished.
    pub fn inc(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
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
