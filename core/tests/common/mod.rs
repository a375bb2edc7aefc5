//! Helpers shared by the core's integration tests.

use isoscope_core::command::{Command, CommandSink, Point2};
use std::convert::Infallible;

/// A sink that keeps every command with its level index.
#[derive(Default)]
pub struct Log(pub Vec<(usize, Command<Point2>)>);

impl CommandSink<Point2> for Log {
    type Error = Infallible;
    fn command(&mut self, level: usize, c: Command<Point2>) -> Result<(), Infallible> {
        self.0.push((level, c));
        Ok(())
    }
}
