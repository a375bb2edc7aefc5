// The page's workers: the wasm Scope (web/src/lib.rs) off the page's
// thread, so that reading a volume and building a frame, which can take
// seconds, never hold up the page; and in a second worker on this module,
// the Painter that draws the frames the Scope built (app.js), while the
// Scope builds the next. app.js sends each requests, one at a time
// in the order sent: { id, op, ...arguments }; it answers each with
// { id, ok: true, value } or { id, ok: false, error }, and while one runs
// sends { progress: { id, label, done, total } } (total 0: a step with no
// count) when the step changes and at most every PROGRESS_MS otherwise.

import init, { Link, Painter, Scope, png_of } from './isoscope_web.js';

const PROGRESS_MS = 100;

let scope = null;
// The picture, in the page's painter worker: it draws the frames another
// worker's Scope built (app.js).
let painter = null;
// The board over Web Serial (web/serial.js moves the port's bytes): the
// command line's sender, on this worker's clock.
let link = null;
// The request running, and what the page was last told of it.
let job = null;

// Called by the Scope during long work (lib.rs's `report`).
self.isoscopeProgress = (label, done, total) => {
  if (!job) return;
  const now = performance.now();
  if (label === job.label && now - job.posted < PROGRESS_MS) return;
  job.label = label;
  job.posted = now;
  self.postMessage({ progress: { id: job.id, label, done, total } });
};

// A request's answer: a value, and the buffers handed over with it.
const answer = (value, transfer = []) => ({ value, transfer });
const bytes = (u8) => answer(u8, [u8.buffer]);

const ops = {
  // A Scope; with `paints` false it only builds, for a painter.
  async init({ size, paints = true }) {
    await init();
    scope = new Scope(size);
    scope.set_drawing(paints);
    return answer(null);
  },
  // A painter of the whole picture, or of band `band` of `bands` (rows
  // split as render splits them on threads).
  async paintInit({ size, band = 0, bands = 1 }) {
    await init();
    painter = bands > 1 ? Painter.band(size, band, bands) : new Painter(size);
    return answer(null);
  },
  // Draw a frame's samples (x, y, beam a sample) on a dark screen or over
  // the last one: its pixels (a band's rows, from row `first`).
  paint({ samples, clear }) {
    painter.paint(samples, clear);
    const t0 = performance.now();
    const pixels = painter.pixels();
    const pixelsMs = performance.now() - t0;
    const [size, first] = [painter.size(), painter.first_row()];
    return answer({ size, first, pixels, drawMs: painter.draw_ms(), pixelsMs }, [pixels.buffer]);
  },
  png() {
    return bytes(painter.png());
  },
  // The band's rows as RGB, and the bands' RGB as render's PNG.
  rgb() {
    return bytes(painter.rgb());
  },
  pngOf({ size, rgb }) {
    return bytes(png_of(size, rgb));
  },
  demo({ spec }) {
    scope.load_demo(spec);
    return answer(scope.info());
  },
  async file({ file }) {
    self.isoscopeProgress('reading the file', 0, 0);
    const data = new Uint8Array(await file.arrayBuffer());
    scope.load_file(file.name, data);
    return answer(scope.info());
  },
  // Apply the page's settings; build the frame if they changed (null if
  // not): its samples for the painter, and whether it is drawn on a dark
  // screen. With `draft`, a draft of it first (lib.rs's Scope::draft)
  // where one can be made and none is drawn yet: `draft` in the answer.
  frame({ settings: s, draft = false }) {
    apply(s);
    const drafted = draft && scope.draft();
    if (!drafted && !scope.update()) return answer(null);
    const samples = scope.frame_samples();
    return answer({ samples, clear: scope.clears(), stats: scope.stats(), draft: drafted }, [samples.buffer]);
  },
  // The board link: greet a board (a new link), move the port's bytes and
  // the time through it (`bytes` read, or `closed`), send the page's
  // volume as `send` would. Each answers what to write and when to wake
  // it (linkIo with nothing), and its state (JSON).
  linkOpen({ baud }) {
    link = new Link(performance.now(), baud);
    return linkStep();
  },
  linkIo({ bytes, closed }) {
    if (!link) throw new Error('no board connected');
    const now = performance.now();
    try {
      if (bytes) link.receive(bytes, now);
      if (closed) link.closed(now);
      link.tick(now);
    } catch (e) {
      // The link has failed for good: its state says why.
      if (e instanceof WebAssembly.RuntimeError) throw e;
    }
    return linkStep();
  },
  linkSend({ settings, spin }) {
    if (!link) throw new Error('no board connected');
    apply(settings);
    const sent = JSON.parse(scope.send_to(link, spin, performance.now()));
    return linkStep(sent);
  },
  samples() {
    return answer(scope.samples_text());
  },
  // The frame for a sound card at `rate` (audio.js): X, Y and beam
  // channels one after the other, and the samples' spacing.
  audio({ rate }) {
    const channels = scope.audio(rate);
    return answer({ channels, step: scope.audio_step() }, [channels.buffer]);
  },
  export({ kind }) {
    switch (kind) {
      case 'png':
        return bytes(scope.png());
      case 'samples':
        return bytes(new TextEncoder().encode(scope.samples_text()));
      case 'svg':
        return bytes(scope.svg());
      case 'wav':
        return bytes(scope.wav());
      default:
        throw new Error(`no export called ${kind}`);
    }
  },
};

function apply(s) {
  scope.set_turning(Boolean(s.turning));
  scope.set_levels(Float32Array.from(s.levels));
  scope.set_view(s.yaw, s.pitch, s.zoom);
  scope.set_planes(s.planes);
  scope.set_every(s.every);
  scope.set_board(s.board);
  scope.set_persistence(s.persistence);
}

// The bytes the link has to write now, the milliseconds until it is to be
// woken (null: it waits for nothing), and its state.
function linkStep(sent = null) {
  const out = link.transmit(performance.now());
  const deadline = link.deadline();
  const wait = deadline === undefined ? null : Math.max(0, deadline - performance.now());
  return answer({ out, wait, state: JSON.parse(link.state()), sent }, [out.buffer]);
}

function message(e) {
  if (e instanceof WebAssembly.RuntimeError) {
    // A trap: out of memory (a volume too large for the page) or a bug.
    return `the page's wasm module stopped (${e.message}): most likely out of memory; reload the page`;
  }
  return String(e && e.message !== undefined ? e.message : e);
}

async function run(req) {
  job = { id: req.id, label: null, posted: 0 };
  try {
    if (!scope && !painter && req.op !== 'init' && req.op !== 'paintInit') {
      throw new Error('the worker has no Scope or Painter yet');
    }
    const op = ops[req.op];
    if (!op) throw new Error(`the worker has no request ${req.op}`);
    const { value, transfer } = await op(req);
    self.postMessage({ id: req.id, ok: true, value }, transfer);
  } catch (e) {
    self.postMessage({ id: req.id, ok: false, error: message(e) });
  } finally {
    job = null;
  }
}

// One request at a time, in order, even across a request's awaits.
let queue = Promise.resolve();
self.onmessage = (e) => {
  queue = queue.then(() => run(e.data));
};
