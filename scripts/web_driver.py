#!/usr/bin/env python3
"""The web app in headless Chromium, driven over the DevTools protocol: the
one driver of scripts/web_test.py (the browser test) and scripts/web_bench.py
(the frame-time benchmark).

It serves target/web with `isoscope-sim serve` on a free port and drives
Chromium over the DevTools protocol on a pipe (--remote-debugging-pipe: no
websocket, nothing to install beyond the browser). Standard library only.
"""

import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SITE = ROOT / "target" / "web"
# The name failures are printed under (the calling script's).
PROG = "web"

# The page is up: its first picture is drawn, or it shows an error.
READY = "window.isoscope && (window.isoscope.ready || window.isoscope.error !== null)"


def fail(msg):
    print(f"{PROG}: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def serve(sim):
    """`isoscope-sim serve` on a free port; its process and the page's address."""
    proc = subprocess.Popen([sim, "serve", "--dir", str(SITE), "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    first = proc.stdout.readline().strip()
    if not first.startswith("http://"):
        proc.kill()
        fail(f"isoscope-sim serve printed {first!r}, not its address")
    return proc, first.split("?")[0] + "index.html"


class Browser:
    """Chromium with the DevTools protocol on fds 3 (in) and 4 (out)."""

    def __init__(self, exe, profile):
        to_child_r, self.to_child = os.pipe()
        self.from_child, from_child_w = os.pipe()
        args = [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions",
                "--force-color-profile=srgb", "--remote-debugging-pipe", f"--user-data-dir={profile}",
                "about:blank"]

        def fds():
            os.dup2(to_child_r, 3)
            os.dup2(from_child_w, 4)

        self.proc = subprocess.Popen(args, pass_fds=(3, 4), preexec_fn=fds, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self.buf = b""
        self.next_id = 0
        self.session = None

    def send(self, method, params=None, session=True, timeout=60):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        os.write(self.to_child, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" not in self.buf:
                if time.monotonic() > deadline:
                    fail(f"no answer to {method} within {timeout} s")
                chunk = os.read(self.from_child, 1 << 20)
                if not chunk:
                    fail(f"Chromium closed the pipe during {method}")
                self.buf += chunk
            line, self.buf = self.buf.split(b"\0", 1)
            reply = json.loads(line)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    fail(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def attach(self):
        target = self.send("Target.createTarget", {"url": "about:blank"}, session=False)["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 session=False)["sessionId"]

    def eval(self, expr, timeout=60):
        r = self.send("Runtime.evaluate", {"expression": expr, "returnByValue": True, "awaitPromise": True},
                      timeout=timeout)
        if "exceptionDetails" in r:
            fail(f"{expr}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def wait(self, expr, what, timeout=60):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.eval(expr):
                return
            time.sleep(0.05)
        fail(f"timed out waiting for {what}")

    def close(self):
        try:
            self.send("Browser.close", session=False, timeout=10)
        except SystemExit:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


@contextlib.contextmanager
def session(sim):
    """The page served and a fresh headless Chromium attached to a tab:
    (browser, the page's address, a temporary folder), all gone after."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if not exe:
        fail("no chromium on PATH (scripts/web-test installs it)")
    if not (SITE / "index.html").exists():
        fail(f"{SITE} holds no page: run scripts/web-build")
    server, base = serve(sim)
    try:
        with tempfile.TemporaryDirectory(prefix="isoscope-web-") as tmpdir:
            tmp = Path(tmpdir)
            b = Browser(exe, tmp / "profile")
            try:
                b.attach()
                yield b, base, tmp
            finally:
                b.close()
    finally:
        server.kill()
        server.wait()


def open_file(b, base, path, query=""):
    """A fresh page (with `query`), then `path` through its file input (as a
    user picks it)."""
    b.send("Page.navigate", {"url": f"{base}?{query}"})
    b.wait(READY, "the page to show its first demo")
    b.send("DOM.enable")
    root = b.send("DOM.getDocument")["root"]["nodeId"]
    node = b.send("DOM.querySelector", {"nodeId": root, "selector": "#file"})["nodeId"]
    b.send("DOM.setFileInputFiles", {"nodeId": node, "files": [str(path)]})


def click(b, element_id):
    """A real mouse click (pressed and released) in the middle of the
    element, scrolled into view first."""
    b.eval(f"document.getElementById({json.dumps(element_id)}).scrollIntoView()")
    r = b.eval(f"(() => {{ const r = document.getElementById({json.dumps(element_id)}).getBoundingClientRect(); "
               "return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    x, y = round(r[0]), round(r[1])
    mouse = {"button": "left", "buttons": 1, "clickCount": 1}
    b.send("Input.dispatchMouseEvent", {"type": "mousePressed", "x": x, "y": y, **mouse})
    b.send("Input.dispatchMouseEvent", {"type": "mouseReleased", "x": x, "y": y, **mouse})
