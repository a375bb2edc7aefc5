//! isoscope firmware: a contour surface on an XY oscilloscope, from an
//! STM32F407G-DISC1 (see `board` for the pins and the output path), fed
//! volumes over a UART by `isoscope-sim send`.
//!
//! The board is the core's device engine ([`isoscope_core::engine`]) behind
//! USART2 ([`serial`]): it takes the host's frames, answers them, streams
//! and contours each volume a slice at a time, and keeps the picture on
//! screen until a new volume is complete. At boot it feeds itself the
//! built-in hydrogen orbital ([`isoscope_scene::boot_frames`]), so the
//! scope shows a picture before any host has spoken.
//!
//! The main loop plays frames of the picture ([`Screen::frame`], from the
//! park position back to it) through the DMA double buffer. Between two
//! half-buffer refills it feeds the received bytes to the engine
//! ([`Link::feed`], through [`Engine::split`]) and queues its answers for
//! the UART; at each frame boundary it calls [`Engine::update`], where a
//! new volume or view becomes the picture.
//!
//! Under the `qemu` feature the same loop runs on QEMU's netduinoplus2
//! without a sample clock, for the end-to-end test
//! (`scripts/firmware-qemu-test`): it records [`isoscope_scene::QEMU_FRAMES`]
//! frames of the boot picture, then, after the first volume received over
//! USART2 is drawn, plays one frame of it unrecorded and records as many
//! frames of it, sends its answers and exits QEMU. With `bench` too
//! (`scripts/firmware-bench`) there is no boot picture and nothing is
//! recorded: the received volume's frames are the board's refill alone.
//!
//! [`Screen::frame`]: isoscope_core::engine::Screen::frame
#![no_std]
#![no_main]

mod board;
mod clock;
mod mem;
mod serial;
mod stack;

use board::Filled;
use cortex_m_rt::{ExceptionFrame, entry, exception};
use isoscope_core::engine::{Engine, Link};
use isoscope_core::wire::DeviceState;
use panic_probe as _;
use serial::{Rx, Tx};

#[cfg(not(feature = "qemu"))]
use defmt_rtt as _;
#[cfg(feature = "qemu")]
use defmt_semihosting as _;

/// Watchdog timeout (LSI tolerance can shorten it to about 0.7 of this).
/// The main loop feeds it every half buffer (512 us), but the longest
/// stretches without feeding are the boot picture, contouring a slice and
/// stitching and ordering a new surface (see docs/board-refresh.md).
const WATCHDOG_MS: u32 = 3_000;
/// Received bytes fed to the engine between two half-buffer refills (at
/// 921,600 baud about 47 arrive in the 512 us of a half).
const FEED_CHUNK: usize = 256;
/// Core cycles spent contouring between two half-buffer refills while a
/// completed slice has work pending, in whole rows (a row of a 128-wide
/// slice is some 15,000 instructions; one more row may start just before
/// the budget runs out); more while the output waits for a free half.
const CONTOUR_CYCLES: u32 = 6_000;

#[entry]
fn main() -> ! {
    stack::paint();
    let mut board = board::init(WATCHDOG_MS);
    defmt::info!(
        "isoscope: {} Hz core, {} samples/s; host link USART2 at {} baud (really {}); engine {} B + buffers {} B SRAM + {} B {}",
        board.sysclk_hz,
        board::SAMPLE_RATE_HZ,
        board::BAUD,
        serial::actual_baud(board.pclk1_hz, board::BAUD),
        mem::ENGINE_BYTES,
        mem::SRAM_BYTES,
        mem::CCM_BYTES,
        if cfg!(feature = "qemu") { "SRAM" } else { "CCM" },
    );
    let engine = match mem::engine() {
        Some(Ok(e)) => e,
        Some(Err(e)) => {
            defmt::error!("isoscope: the engine refused its settings: {}", e);
            board::fault();
        }
        None => board::fault(),
    };
    board.out.set_park(engine.beam().park_sample());
    board.out.park();
    // A new picture's frame is counted as it plays, not in `update` with
    // the beam parked (see `run`).
    engine.count_while_playing(true);
    // A still picture's first frame is kept in the idle slice memory and
    // replayed: the refill at full rate (docs/board-refresh.md).
    engine.replay_frames(true);
    if !cfg!(feature = "bench") {
        boot(engine);
    }
    board.watchdog.feed();
    run(board, engine)
}

/// Put the built-in volume on screen: feed the engine its frames as a host
/// would, drop the answers (nobody asked), draw it.
fn boot(engine: &mut Engine<'_>) {
    let t0 = clock::cycles();
    // Nothing plays yet: the contouring deferred is done as the frames come.
    if isoscope_scene::boot_frames(|frame| {
        engine.feed_all(frame, clock::now_ms());
    })
    .is_err()
    {
        defmt::error!("isoscope: the boot volume could not be encoded");
    }
    let t1 = clock::cycles();
    let fed_stack = stack::peak();
    engine.update(clock::now_ms());
    let t2 = clock::cycles();
    let mut sink = [0u8; 64];
    while engine.transmit(&mut sink) > 0 {}
    defmt::info!(
        "isoscope: boot picture {}^3 {}: fed in {} cycles, drawn in {} cycles; stack {} bytes after feeding, {} after drawing",
        isoscope_scene::SIDE,
        isoscope_scene::DEMO.name(),
        t1.wrapping_sub(t0),
        t2.wrapping_sub(t1),
        fed_stack,
        stack::peak()
    );
    log_events(engine);
}

/// Log the engine's events.
fn log_events(engine: &mut Engine<'_>) {
    while let Some(ev) = engine.next_event() {
        defmt::info!("engine t={}ms: {}", clock::now_ms(), ev);
    }
}

/// Move the engine's answers into the transmit ring (as many as fit; the
/// rest wait in the engine's queue) and start sending.
fn answer(link: &mut Link<'_, '_>, tx: &mut Tx) {
    let mut buf = [0u8; 64];
    while link.pending() > 0 {
        let room = tx.room().min(buf.len());
        if room == 0 {
            break;
        }
        let n = link.transmit(buf.get_mut(..room).unwrap_or_default());
        tx.write(buf.get(..n).unwrap_or_default());
    }
    tx.pump();
}

/// Received bytes the engine has not taken yet: it stops after a frame
/// that completes a slice and takes the rest once that slice is contoured.
struct Inbox {
    buf: [u8; FEED_CHUNK],
    start: usize,
    end: usize,
}

impl Inbox {
    const fn new() -> Self {
        Self { buf: [0; FEED_CHUNK], start: 0, end: 0 }
    }

    /// The bytes waiting, after topping up from `rx` when there are none.
    fn bytes(&mut self, rx: &mut Rx) -> &[u8] {
        if self.start >= self.end {
            self.start = 0;
            self.end = rx.read(&mut self.buf);
        }
        self.buf.get(self.start..self.end).unwrap_or_default()
    }

    fn consume(&mut self, n: usize) {
        self.start = (self.start + n).min(self.end);
    }
}

/// Between two half-buffer refills: rows of the pending contouring (for
/// [`CONTOUR_CYCLES`]), or feed what arrived; send the answers. `refill`
/// refills a free half of the output, if any, from inside a long pass (a
/// thinning of the surface, several milliseconds).
fn serve(
    link: &mut Link<'_, '_>,
    rx: &mut Rx,
    inbox: &mut Inbox,
    tx: &mut Tx,
    timing: &mut Timing,
    refill: &mut dyn FnMut(),
) {
    let busy = link.busy();
    if busy || !inbox.bytes(rx).is_empty() {
        let receiving = link.state() == DeviceState::Receiving;
        let t0 = clock::cycles();
        if busy {
            link.contour_polling(|_| clock::cycles().wrapping_sub(t0) < CONTOUR_CYCLES, refill);
        } else {
            let n = link.feed(inbox.bytes(rx), clock::now_ms());
            inbox.consume(n);
        }
        let dt = clock::cycles().wrapping_sub(t0);
        timing.feed = timing.feed.max(dt);
        match (receiving, link.state() == DeviceState::Receiving) {
            (false, true) => timing.volume_feed = u64::from(dt),
            (true, _) => timing.volume_feed += u64::from(dt),
            (false, false) => {}
        }
    }
    answer(link, tx);
}

/// Refill a free half of the output from `frame`, if one is free (never
/// waiting): from inside a long pass of the engine. (Never inlined: the
/// profile of the dark stretches, `scripts/firmware-dark`, names it.)
#[inline(never)]
fn refill(out: &mut board::Streaming, frame: &mut impl isoscope_core::output::SampleSource) {
    if out.ready() && out.fill_from(frame).is_err() {
        board::fault();
    }
}

/// The longest stretches the main loop spent away from the output, in core
/// cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, defmt::Format)]
struct Timing {
    /// One `Link::feed` or `Link::contour_while` call.
    feed: u32,
    /// The `Link::feed` and `Link::contour_while` calls of the last volume
    /// received, from the one that began it to the one that ended it:
    /// decoding and contouring.
    volume_feed: u64,
    /// One `Engine::update` that redrew the picture.
    update: u32,
    /// Filling one half buffer (512 samples) from the beam scheduler (on
    /// the board, with the wait for the DMA to free it).
    fill: u32,
    /// All half-buffer fills, and how many.
    fill_total: u64,
    halves: u32,
}

/// Log what changed: new longest stretches, late refills, link losses, a
/// deeper stack (checked once a second).
struct Report {
    timing: Timing,
    late: u32,
    /// The sample rate last logged.
    rate_hz: u32,
    serial: serial::Stats,
    core_mhz: u32,
    stack: usize,
    stack_checked_ms: u32,
}

impl Report {
    fn new(core_hz: u32) -> Self {
        Self {
            timing: Timing::default(),
            late: 0,
            rate_hz: board::SAMPLE_RATE_HZ,
            serial: serial::stats(),
            core_mhz: (core_hz / 1_000_000).max(1),
            stack: 0,
            stack_checked_ms: 0,
        }
    }

    /// The sample clock runs at `hz` (paced): log a change.
    fn rate(&mut self, hz: u32, refresh_hz: f32) {
        if hz != self.rate_hz {
            self.rate_hz = hz;
            defmt::info!("isoscope: sample clock {} samples/s, picture refreshed at {} Hz", hz, refresh_hz);
        }
    }

    fn log(&mut self, timing: Timing, late: u32) {
        if (timing.feed, timing.update, timing.fill)
            != (self.timing.feed, self.timing.update, self.timing.fill)
        {
            self.timing = timing;
            defmt::info!(
                "isoscope: longest feed {} us, redraw {} us, half-buffer fill {} us ({} / {} / {} cycles)",
                timing.feed / self.core_mhz,
                timing.update / self.core_mhz,
                timing.fill / self.core_mhz,
                timing.feed,
                timing.update,
                timing.fill
            );
        }
        if late != self.late {
            self.late = late;
            defmt::warn!("isoscope: {} half buffers refilled late", late);
        }
        let s = serial::stats();
        if (s.dropped, s.overruns) != (self.serial.dropped, self.serial.overruns) {
            defmt::warn!("isoscope: host link {}", s);
        }
        self.serial = s;
        let now = clock::now_ms();
        if now.wrapping_sub(self.stack_checked_ms) >= 1_000 {
            self.stack_checked_ms = now;
            let peak = stack::peak();
            if peak > self.stack {
                self.stack = peak;
                defmt::info!("isoscope: stack peak {} of {} bytes", peak, stack::size());
            }
        }
    }
}

/// The main loop: frame after frame of the picture, the link served
/// between half buffers, the engine updated between frames.
fn run(board: board::Board, engine: &mut Engine<'static>) -> ! {
    let board::Board { out, mut watchdog, mut rx, mut tx, sysclk_hz, .. } = board;
    let mut inbox = Inbox::new();
    let mut out = out.start();
    let mut timing = Timing::default();
    let mut report = Report::new(sysclk_hz);
    let mut replaying = false;
    #[cfg(feature = "qemu")]
    let mut script = qemu::Script::new(engine.counters().volumes);
    defmt::info!("isoscope: showing the picture; listening on USART2");
    loop {
        // A frame boundary: what the link changed becomes the picture. A
        // commit takes long (docs/board-refresh.md): the picture on screen
        // plays on from its recording meanwhile, refilled from inside the
        // commit; or, with no recording to play (or a commit that needs
        // all of the memory), the beam waits parked and blanked.
        log_events(engine);
        let hold = engine.commit_parks();
        if hold && out.hold().is_err() {
            board::fault();
        }
        // The sample clock may have been slowed (or sped up again) for
        // this picture: the refresh rate reported follows it.
        let rate = out.sample_rate_hz();
        engine.set_playback_rate(rate);
        report.rate(rate, engine.refresh_hz());
        let t0 = clock::cycles();
        let redrawn = engine.update_playing(clock::now_ms(), &mut |frame| {
            refill(&mut out, frame);
            watchdog.feed();
        });
        // The old frame to its end: the new picture starts on a frame
        // boundary.
        if let Some(mut rest) = engine.unfinished() {
            loop {
                match out.fill_from(&mut rest) {
                    Ok(Filled::Half) => watchdog.feed(),
                    Ok(Filled::FrameEnd) => break,
                    Err(_) => board::fault(),
                }
            }
        }
        if redrawn {
            timing.update = timing.update.max(clock::cycles().wrapping_sub(t0));
        }
        if hold {
            out.release();
        }
        answer(&mut engine.split().0, &mut tx);
        log_events(engine);
        report.log(timing, out.late());
        #[cfg(feature = "qemu")]
        script.boundary(redrawn, engine, &mut out, &mut tx, &report);

        let (mut link, mut screen) = engine.split();
        let mut frame = screen.frame();
        // From a scheduled frame to a replayed one, the refill costs a few
        // cycles a sample: the sample clock goes back to full rate at once.
        if frame.is_replay() && !replaying {
            out.restart_pacing();
        }
        replaying = frame.is_replay();
        loop {
            let t0 = clock::cycles();
            match out.fill_from(&mut frame) {
                Ok(Filled::Half) => {
                    let dt = clock::cycles().wrapping_sub(t0);
                    timing.fill = timing.fill.max(dt);
                    timing.fill_total += u64::from(dt);
                    timing.halves = timing.halves.wrapping_add(1);
                }
                Ok(Filled::FrameEnd) => break,
                Err(_) => {
                    defmt::error!("isoscope: DMA transfer error; beam parked, waiting for the watchdog");
                    board::fault();
                }
            }
            serve(&mut link, &mut rx, &mut inbox, &mut tx, &mut timing, &mut || refill(&mut out, &mut frame));
            // While the DMA still plays both halves, more of a slice's
            // contouring (whole rows for a short budget a call, so the
            // refill is not late).
            while link.busy() && !out.ready() {
                serve(&mut link, &mut rx, &mut inbox, &mut tx, &mut timing, &mut || {
                    refill(&mut out, &mut frame)
                });
            }
            watchdog.feed();
        }
        let played = frame.stats();
        if played.samples == 0 {
            // Nothing to draw: the beam rests parked for a half buffer.
            if out.pad().is_err() {
                board::fault();
            }
            serve(&mut link, &mut rx, &mut inbox, &mut tx, &mut timing, &mut || {});
            watchdog.feed();
        }
        // The first frame of a new picture counts it: its refresh rate, the
        // redraw event and the status after a volume.
        engine.played(played);
    }
}

#[cfg(feature = "qemu")]
mod qemu {
    //! The end-to-end test's script, run at every frame boundary: record
    //! the boot picture's first frames, then the first received volume's.

    use super::{Report, answer, log_events};
    use crate::board::{self, Streaming};
    use crate::serial::Tx;
    use crate::{clock, serial, stack};
    use isoscope_core::engine::Engine;
    use isoscope_scene::QEMU_FRAMES;

    enum Step {
        /// Recording the boot picture; frames left.
        Boot(usize),
        /// Waiting for a volume from the host.
        Wait,
        /// Playing the received picture once unrecorded: its refill is
        /// the board's work alone (a recorded frame also writes every
        /// sample to the DAC from the CPU), for `scripts/firmware-bench`.
        Unrecorded,
        /// Recording the received picture; frames left.
        Received(usize),
    }

    /// Where the test stands.
    pub struct Script {
        step: Step,
        started: bool,
        boot_volumes: u32,
    }

    impl Script {
        pub fn new(boot_volumes: u32) -> Self {
            let step = if cfg!(feature = "bench") { Step::Wait } else { Step::Boot(QEMU_FRAMES) };
            Self { step, started: false, boot_volumes }
        }

        /// A frame boundary; `redrawn`: the picture changed here.
        pub fn boundary(
            &mut self,
            redrawn: bool,
            engine: &mut Engine<'_>,
            out: &mut Streaming,
            tx: &mut Tx,
            report: &Report,
        ) {
            match self.step {
                Step::Boot(left) if !self.started => {
                    self.started = true;
                    out.record(true);
                    self.step = Step::Boot(left);
                }
                Step::Boot(left) => {
                    if left > 1 {
                        self.step = Step::Boot(left - 1);
                    } else {
                        out.record(false);
                        out.park();
                        defmt::info!(
                            "qemu: recorded {} boot frames; waiting for a volume on USART2",
                            QEMU_FRAMES
                        );
                        self.step = Step::Wait;
                    }
                }
                Step::Wait => {
                    if redrawn && engine.counters().volumes > self.boot_volumes {
                        self.step = Step::Unrecorded;
                    }
                }
                Step::Unrecorded => {
                    out.record(!cfg!(feature = "bench"));
                    self.step = Step::Received(QEMU_FRAMES);
                }
                Step::Received(left) if left > 1 => self.step = Step::Received(left - 1),
                Step::Received(_) => {
                    out.record(false);
                    out.park();
                    // The answers (the status sent once the picture was
                    // drawn) go out before QEMU ends.
                    while engine.split().0.pending() > 0 || tx.pending() > 0 {
                        answer(&mut engine.split().0, tx);
                    }
                    log_events(engine);
                    defmt::info!(
                        "qemu: played {} frames of the received volume at t={} ms; {}; {}; engine {}",
                        QEMU_FRAMES,
                        clock::now_ms(),
                        report.timing,
                        serial::stats(),
                        engine.counters()
                    );
                    defmt::info!("qemu: stack peak {} of {} bytes", stack::peak(), stack::size());
                    board::exit(true);
                }
            }
        }
    }
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    board::fault()
}
