#!/usr/bin/env python3
"""The page's board over Web Serial, tested against the virtual board.

Used by scripts/web_test.py. The page's navigator.serial is replaced (before
any of the page's scripts run: Page.addScriptToEvaluateOnNewDocument) by a
double whose port's streams are bridged, over HTTP to a small server here,
to a TCP connection to a real `isoscope-sim device --tcp` (optionally
through `isoscope-sim relay`, which damages the line). The page connects
and sends its volume with its own sender (the command line's, in wasm); the
board writes the frame's samples once it shows the volume, and they must be
`isoscope-sim render --samples`'s for the same scene, sample for sample.

The bridge: POST /open (a new connection to the board), POST /write (the
body's bytes to the board), GET /read (the board's bytes, waiting up to
READ_WAIT_S for some; 410 once the board closed), POST /close. Standard
library only.
"""

import json
import socket
import subprocess
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from web_driver import click, fail, open_file

READ_WAIT_S = 0.25

# The double: a port whose readable stream long-polls /read and whose
# writable stream posts to /write. BRIDGE is replaced by the bridge's
# address.
DOUBLE = r"""(() => {
  const BRIDGE = '%BRIDGE%';
  class Port extends EventTarget {
    async open({ baudRate }) {
      const r = await fetch(BRIDGE + '/open', { method: 'POST', body: String(baudRate) });
      if (!r.ok) throw new Error('the test bridge could not reach the board');
      let closed = false;
      this.stop = () => { closed = true; };
      this.readable = new ReadableStream({
        async pull(c) {
          for (;;) {
            if (closed) return c.close();
            const r = await fetch(BRIDGE + '/read', { cache: 'no-store' });
            if (r.status === 410) return c.close();
            const b = new Uint8Array(await r.arrayBuffer());
            if (b.length) return c.enqueue(b);
          }
        },
        cancel() { closed = true; },
      });
      this.writable = new WritableStream({
        async write(chunk) { await fetch(BRIDGE + '/write', { method: 'POST', body: chunk }); },
      });
    }
    async close() {
      this.stop();
      await fetch(BRIDGE + '/close', { method: 'POST' });
    }
    getInfo() { return {}; }
  }
  const serial = new EventTarget();
  serial.requestPort = async () => new Port();
  serial.getPorts = async () => [];
  Object.defineProperty(Navigator.prototype, 'serial', { get: () => serial, configurable: true });
})();"""


class Bridge:
    """The HTTP end the double talks to, and a TCP connection to the board."""

    def __init__(self):
        self.board = None  # the board's address, set per test
        self.sock = None
        self.buf = bytearray()
        self.eof = False
        self.cond = threading.Condition()
        self.written = 0
        bridge = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def reply(self, code, body=b""):
                self.send_response(code)
                self.send_header("Access-Control-Allow-Origin", "*")
                self.send_header("Access-Control-Allow-Methods", "GET, POST, OPTIONS")
                self.send_header("Access-Control-Allow-Headers", "*")
                self.send_header("Content-Type", "application/octet-stream")
                # Never from the cache: a 410 is cacheable by default.
                self.send_header("Cache-Control", "no-store")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def do_OPTIONS(self):
                self.reply(204)

            def do_GET(self):
                if self.path != "/read":
                    return self.reply(404)
                code, body = bridge.read()
                self.reply(code, body)

            def do_POST(self):
                body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
                if self.path == "/open":
                    self.reply(200 if bridge.open() else 502)
                elif self.path == "/write":
                    self.reply(200 if bridge.write(body) else 410)
                elif self.path == "/close":
                    bridge.close()
                    self.reply(200)
                else:
                    self.reply(404)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"

    def open(self):
        self.close()
        host, port = self.board.rsplit(":", 1)
        try:
            sock = socket.create_connection((host, int(port)), timeout=10)
        except OSError:
            return False
        sock.settimeout(None)
        with self.cond:
            self.sock, self.buf, self.eof = sock, bytearray(), False
        threading.Thread(target=self.pump, args=(sock,), daemon=True).start()
        return True

    def pump(self, sock):
        while True:
            try:
                data = sock.recv(65536)
            except OSError:
                data = b""
            with self.cond:
                if sock is not self.sock:
                    return
                if not data:
                    self.eof = True
                else:
                    self.buf += data
                self.cond.notify_all()
            if not data:
                return

    def read(self):
        with self.cond:
            self.cond.wait_for(lambda: self.buf or self.eof or self.sock is None, timeout=READ_WAIT_S)
            if not self.buf and (self.eof or self.sock is None):
                return 410, b""
            data, self.buf = bytes(self.buf), bytearray()
            return 200, data

    def write(self, data):
        sock = self.sock
        if sock is None:
            return False
        try:
            sock.sendall(data)
        except OSError:
            return False
        self.written += len(data)
        return True

    def close(self):
        with self.cond:
            sock, self.sock = self.sock, None
            self.cond.notify_all()
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass

    def stop(self):
        self.close()
        self.server.shutdown()


def spawn_first_line(args):
    """A process and the first line it prints (an address)."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    first = proc.stdout.readline().strip()
    if not first:
        proc.kill()
        fail(f"{args[1]} printed no address")
    return proc, first


def install(b, bridge):
    """The double in every page loaded from now on."""
    b.send("Page.enable")
    b.send("Page.addScriptToEvaluateOnNewDocument", {"source": DOUBLE.replace("%BRIDGE%", bridge.url)})


def send_from_page(b, base, sim, tmp, bridge, name, query, relay=None, file=None, timeout=120):
    """Load the page with `query` (and `file` through its file input), connect to a new f407 virtual board
    (through `isoscope-sim relay` with the `relay` flags, if any), send the
    page's volume; the page's link state when done, what it sent (JSON),
    and the board's samples."""
    samples = tmp / f"board-{name}.txt"
    device, addr = spawn_first_line([sim, "device", "--tcp", "127.0.0.1:0", "--board", "f407", "--baud", "0",
                                     "--exit-after", "1", "--samples", str(samples)])
    procs = [device]
    try:
        if relay is not None:
            r, addr = spawn_first_line([sim, "relay", "--to", addr, *relay])
            procs.append(r)
        bridge.board = addr
        # A fresh page (not the last one, before the navigation commits):
        # its link has no state yet.
        fresh = ("window.isoscope && window.isoscope.ready && !window.isoscope.pending() && "
                 "window.isoscope.serial && window.isoscope.serial.state === null")
        if file is None:
            b.send("Page.navigate", {"url": f"{base}?{query}"})
        else:
            open_file(b, base, file, query)
            fresh += (f" && (() => {{ const i = window.isoscope.info(); return i && i.name === "
                      f"{json.dumps(file.name)} && window.isoscope.frames >= 2; }})()")
        b.wait(fresh, f"{name}: the page to show its volume", timeout=60)
        click(b, "serial-connect")
        b.wait("(() => { const s = window.isoscope.serial; return s.error !== null || "
               "(s.state && s.state.state === 'connected'); })()", f"{name}: the board's hello", timeout=30)
        click(b, "serial-send")
        b.wait("(() => { const s = window.isoscope.serial; return s.error !== null || "
               "(s.state && s.state.state === 'done'); })()", f"{name}: the volume sent", timeout=timeout)
        serial = b.eval("window.isoscope.serial")
        if serial["error"]:
            fail(f"{name}: the page's send failed: {serial['error']}")
        try:
            device.wait(timeout=60)
        except subprocess.TimeoutExpired:
            fail(f"{name}: the board did not show the volume")
        shown = b.eval("document.getElementById('serial-status').textContent")
        return serial, shown, samples.read_text()
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()


def check_no_answer(b, base, sim, bridge):
    """A line that loses every byte: the page greets the board three times
    and then shows send's error."""
    device, addr = spawn_first_line([sim, "device", "--tcp", "127.0.0.1:0", "--baud", "0"])
    relay, addr = spawn_first_line([sim, "relay", "--to", addr, "--drop", "1"])
    try:
        bridge.board = addr
        b.send("Page.navigate", {"url": f"{base}?demo=sphere:8&size=64"})
        b.wait("window.isoscope && window.isoscope.ready && window.isoscope.serial && "
               "window.isoscope.serial.state === null", "the page for a silent board")
        click(b, "serial-connect")
        b.wait("window.isoscope.serial.error !== null", "the page to give up on a silent board", timeout=30)
        shown = b.eval("document.getElementById('error').hidden ? '' : "
                       "document.getElementById('error').textContent")
        if "no answer from the board" not in shown:
            fail(f"a silent board's error is not shown clearly: {shown!r}")
        print(f"web-test: a board behind a line that loses every byte: the page shows: {shown}")
    finally:
        for p in (relay, device):
            p.kill()
            p.wait()


def check(b, base, sim, tmp, render, data):
    """The page's sender against the virtual board: a demo on a clean line
    and on a line that loses frames, and a real file if `data` has one."""
    bridge = Bridge()
    try:
        install(b, bridge)
        cases = [
            ("hydrogen 16^3", "demo=hydrogen:16&level=0.05&yaw=-40&pitch=35&size=128",
             ["--demo", "hydrogen:16", "--level", "0.05", "--yaw", "-40", "--pitch", "35"], None),
            # The 2nd, 5th and 9th frames towards the board lost (the hello
            # among them): each is sent again.
            ("torus 20^3, two planes, frames lost", "demo=torus:20&level=0.3&axes=xy,yz&size=128",
             ["--demo", "torus:20", "--level", "0.3", "--axes", "xy,yz"],
             ["--lose-frame", "1", "--lose-frame", "4", "--lose-frame", "8"]),
            # One bit in a thousand flipped, both ways (docs/link.md's
            # noisiest line that 1 KiB chunks still carry).
            ("gyroid 16^3, a noisy line", "demo=gyroid:16&size=128",
             ["--demo", "gyroid:16"], ["--flip", "1e-3", "--seed", "7"]),
        ]
        cases = [(name, query, flags, relay, None) for name, query, flags, relay in cases]
        head = data / "brainsmall.den" if data is not None else None
        if head is not None and head.exists():
            # The MRI head through the page's file input, on the board
            # preset: fitted to the f407 as `send --board f407` fits it.
            cases.append(("brainsmall.den on the f407 preset", "every=6&axes=xy,yz&board=f407&size=128",
                          [str(head), "--axes", "xy,yz"], None, head))
        else:
            print("web-test: note: no brainsmall.den in the data folder; a real file is not sent over Web Serial")
        for name, query, flags, relay, file in cases:
            serial, shown, board = send_from_page(b, base, sim, tmp, bridge, name, query, relay, file)
            state, sent = serial["state"], serial["sent"]
            p = state["progress"]
            if p["bytes_acked"] != p["bytes"] or "board_state=Showing" not in (state["report"] or ""):
                fail(f"{name}: the page's sender did not finish: {json.dumps(state)}")
            if relay and p["retransmitted"] == 0:
                fail(f"{name}: frames were lost on the line but none was sent again: {json.dumps(state)}")
            if "Showing" not in shown or "bytes acknowledged (100%)" not in shown:
                fail(f"{name}: the page does not show the board's status: {shown!r}")
            want, _ = render(sim, [*flags, "--board", "f407", "--every", str(sent["every"])], tmp,
                             f"serial-{name.split()[0]}")
            if board != want:
                g, w = board.splitlines(), want.splitlines()
                first = next((i for i, (x, y) in enumerate(zip(g, w)) if x != y), min(len(g), len(w)))
                fail(f"{name}: the board's {len(g)} samples differ from render's {len(w)} from sample {first}")
            print(f"web-test: {name}: the page sent {sent['dims']} {sent['dtype']} over Web Serial "
                  f"({p['bytes']} bytes, {p['frames']} frames, {p['retransmitted']} sent again, "
                  f"{p['timeouts']} timeouts); the board's {board.count(chr(10))} samples equal "
                  f"render --samples, sample for sample")
        check_no_answer(b, base, sim, bridge)
    finally:
        bridge.stop()
