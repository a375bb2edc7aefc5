// The page: controls around the wasm Scope (web/src/lib.rs), which reads
// the volume and builds the frame through isoscope's one picture pipeline,
// and the wasm Painter, which draws it on the simulated phosphor. Each
// lives in a worker (worker.js), so that long work never holds up the page
// and a frame is drawn while the next is built; this file only moves
// values between the controls and the workers, pixels onto the canvas, and
// the workers' exports into downloads.
//
// URL parameters (all optional): demo=NAME:N, level=L[,L...], yaw, pitch,
// zoom (0.1 to 1), axes=xy,xz,yz, every=N (0: auto), board=f407, spin=1,
// size=PIXELS. Tests read window.isoscope (see docs/web.md).

import { setupSerial } from './serial.js';
import { setupAudio } from './audio.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const DEFAULT_VIEW = { yaw: 30, pitch: 20, zoom: 0.9 };
const SPIN_DEG_PER_S = 20;
// Painters of a band each (see `painters`): one for each core beyond the
// two the page's thread and the scope's worker keep busy, at least one.
// (On two cores two painters were no faster than one: 35 against 32 to 39
// frames a second turning hydrogen 32^3, docs/web.md.)
const PAINTERS_DEFAULT = Math.min(4, Math.max(1, (navigator.hardwareConcurrency || 2) - 2));
// Work shown with its progress once it has run this long.
const BUSY_AFTER_MS = 300;
// A change of settings is first drawn as a draft (a quarter of the slices,
// lib.rs's Scope::draft) when the last frame took this long to build, so
// that a slider dragged across a large volume answers at once; the frame
// itself follows when the settings rest.
const DRAFT_AFTER_MS = 100;

const view = { ...DEFAULT_VIEW };
let levels = [];
let info = null;
let stats = null;
// A setting changed since the last frame asked for; a frame is being
// built; a volume is loading.
let dirty = false;
let building = false;
let loading = false;
// Frames handed to the painter and not yet on the canvas.
let painting = 0;
// Milliseconds the last frame (not a draft) of this volume took to build.
let lastBuildMs = 0;
let spinning = false;
// The mouse turns the view (a drag on the picture).
let dragging = false;

// What a test (or the console) reads: whether the first picture is up,
// the last error, the frame's samples as `render --samples` writes them (a
// promise: the worker has them), and whether a redraw is due or under way.
const api = {
  ready: false,
  error: null,
  frames: 0,
  // Milliseconds from asking the worker for the last frame to its pixels
  // on the canvas.
  frameMs: null,
  // Called after each frame is on the canvas with its stats (for
  // scripts/web_bench.py).
  onframe: null,
  samples: () => call('samples'),
  stats: () => stats,
  info: () => info,
  view: () => ({ ...view }),
  pending: () => dirty || building || loading || painting > 0,
};
window.isoscope = api;
// The picture as XY audio (audio.js).
const audio = setupAudio(call, api);

// Two workers on the same module (worker.js): the scope, which reads the
// volume and builds each frame, and the painter, which draws the frames
// the scope built, so that the next frame is built while the last one is
// drawn. The requests neither has answered, oldest first.
const worker = new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
// The painters: each draws a band of the picture's rows from the same
// samples (render's bytes together: `?painters=N`, 1 to 4, PAINTERS_DEFAULT
// unless said), so that a frame is drawn on as many cores.
const painters = Array.from(
  { length: Math.round(Math.min(4, Math.max(1, param('painters', PAINTERS_DEFAULT)))) },
  () => new Worker(new URL('./worker.js', import.meta.url), { type: 'module' }),
);
const waiting = new Map();
let nextId = 0;
let progress = null;

// Ask `to` (the scope's worker unless said) to do `op`; a promise of its
// answer.
function ask(to, op, args = {}, transfer = []) {
  const id = ++nextId;
  return new Promise((resolve, reject) => {
    waiting.set(id, { resolve, reject, start: performance.now() });
    to.postMessage({ id, op, ...args }, transfer);
  });
}
// (Declarations, not constants: `setupAudio` above is handed `call`.)
function call(op, args, transfer) {
  return ask(worker, op, args, transfer);
}
// A frame's samples to every painter: the parts of its picture.
function paint(samples, clear) {
  return Promise.all(
    painters.map((p, k) => {
      const s = k === painters.length - 1 ? samples : samples.slice();
      return ask(p, 'paint', { samples: s, clear }, [s.buffer]);
    }),
  );
}

// The picture as render's PNG: the painter's, or the bands' RGB joined.
async function picturePng() {
  if (painters.length === 1) return ask(painters[0], 'png');
  const parts = await Promise.all(painters.map((p) => ask(p, 'rgb')));
  const rgb = new Uint8Array(parts.reduce((n, a) => n + a.length, 0));
  parts.reduce((at, a) => (rgb.set(a, at), at + a.length), 0);
  return ask(painters[0], 'pngOf', { size: $('screen').width, rgb }, [rgb.buffer]);
}

const named = painters.map((p, k) => [p, painters.length > 1 ? `painter ${k + 1}` : 'painter']);
for (const [w, name] of [[worker, 'worker'], ...named]) {
  w.onmessage = (e) => {
    const m = e.data;
    if (m.progress) {
      progress = m.progress;
      return;
    }
    const r = waiting.get(m.id);
    if (!r) return;
    waiting.delete(m.id);
    if (progress && progress.id === m.id) progress = null;
    if (m.ok) r.resolve(m.value);
    else r.reject(new Error(m.error));
  };
  w.onerror = (e) => {
    e.preventDefault();
    const err = new Error(`the page's ${name} failed: ${e.message || 'it could not start'}`);
    for (const r of waiting.values()) r.reject(err);
    waiting.clear();
    showError(err);
  };
}

// The oldest request's progress, once it has run BUSY_AFTER_MS.
function showBusy(now) {
  const first = waiting.entries().next().value;
  const busy = $('busy');
  if (!first || now - first[1].start < BUSY_AFTER_MS) {
    busy.hidden = true;
    return;
  }
  const [id, w] = first;
  const p = progress && progress.id === id ? progress : null;
  const bar = $('busy-bar');
  const seconds = ((now - w.start) / 1000).toFixed(1);
  if (p && p.total > 0) {
    bar.value = Math.min(p.done / p.total, 1);
    $('busy-label').textContent = `${p.label}: ${Math.min(100, Math.round((100 * p.done) / p.total))}% (${seconds} s)`;
  } else {
    bar.removeAttribute('value');
    $('busy-label').textContent = `${p ? p.label : 'working'}… (${seconds} s)`;
  }
  busy.hidden = false;
}

function message(e) {
  return String(e && e.message !== undefined ? e.message : e);
}

function showError(e) {
  api.error = message(e);
  $('error').textContent = api.error;
  $('error').hidden = false;
}

function clearError() {
  $('error').hidden = true;
}

// A number from the URL, or the fallback.
function param(name, fallback) {
  const v = Number.parseFloat(params.get(name) ?? '');
  return Number.isFinite(v) ? v : fallback;
}

function changed() {
  dirty = true;
}

function planesValue() {
  return ['xy', 'xz', 'yz'].filter((p) => $(`plane-${p}`).checked).join(',');
}

// Every setting of the controls, as the worker's `frame` takes them.
function settings() {
  return {
    levels,
    yaw: view.yaw,
    pitch: view.pitch,
    zoom: view.zoom,
    planes: planesValue(),
    every: Number.parseInt($('every').value, 10) || 0,
    board: $('board').checked ? 'f407' : '',
    persistence: $('persistence').checked,
    // While the view turns, frames turn the board's picture (SetView);
    // when it stops, the still is built again exactly (Scope.set_turning).
    turning: spinning || dragging,
  };
}

// Turn the view by the spin since it was last turned (`t`: the page's
// clock in ms).
let last = null;
function spin(t) {
  if (spinning && last !== null) {
    view.yaw = ((view.yaw + (SPIN_DEG_PER_S * (t - last)) / 1000 + 180) % 360) - 180;
    changed();
  }
  last = t;
}

// Ask for the frame if anything changed, one frame at a time: changes made
// while one is built go into the next, which is asked for as soon as this
// one is built (not at the next animation frame) while the painter draws
// this one; at most two frames wait for the painter.
async function redraw() {
  if (!dirty || building || loading || painting > 1) return;
  dirty = false;
  building = true;
  const t0 = performance.now();
  try {
    const frame = await call('frame', { settings: settings(), draft: lastBuildMs >= DRAFT_AFTER_MS });
    if (frame) {
      const built = JSON.parse(frame.stats);
      show(frame, built, t0);
      // After a draft the frame itself is owed (the next request builds
      // it if the settings have not moved on meanwhile, else a new draft).
      if (frame.draft) dirty = true;
      else lastBuildMs = built.build_ms;
    } else if (painting === 0) api.ready = true;
    clearError();
  } catch (e) {
    showError(e);
  } finally {
    building = false;
  }
  spin(performance.now());
  // (A hidden page waits for the animation frames, which stop.)
  if (dirty && !document.hidden) redraw();
}

// Hand a built frame (its stats parsed: `built`) to the painter; its
// picture onto the canvas when drawn (frames are drawn in the order built).
function show(frame, built, t0) {
  painting += 1;
  paint(frame.samples, frame.clear)
    .then((parts) => {
      const screen = $('screen').getContext('2d');
      for (const p of parts) {
        const rgba = new Uint8ClampedArray(p.pixels.buffer);
        const rows = rgba.length / (4 * p.size);
        if (rows > 0) screen.putImageData(new ImageData(rgba, p.size, rows), 0, p.first);
      }
      const slowest = (key) => Math.max(...parts.map((p) => p[key]));
      stats = { ...built, draw_ms: slowest('drawMs'), pixels_ms: slowest('pixelsMs') };
      api.frameMs = performance.now() - t0;
      api.frames += 1;
      api.ready = true;
      // The sound is the frame's, not a draft's.
      if (!frame.draft) audio.update();
      showStats();
      if (api.onframe) api.onframe(stats, api.frameMs);
    })
    .catch(showError)
    .finally(() => {
      painting -= 1;
      if (dirty && !document.hidden) redraw();
    });
}

const fmt = (n) => Number(n).toLocaleString('en');

function showStats() {
  const s = stats;
  if (!s) return;
  const lit = s.samples ? Math.round((100 * s.lit_samples) / s.samples) : 0;
  const rate = s.sample_rate_hz >= 1e6 ? `${s.sample_rate_hz / 1e6} MS/s` : `${s.sample_rate_hz / 1e3} kS/s`;
  const lines = [
    `${fmt(s.points)} points, ${fmt(s.polylines)} polylines · ${fmt(s.samples)} samples (${lit}% lit)`,
    `blanked travel ${(100 * s.blank_ratio).toFixed(1)}% of lit · refresh ${s.fps.toFixed(1)} Hz at ${rate}`,
    `${s.draft ? 'a draft, the frame follows · ' : ''}` +
      `${s.board === 'host' ? 'host memory' : `${s.board} board`} · every ${s.every} · ` +
      `built in ${s.build_ms.toFixed(0)} ms, drawn in ${(s.draw_ms + s.pixels_ms).toFixed(0)} ms, ` +
      `on the screen after ${api.frameMs.toFixed(0)} ms`,
    ...s.remarks,
  ];
  $('stats').textContent = lines.join('\n');
}

// The level slider over the volume's histogram, suggested levels marked.
function showVolume(json) {
  info = JSON.parse(json);
  $('volume-name').textContent = `${info.name}: ${info.dims.join('×')} ${info.dtype}`;
  const notes = $('notes');
  notes.replaceChildren(...info.notes.map((n) => Object.assign(document.createElement('li'), { textContent: n })));
  const [lo, hi] = info.range ?? [0, 1];
  const slider = $('level');
  slider.min = lo;
  slider.max = hi > lo ? hi : lo + 1;
  slider.value = info.default_levels[0];
  const sugg = $('suggested');
  sugg.replaceChildren(document.createTextNode(info.suggested.length ? 'suggested: ' : ''));
  for (const l of info.suggested) {
    const b = Object.assign(document.createElement('button'), { type: 'button', textContent: l.toPrecision(4) });
    b.addEventListener('click', () => setLevels([l]));
    sugg.append(b, ' ');
  }
  levels = info.default_levels;
  showLevel(levels);
}

function showLevel(levels) {
  $('level-value').textContent = levels.map((l) => Number(l).toPrecision(4)).join(', ');
  drawHistogram(levels);
}

function drawHistogram(levels) {
  const c = $('histogram');
  const g = c.getContext('2d');
  g.clearRect(0, 0, c.width, c.height);
  if (!info || !info.range) return;
  const h = info.histogram;
  const top = Math.log1p(Math.max(...h));
  const w = c.width / h.length;
  g.fillStyle = '#3a6';
  h.forEach((n, i) => {
    const bar = top > 0 ? (Math.log1p(n) / top) * c.height : 0;
    g.fillRect(i * w, c.height - bar, Math.max(w - 0.5, 0.5), bar);
  });
  const [lo, hi] = info.range;
  const x = (v) => ((v - lo) / (hi - lo || 1)) * c.width;
  g.fillStyle = '#fc3';
  for (const l of info.suggested) g.fillRect(x(l) - 1, 0, 2, 8);
  g.fillStyle = '#fff';
  for (const l of levels) g.fillRect(x(l) - 0.5, 0, 1, c.height);
}

function setLevels(ls) {
  levels = ls;
  $('level').value = levels[0];
  showLevel(levels);
  changed();
}

// Load a volume in the worker (`op` with `args`), drawn at `at` if given
// (else its default levels); the page keeps the old one if it fails.
async function load(op, args, at = null) {
  loading = true;
  lastBuildMs = 0;
  try {
    showVolume(await call(op, args));
    if (at) setLevels(at);
    clearError();
    changed();
    return true;
  } catch (e) {
    showError(e);
    return false;
  } finally {
    loading = false;
  }
}

async function loadDemo(spec, at = null) {
  if (await load('demo', { spec }, at)) $('demo').value = spec;
}

async function loadFile(file) {
  if (await load('file', { file })) $('demo').value = '';
}

// The exports: the command line's files of the frame on the screen.
const EXPORTS = {
  png: ['image/png', '.png'],
  samples: ['text/plain', '.samples.txt'],
  svg: ['image/svg+xml', '.svg'],
  wav: ['audio/wav', '.wav'],
};

// A file name for the volume: `hydrogen:32` as hydrogen-32, `head.nii.gz`
// as head.
function baseName() {
  const name = info ? info.name.replace(/\.gz$/i, '').replace(/\.[a-z0-9]+$/i, '') : 'isoscope';
  return name.replace(/[^A-Za-z0-9._-]+/g, '-') || 'isoscope';
}

async function exportFile(kind) {
  const [type, ext] = EXPORTS[kind];
  try {
    // The picture is the painter's; the rest the scope's.
    const data = kind === 'png' ? await picturePng() : await call('export', { kind });
    const url = URL.createObjectURL(new Blob([data], { type }));
    const a = Object.assign(document.createElement('a'), { href: url, download: baseName() + ext });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60_000);
    clearError();
  } catch (e) {
    showError(e);
  }
}

function wireControls() {
  const canvas = $('screen');
  let drag = null;
  canvas.addEventListener('pointerdown', (e) => {
    drag = { x: e.clientX, y: e.clientY };
    dragging = true;
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    view.yaw += (e.clientX - drag.x) * 0.5;
    view.pitch = Math.max(-90, Math.min(90, view.pitch + (e.clientY - drag.y) * 0.5));
    drag = { x: e.clientX, y: e.clientY };
    changed();
  });
  canvas.addEventListener('pointerup', () => {
    drag = null;
    dragging = false;
    changed();
  });
  canvas.addEventListener(
    'wheel',
    (e) => {
      e.preventDefault();
      view.zoom = Math.max(0.1, Math.min(1, view.zoom * Math.exp(-e.deltaY * 0.001)));
      changed();
    },
    { passive: false },
  );
  const scopeBox = $('scope');
  scopeBox.addEventListener('dragover', (e) => {
    e.preventDefault();
    $('drop-hint').hidden = false;
  });
  scopeBox.addEventListener('dragleave', () => {
    $('drop-hint').hidden = true;
  });
  scopeBox.addEventListener('drop', (e) => {
    e.preventDefault();
    $('drop-hint').hidden = true;
    const file = e.dataTransfer.files[0];
    if (file) loadFile(file);
  });
  $('file').addEventListener('change', (e) => {
    const file = e.target.files[0];
    if (file) loadFile(file);
  });
  $('demo').addEventListener('change', (e) => {
    if (e.target.value) loadDemo(e.target.value);
  });
  $('level').addEventListener('input', (e) => setLevels([Number.parseFloat(e.target.value)]));
  for (const id of ['plane-xy', 'plane-xz', 'plane-yz', 'every', 'board', 'persistence']) {
    $(id).addEventListener('change', changed);
  }
  $('spin').addEventListener('change', (e) => {
    spinning = e.target.checked;
    changed();
  });
  $('reset').addEventListener('click', () => {
    Object.assign(view, DEFAULT_VIEW);
    changed();
  });
  for (const kind of Object.keys(EXPORTS)) {
    $(`export-${kind}`).addEventListener('click', () => exportFile(kind));
  }
}

function tick() {
  spin(performance.now());
  redraw();
  showBusy(performance.now());
  requestAnimationFrame(tick);
}

async function main() {
  const size = Math.round(Math.max(64, Math.min(2048, param('size', 640))));
  $('screen').width = size;
  $('screen').height = size;
  requestAnimationFrame(tick);
  const bands = painters.length;
  await Promise.all([
    call('init', { size, paints: false }),
    ...painters.map((p, band) => ask(p, 'paintInit', { size, band, bands })),
  ]);
  view.yaw = param('yaw', view.yaw);
  view.pitch = param('pitch', view.pitch);
  view.zoom = param('zoom', view.zoom);
  const axes = (params.get('axes') ?? 'xy,xz,yz').split(',');
  for (const p of ['xy', 'xz', 'yz']) $(`plane-${p}`).checked = axes.includes(p);
  const every = String(Math.max(0, Math.round(param('every', 0))));
  if (![...$('every').options].some((o) => o.value === every)) $('every').add(new Option(every));
  $('every').value = every;
  $('board').checked = params.get('board') === 'f407';
  spinning = $('spin').checked = params.get('spin') === '1';
  wireControls();
  setupSerial({ call, settings, spinning: () => spinning, showError });
  const at = params.has('level') ? params.get('level').split(',').map(Number.parseFloat) : null;
  await loadDemo(params.get('demo') ?? 'hydrogen:32', at);
}

main().catch(showError);
