// The board over Web Serial: "Connect" opens a serial port
// (navigator.serial) and greets the board; "Send to board" sends the
// page's volume with its levels, planes, stride and view as
// `isoscope-sim send` would. The protocol is not here: the worker's Link
// (web/src/lib.rs) is the command line's sender, compiled to wasm. This
// file only moves bytes between the port and the worker, wakes the link at
// the deadline it asks for, and shows its progress and the board's status.
//
// Web Serial is in Chromium-based browsers, in a secure context (https,
// or http://localhost / 127.0.0.1). Tests replace navigator.serial with a
// double (scripts/web_test.py) and read window.isoscope.serial.

const $ = (id) => document.getElementById(id);
const DEFAULT_BAUD = 921600; // isoscope-sim send's --baud
const SPIN_DEG_PER_S = 20; // the page's spin

const fmt = (n) => Number(n).toLocaleString('en');

// `call(op, args)`: a request to the page's worker; `settings()`: the
// page's settings as the worker's `frame` takes them; `spinning()`:
// whether the page spins; `showError(e)`: the page's error line.
export function setupSerial({ call, settings, spinning, showError }) {
  const api = { state: null, sent: null, error: null, sends: 0 };
  window.isoscope.serial = api;
  let port = null;
  let reader = null;
  let writer = null;
  let baud = DEFAULT_BAUD;
  let timer = null;
  // Link requests run one at a time, in order, and their bytes are written
  // in that order.
  let queue = Promise.resolve();
  // Waiting for the board's hello: { resolve, reject }.
  let greeting = null;

  if (!('serial' in navigator)) {
    $('serial-connect').disabled = true;
    $('serial-send').disabled = true;
    $('serial-status').textContent =
      'This browser has no Web Serial: use a Chromium-based browser (Chrome, Edge, Opera) over https or on localhost.';
    return;
  }

  function fail(e) {
    api.error = String(e && e.message !== undefined ? e.message : e);
    showError(e);
  }

  // A link request; its answer applied: bytes written, the wake-up set,
  // the state shown.
  function link(op, args = {}) {
    const p = queue.then(() => call(op, args)).then(step);
    queue = p.catch(() => {});
    return p;
  }

  async function step(r) {
    if (r.out.length && writer) await writer.write(r.out);
    clearTimeout(timer);
    timer = r.wait === null ? null : setTimeout(() => link('linkIo').catch(fail), r.wait);
    if (r.sent) api.sent = r.sent;
    show(r.state);
    return r;
  }

  function show(s) {
    api.state = s;
    const lines = [];
    if (!port) lines.push(s.state === 'done' ? 'the port is closed' : 'not connected');
    if (s.board) {
      const known = s.board.known ? ` (an ${s.board.known} by its capabilities)` : '';
      lines.push(`board${known}: firmware ${s.board.firmware}, slices of up to ${fmt(s.board.slice_bytes)} bytes, ` +
        `${fmt(s.board.points)} points`);
    } else if (s.state === 'greeting') {
      lines.push('saying hello to the board…');
    }
    const p = s.progress;
    if (p.frames > 0) {
      const pct = p.bytes ? Math.round((100 * p.bytes_acked) / p.bytes) : 100;
      lines.push(`${s.state === 'sending' ? 'sending' : 'sent'}: ${fmt(p.bytes_acked)} of ${fmt(p.bytes)} bytes ` +
        `acknowledged (${pct}%), ${fmt(p.frames_acked)} of ${fmt(p.frames)} frames, ` +
        `${fmt(p.retransmitted)} sent again, ${fmt(p.timeouts)} timeouts`);
      $('serial-progress').max = p.frames;
      $('serial-progress').value = p.frames_acked;
      $('serial-progress').hidden = false;
    }
    if (s.state === 'picture') lines.push('waiting for the board to show the picture…');
    if (s.status) {
      lines.push(`the board: ${s.status.state}, ${fmt(s.status.points)} points, refresh ${s.status.refresh_hz} Hz`);
    }
    if (s.report) lines.push(s.report.trim().split('\n').join(' · '));
    if (s.error) lines.push(`error: ${s.error}`);
    $('serial-status').textContent = lines.join('\n');
    $('serial-send').disabled = !port || s.state === 'sending' || s.state === 'picture' || s.state === 'greeting';
    if (greeting && s.state !== 'greeting') {
      const g = greeting;
      greeting = null;
      if (s.state === 'connected') g.resolve();
      else g.reject(new Error(s.error ?? `the board link is ${s.state}`));
    }
    if (s.state === 'failed') fail(new Error(s.error));
  }

  // A new link over the open port: hello, and what the board takes.
  function greet() {
    const hello = new Promise((resolve, reject) => {
      greeting = { resolve, reject };
    });
    link('linkOpen', { baud }).catch(fail);
    return hello;
  }

  async function readLoop(r) {
    try {
      for (;;) {
        const { value, done } = await r.read();
        if (done) break;
        if (value && value.length) link('linkIo', { bytes: value }).catch(fail);
      }
    } catch (e) {
      if (port) fail(new Error(`the serial port failed: ${e.message ?? e}`));
    } finally {
      if (port) await disconnect(true);
    }
  }

  async function connect() {
    if (port) await disconnect(false);
    baud = Number.parseInt($('serial-baud').value, 10) || DEFAULT_BAUD;
    const p = await navigator.serial.requestPort();
    await p.open({ baudRate: baud });
    port = p;
    writer = port.writable.getWriter();
    reader = port.readable.getReader();
    $('serial-connect').textContent = 'Disconnect';
    readLoop(reader);
    await greet();
  }

  // Close the port; `lost`: it went away (the link is told).
  async function disconnect(lost) {
    const p = port;
    port = null;
    clearTimeout(timer);
    $('serial-connect').textContent = 'Connect';
    if (lost) await link('linkIo', { closed: true }).catch(fail);
    try {
      if (reader) await reader.cancel();
    } catch {}
    try {
      if (reader) reader.releaseLock();
      if (writer) writer.releaseLock();
      if (p) await p.close();
    } catch {}
    reader = null;
    writer = null;
    $('serial-send').disabled = true;
  }

  async function send() {
    if (!port) throw new Error('connect to a board first');
    // Each volume after the first gets a new hello.
    if (!api.state || api.state.state !== 'connected') await greet();
    api.sends += 1;
    await link('linkSend', { settings: settings(), spin: spinning() ? SPIN_DEG_PER_S : 0 });
  }

  $('serial-baud').value = String(DEFAULT_BAUD);
  $('serial-send').disabled = true;
  $('serial-connect').addEventListener('click', () => {
    api.error = null;
    (port ? disconnect(false) : connect()).catch(fail);
  });
  $('serial-send').addEventListener('click', () => {
    api.error = null;
    send().catch(fail);
  });
  navigator.serial.addEventListener?.('disconnect', (e) => {
    if (port && e.target === port) fail(new Error('the board was disconnected'));
  });
}
