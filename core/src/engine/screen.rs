//! The picture half of the engine: the surface on screen projected through
//! the view ([`Projected`]), and the frames a board plays of it ([`Frame`]):
//! scheduled live, or replayed from a recording of the first frame while
//! the picture stands still ([`crate::beam::replay`]).

use crate::beam::replay::{Player, Recorder, Replay};
use crate::beam::{BeamConfig, FrameStats, Scheduler};
use crate::command::{Command, Point3};
use crate::output::{RunSink, Sample, SampleSource};
use crate::path::{Commands, Geometry};
use crate::view::{ScreenPoint, ViewTransform};

/// The picture half of an [`Engine`](super::Engine)
/// ([`Engine::split`](super::Engine::split)): the surface on screen, its
/// view, the beam settings it is played with, and the replay of its frame.
#[derive(Debug)]
pub struct Screen<'e, 'a> {
    pub(super) front: &'e Geometry<'a>,
    pub(super) transform: Option<ViewTransform>,
    pub(super) beam: BeamConfig,
    pub(super) replay: Replay<'e>,
    /// The picture's generation, when its frames may be replayed (a still
    /// picture, nothing about to change it).
    pub(super) key: Option<u32>,
}

impl<'e, 'a> Screen<'e, 'a> {
    /// One frame, the samples of [`Engine::frame`](super::Engine::frame):
    /// replayed when the picture's frame is kept, else scheduled (and kept,
    /// if the engine replays frames and the frame fits).
    pub fn frame(&mut self) -> Frame<'_, 'e> {
        let live = Scheduler::new(Projected::new(self.front, self.transform), &self.beam);
        let Some(key) = self.key else { return Frame::Live(live) };
        if self.replay.holds(key) {
            return match self.replay.play(key) {
                Some(player) => Frame::Replay(player),
                None => Frame::Live(live),
            };
        }
        match self.replay.record(key) {
            Some(rec) => Frame::Recording(live, rec),
            None => Frame::Live(live),
        }
    }

    /// The picture's drawing commands on the screen, in drawing order.
    pub fn commands(&self) -> Projected<'e> {
        Projected::new(self.front, self.transform)
    }

    /// The beam settings.
    pub fn beam(&self) -> &BeamConfig {
        &self.beam
    }
}

/// One frame as a board plays it ([`Screen::frame`]): a [`SampleSource`]
/// and an iterator of the same samples whichever way they are made.
#[derive(Debug)]
pub enum Frame<'r, 'a> {
    /// Scheduled from the picture's commands.
    Live(Scheduler<Projected<'r>>),
    /// Scheduled, and recorded for the frames after it.
    Recording(Scheduler<Projected<'r>>, Recorder<'r, 'a>),
    /// Played from the recording.
    Replay(Player<'r>),
}

impl Frame<'_, '_> {
    /// Whether the frame is replayed from a recording (its refill costs a
    /// few cycles a sample).
    pub fn is_replay(&self) -> bool {
        matches!(self, Self::Replay(_))
    }

    /// The frame's statistics so far ([`Scheduler::stats`]); a replayed
    /// frame's are those of the frame recorded, whole.
    pub fn stats(&self) -> FrameStats {
        match self {
            Self::Live(s) | Self::Recording(s, _) => s.stats(),
            Self::Replay(p) => p.stats(),
        }
    }
}

impl SampleSource for Frame<'_, '_> {
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize {
        self.fill_runs(max, &mut crate::output::Each(put))
    }

    #[inline]
    fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        match self {
            Self::Live(s) => s.fill_runs(max, sink),
            Self::Recording(s, rec) => {
                let n = rec.fill_runs(s, max, sink);
                if n < max {
                    rec.finish(s.stats());
                }
                n
            }
            Self::Replay(p) => p.fill_runs(max, sink),
        }
    }
}

impl Iterator for Frame<'_, '_> {
    type Item = Sample;

    fn next(&mut self) -> Option<Sample> {
        self.next_sample()
    }
}

impl core::iter::FusedIterator for Frame<'_, '_> {}

/// The picture's commands projected on the screen (nothing without a
/// picture).
#[derive(Debug, Clone)]
pub struct Projected<'e> {
    commands: Commands<'e, 'e>,
    transform: Option<ViewTransform>,
}

impl<'e> Projected<'e> {
    /// `front`'s commands through `transform`, taken in the store's own
    /// fixed point (the transform scaled to it, bit-identical).
    pub(super) fn new(front: &'e Geometry<'_>, transform: Option<ViewTransform>) -> Self {
        let transform = transform.map(|t| t.in_steps_of(front.shift()));
        Self { commands: front.commands(), transform }
    }
}

impl Iterator for Projected<'_> {
    type Item = Command<ScreenPoint>;

    #[inline]
    fn next(&mut self) -> Option<Command<ScreenPoint>> {
        // By reference: the transform is some twenty words, and this runs
        // for every point of every frame.
        let t = self.transform.as_ref()?;
        // Unchecked: the scheduler skips points that are not finite.
        self.commands
            .next_packed()
            .map(|c| c.map(|[x, y, z]| t.project_raw(Point3::new(f32::from(x), f32::from(y), f32::from(z)))))
    }
}
