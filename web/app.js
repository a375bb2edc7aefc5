// The page: controls around the wasm Scope (web/src/lib.rs), which reads
// the volume, builds the frame through isoscope's one picture pipeline and
// draws it on the simulated phosphor. This file only moves values between
// the controls and the Scope, and pixels onto the canvas.
//
// URL parameters (all optional): demo=NAME:N, level=L[,L...], yaw, pitch,
// zoom (0.1 to 1), axes=xy,xz,yz, every=N (0: auto), board=f407, spin=1,
// size=PIXELS. Tests read window.isoscope (see docs/web.md).

import init, { Scope } from './isoscope_web.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const DEFAULT_VIEW = { yaw: 30, pitch: 20, zoom: 0.9 };
const SPIN_DEG_PER_S = 20;

const view = { ...DEFAULT_VIEW };
let scope = null;
let info = null;
let dirty = false;
let spinning = false;

// What a test (or the console) reads: whether the first picture is up,
// the last error, and the frame's samples as `render --samples` writes them.
const api = {
  ready: false,
  error: null,
  frames: 0,
  samples: () => (scope ? scope.samples_text() : ''),
  stats: () => (scope ? JSON.parse(scope.stats()) : null),
  info: () => info,
  view: () => ({ ...view }),
  pending: () => dirty,
};
window.isoscope = api;

function message(e) {
  if (e instanceof WebAssembly.RuntimeError) {
    // A trap: out of memory (a volume too large for the page) or a bug.
    return `the page's wasm module stopped (${e.message}): most likely out of memory; reload the page`;
  }
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

// Give the Scope every setting of the controls.
function applySettings() {
  scope.set_view(view.yaw, view.pitch, view.zoom);
  scope.set_planes(planesValue());
  scope.set_every(Number.parseInt($('every').value, 10) || 0);
  scope.set_board($('board').checked ? 'f407' : '');
}

// Build and draw the frame if anything changed.
function redraw() {
  if (!scope || !dirty) return;
  dirty = false;
  try {
    applySettings();
    if (scope.update()) {
      const size = scope.size();
      const rgba = new Uint8ClampedArray(scope.pixels().buffer);
      $('screen').getContext('2d').putImageData(new ImageData(rgba, size, size), 0, 0);
      api.frames += 1;
      showStats();
    }
    clearError();
    api.ready = true;
  } catch (e) {
    showError(e);
  }
}

const fmt = (n) => Number(n).toLocaleString('en');

function showStats() {
  const s = JSON.parse(scope.stats());
  if (!s) return;
  const lit = s.samples ? Math.round((100 * s.lit_samples) / s.samples) : 0;
  const rate = s.sample_rate_hz >= 1e6 ? `${s.sample_rate_hz / 1e6} MS/s` : `${s.sample_rate_hz / 1e3} kS/s`;
  const lines = [
    `${fmt(s.points)} points, ${fmt(s.polylines)} polylines · ${fmt(s.samples)} samples (${lit}% lit)`,
    `blanked travel ${(100 * s.blank_ratio).toFixed(1)}% of lit · refresh ${s.fps.toFixed(1)} Hz at ${rate}`,
    `${s.board === 'host' ? 'host memory' : `${s.board} board`} · every ${s.every} · ` +
      `built in ${s.build_ms.toFixed(0)} ms, drawn in ${s.draw_ms.toFixed(0)} ms`,
    ...s.remarks,
  ];
  $('stats').textContent = lines.join('\n');
}

// The level slider over the volume's histogram, suggested levels marked.
function showVolume() {
  info = JSON.parse(scope.info());
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
  showLevel(info.default_levels);
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

function setLevels(levels) {
  scope.set_levels(Float32Array.from(levels));
  $('level').value = levels[0];
  showLevel(levels);
  changed();
}

function loaded() {
  showVolume();
  clearError();
  changed();
}

function loadDemo(spec) {
  try {
    scope.load_demo(spec);
    $('demo').value = spec;
    loaded();
  } catch (e) {
    showError(e);
  }
}

async function loadFile(file) {
  $('stats').textContent = `reading ${file.name}…`;
  try {
    const bytes = new Uint8Array(await file.arrayBuffer());
    scope.load_file(file.name, bytes);
    $('demo').value = '';
    loaded();
  } catch (e) {
    showError(e);
  }
}

function wireControls() {
  const canvas = $('screen');
  let drag = null;
  canvas.addEventListener('pointerdown', (e) => {
    drag = { x: e.clientX, y: e.clientY };
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
  for (const id of ['plane-xy', 'plane-xz', 'plane-yz', 'every', 'board']) {
    $(id).addEventListener('change', changed);
  }
  $('spin').addEventListener('change', (e) => {
    spinning = e.target.checked;
  });
  $('reset').addEventListener('click', () => {
    Object.assign(view, DEFAULT_VIEW);
    changed();
  });
}

let last = null;
function tick(t) {
  if (spinning && last !== null) {
    view.yaw = ((view.yaw + (SPIN_DEG_PER_S * (t - last)) / 1000 + 180) % 360) - 180;
    changed();
  }
  last = t;
  redraw();
  requestAnimationFrame(tick);
}

async function main() {
  await init();
  const size = Math.round(Math.max(64, Math.min(2048, param('size', 640))));
  $('screen').width = size;
  $('screen').height = size;
  scope = new Scope(size);
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
  loadDemo(params.get('demo') ?? 'hydrogen:32');
  if (params.has('level')) {
    setLevels(params.get('level').split(',').map(Number.parseFloat));
  }
  redraw();
  requestAnimationFrame(tick);
}

main().catch(showError);
