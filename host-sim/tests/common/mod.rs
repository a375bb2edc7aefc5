//! Helpers shared by the host tool's integration tests (each test crate
//! uses some of them).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// A cached real data file (`scripts/fetch-data`, which `scripts/test`
/// runs first); a missing one fails the test.
pub fn real_data(name: &str) -> PathBuf {
    let dir = std::env::var_os("ISOSCOPE_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/isoscope-data"));
    let path = dir.join(name);
    assert!(path.is_file(), "{} is missing: run scripts/fetch-data", path.display());
    path
}

/// Stops process `pid` (with `kill`) should it run for two minutes, so that
/// a test waiting for a virtual board to exit fails instead of waiting for
/// good.
pub struct Watchdog {
    done: Arc<AtomicBool>,
    thread: JoinHandle<bool>,
}

impl Watchdog {
    /// Watch process `pid`.
    pub fn new(pid: u32) -> Self {
        let done = Arc::new(AtomicBool::new(false));
        let thread = {
            let (done, pid) = (Arc::clone(&done), pid.to_string());
            std::thread::spawn(move || {
                for _ in 0..1200 {
                    if done.load(Ordering::Relaxed) {
                        return false;
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
                let _ = std::process::Command::new("kill").arg(&pid).status();
                true
            })
        };
        Self { done, thread }
    }

    /// The process ended: whether the watchdog had to stop it.
    pub fn stopped_it(self) -> bool {
        self.done.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// A scratch folder, `isoscope-NAME-PID` in the system's, removed
/// afterwards.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("isoscope-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    /// The path of file `name` in it.
    pub fn path(&self, name: &str) -> String {
        self.0.join(name).to_string_lossy().into_owned()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
