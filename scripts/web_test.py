#!/usr/bin/env python3
"""The web app in a real browser: headless Chromium against target/web.

Called by scripts/web-test (which builds the page and installs Chromium).
Serves target/web and drives Chromium with scripts/web_driver.py, and for
each scene checks that

- the page's frame (window.isoscope.samples(), `x y beam` a line) equals
  `isoscope-sim render --samples` for the same scene, byte for byte;
- the canvas equals `isoscope-sim render`'s PNG of that scene, and the
  first scene's also the golden tests/golden/hydrogen32.png, within the
  tolerances below;
- the page's exports, downloaded by clicking their buttons, are the command
  line's files of the scene byte for byte: the PNG `render` writes, its
  `--samples` text, `contour --format svg`'s SVG and `wav`'s WAV;
- a large volume loads in the page's worker: the page shows the work's
  progress and its thread never stalls for long meanwhile;
- "play as audio" hands WebAudio the frame `isoscope-sim wav` writes for
  the AudioContext's rate (within 1 LSB of its 16-bit PCM), and a new one
  when the level changes.

Standard library only. Usage: web_test.py SIM_BINARY [DATA_DIR]
"""

import base64
import json
import subprocess
import sys
import time
import wave
import zlib
from pathlib import Path

import web_driver
import web_serial
from web_driver import READY, ROOT, click, fail, open_file

web_driver.PROG = "web-test"
GOLDEN = ROOT / "tests" / "golden" / "hydrogen32.png"
SIZE = 256

# The canvas against render's PNG of the same samples: the page and the
# CLI run the same phosphor code, compiled for wasm32 and for the host,
# whose f32 powf/exp may differ in the last bit (the host's come from the
# system's libm, wasm's from Rust's), so a pixel's tone may land a table
# step away. A channel may differ by at most MAX_CHANNEL_DIFF, and on
# average by at most MEAN_DIFF (of 255); a wrong picture (another view,
# level or beam) differs by tens on thousands of channels.
MAX_CHANNEL_DIFF = 3
MEAN_DIFF = 0.05
# The canvas against the golden picture tests/tests/render.rs keeps (and
# ISOSCOPE_BLESS=1 rewrites there): its rule, a mean difference of at most
# 0.5 and at most 0.1% of the channels off by more than 16, which a
# 20-degree turn fails.
GOLDEN_MEAN = 0.5
GOLDEN_BIG, GOLDEN_BIG_SHARE = 16, 0.001

# (name, page query, render flags): the page's defaults are render's.
SCENES = [
    ("hydrogen 32^3, defaults", "demo=hydrogen:32", ["--demo", "hydrogen:32"]),
    (
        "torus 24^3 on the f407 board, turned, zoomed out, two planes, three painters",
        "demo=torus:24&level=0.3&yaw=-40&pitch=35&zoom=0.75&axes=xy,yz&every=2&board=f407&painters=3",
        ["--demo", "torus:24", "--level", "0.3", "--yaw", "-40", "--pitch", "35", "--margin", "0.125",
         "--axes", "xy,yz", "--every", "2", "--board", "f407"],
    ),
]
# A real volume, opened through the page's file input.
FILE_SCENE = "brainsmall.den"
# A large demo, picked from the page's list: seconds of work in the worker.
LARGE_DEMO = "gyroid:256"
# The longest the page's thread may go without running a 10 ms timer while
# the large demo loads (about 2.4 s of work in the worker on this project's
# machine; a page doing it on its own thread stalls that long).
MAX_STALL_MS = 250


CANVAS = """(() => {
  const c = document.getElementById('screen');
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let s = '';
  for (let i = 0; i < d.length; i += 0x8000) s += String.fromCharCode.apply(null, d.subarray(i, i + 0x8000));
  return [c.width, c.height, btoa(s)];
})()"""


def page_frame(b):
    """The page's samples and canvas (RGB), once its picture is up."""
    err = b.eval("window.isoscope.error")
    if err:
        fail(f"the page shows an error: {err}")
    samples = b.eval("window.isoscope.samples()")
    w, h, data = b.eval(CANVAS)
    rgba = base64.b64decode(data)
    rgb = bytes(x for i, x in enumerate(rgba) if i % 4 != 3)
    return samples, (w, h, rgb)


def read_png(path):
    """An 8-bit RGB or RGBA, non-interlaced PNG as (width, height, RGB bytes)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        fail(f"{path} is not a PNG")
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            w, h = int.from_bytes(body[0:4], "big"), int.from_bytes(body[4:8], "big")
            depth, ctype, interlace = body[8], body[9], body[12]
            if depth != 8 or ctype not in (2, 6) or interlace:
                fail(f"{path}: only 8-bit RGB(A) non-interlaced PNGs are read here")
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
    raw = zlib.decompress(idat)
    stride = w * bpp
    out, prev = bytearray(), bytearray(stride)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line
        prev = line
    rgb = out if bpp == 3 else bytes(x for i, x in enumerate(out) if i % 4 != 3)
    return w, h, bytes(rgb)


def compare(name, got, want, what, golden=False):
    (gw, gh, g), (ww, wh, wpx) = got, want
    if (gw, gh) != (ww, wh):
        fail(f"{name}: the canvas is {gw}x{gh}, {what} {ww}x{wh}")
    diffs = [abs(a - b) for a, b in zip(g, wpx)]
    worst, mean = max(diffs), sum(diffs) / len(diffs)
    big = sum(1 for d in diffs if d > GOLDEN_BIG)
    lit = sum(1 for x in wpx if x > 16)
    print(f"web-test: {name}: canvas vs {what}: max channel diff {worst}, mean {mean:.4f}, "
          f"{big} channels off by more than {GOLDEN_BIG} ({lit} lit channels)")
    if lit < 1000:
        fail(f"{name}: {what} is almost black ({lit} lit channels)")
    if golden:
        if mean > GOLDEN_MEAN or big > GOLDEN_BIG_SHARE * len(diffs):
            fail(f"{name}: the canvas differs from {what} beyond the golden tolerance")
    elif worst > MAX_CHANNEL_DIFF or mean > MEAN_DIFF:
        fail(f"{name}: the canvas differs from {what} (max {worst} > {MAX_CHANNEL_DIFF} or mean {mean:.4f} > "
             f"{MEAN_DIFF})")


def render(sim, flags, tmp, tag):
    samples, png = tmp / f"{tag}.txt", tmp / f"{tag}.png"
    subprocess.run([sim, "render", *flags, "--size", str(SIZE), "--samples", str(samples), "-o", str(png)],
                   check=True, stderr=subprocess.DEVNULL)
    return samples.read_text(), read_png(png)


def check_scene(b, name, got, sim_flags, sim, tmp, tag, golden=None):
    samples, canvas = got
    want_samples, want_png = render(sim, sim_flags, tmp, tag)
    n = want_samples.count("\n")
    if samples != want_samples:
        g, w = samples.splitlines(), want_samples.splitlines()
        first = next((i for i, (x, y) in enumerate(zip(g, w)) if x != y), min(len(g), len(w)))
        fail(f"{name}: the page's {len(g)} samples differ from render's {len(w)} from sample {first}")
    print(f"web-test: {name}: {n} samples equal render --samples, sample for sample")
    compare(name, canvas, want_png, "render's PNG")
    if golden is not None:
        compare(name, canvas, read_png(golden), f"the golden {golden.name}", golden=True)


# The exports: button, file name ending, and how the command line makes the
# same file (None: render's PNG or samples, made by check_scene).
EXPORTS = [("png", ".png"), ("samples", ".samples.txt"), ("svg", ".svg"), ("wav", ".wav")]


def download(b, kind, folder, name):
    """Click the page's export button `kind` (a real click) and wait for
    its download, `name` in `folder`."""
    b.send("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(folder)}, session=False)
    click(b, f"export-{kind}")
    path = folder / name
    deadline = time.monotonic() + 60
    while not path.exists():
        err = b.eval("window.isoscope.error")
        if err:
            fail(f"exporting {kind}: the page shows an error: {err}")
        if time.monotonic() > deadline:
            fail(f"no download {name} within 60 s of clicking export-{kind} (in {folder}: "
                 f"{sorted(p.name for p in folder.iterdir()) if folder.exists() else []})")
        time.sleep(0.05)
    return path.read_bytes()


def check_exports(b, name, flags, sim, tmp, tag, stem, svg=True):
    """The page's four exports of the scene against the command line's
    files; `flags` are render's for it (check_scene wrote its PNG and
    samples). `svg`: whether `contour --format svg` draws this scene (it
    has no --board)."""
    every = b.eval("window.isoscope.stats().every")
    want = {"png": (tmp / f"{tag}.png").read_bytes(), "samples": (tmp / f"{tag}.txt").read_bytes()}
    if svg:
        out = tmp / f"{tag}.svg"
        subprocess.run([sim, "contour", "--format", "svg", *flags, "--every", str(every), "-o", str(out)],
                       check=True, stderr=subprocess.DEVNULL)
        want["svg"] = out.read_bytes()
    out = tmp / f"{tag}.wav"
    subprocess.run([sim, "wav", *flags, "-o", str(out)], check=True, stderr=subprocess.DEVNULL)
    want["wav"] = out.read_bytes()
    folder = tmp / f"downloads-{tag}"
    folder.mkdir()
    for kind, ending in EXPORTS:
        if kind not in want:
            continue
        got = download(b, kind, folder, stem + ending)
        if got != want[kind]:
            first = next((i for i, (x, y) in enumerate(zip(got, want[kind])) if x != y),
                         min(len(got), len(want[kind])))
            fail(f"{name}: the page's {kind} export ({len(got)} bytes) differs from the command line's "
                 f"({len(want[kind])} bytes) from byte {first}")
    print(f"web-test: {name}: the {', '.join(k for k, _ in EXPORTS if k in want)} exports equal the command "
          f"line's files, byte for byte ({', '.join(f'{len(v)}' for v in want.values())} bytes)")


def drag(b):
    """Drag on the screen: 40 px right and 20 down, yaw and pitch +20 and +10
    degrees at half a degree a pixel."""
    box = b.eval("(() => { const c = document.getElementById('screen'); c.scrollIntoView({ block: 'center' }); "
                 "const r = c.getBoundingClientRect(); "
                 "return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    x, y = round(box[0]), round(box[1])
    mouse = {"button": "left", "buttons": 1, "clickCount": 1}
    b.send("Input.dispatchMouseEvent", {"type": "mousePressed", "x": x, "y": y, **mouse})
    for step in range(1, 5):
        b.send("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x + 10 * step, "y": y + 5 * step, **mouse})
    b.send("Input.dispatchMouseEvent", {"type": "mouseReleased", "x": x + 40, "y": y + 20, **mouse})


def check_large(b, sim, tmp):
    """Pick the large demo from the page's list: the page shows the work's
    progress, its thread keeps running, and the frame is render's."""
    b.eval("(() => { window.__stall = { max: 0, last: performance.now() }; setInterval(() => { "
           "const now = performance.now(); window.__stall.max = Math.max(window.__stall.max, now - "
           "window.__stall.last); window.__stall.last = now; }, 10); })()")
    frames = b.eval("window.isoscope.frames")
    t0 = time.monotonic()
    b.eval(f"(() => {{ const s = document.getElementById('demo'); s.value = {json.dumps(LARGE_DEMO)}; "
           "s.dispatchEvent(new Event('change')); })()")
    shown, done = [], (f"(() => {{ const i = window.isoscope.info(); return window.isoscope.error !== null || "
                       f"(i && i.name === {json.dumps(LARGE_DEMO)} && window.isoscope.frames > {frames} && "
                       "!window.isoscope.pending()); })()")
    while not b.eval(done):
        label = b.eval("document.getElementById('busy').hidden ? null : "
                       "document.getElementById('busy-label').textContent")
        if label and label.split(" (")[0] not in shown:
            shown.append(label.split(" (")[0])
        if time.monotonic() - t0 > 120:
            fail(f"{LARGE_DEMO} did not show within 120 s")
        time.sleep(0.03)
    seconds, stall = time.monotonic() - t0, b.eval("window.__stall.max")
    print(f"web-test: {LARGE_DEMO}: shown after {seconds:.1f} s; the page showed {shown}; its thread's longest "
          f"stall {stall:.0f} ms")
    if stall > MAX_STALL_MS:
        fail(f"{LARGE_DEMO}: the page's thread stalled {stall:.0f} ms (more than {MAX_STALL_MS}) while it loaded")
    if not any("%" in s for s in shown):
        fail(f"{LARGE_DEMO}: the page showed no progress with a count while it loaded ({shown})")
    # The page keeps its view from one volume to the next.
    v = b.eval("window.isoscope.view()")
    flags = ["--demo", LARGE_DEMO, "--yaw", str(v["yaw"]), "--pitch", str(v["pitch"]), "--margin",
             str((1 - v["zoom"]) / 2)]
    check_scene(b, f"{LARGE_DEMO} at the page's view", page_frame(b), flags, sim, tmp, "large")
    # A new level on a volume this slow to build shows a draft first (a
    # quarter of the slices), then the frame itself: render's.
    b.eval("(() => { window.__shown = []; window.isoscope.onframe = (s) => window.__shown.push([s.draft, s.every]); "
           "const l = document.getElementById('level'); l.value = '0.25'; l.dispatchEvent(new Event('input')); })()")
    b.wait("window.__shown.length > 0 && !window.isoscope.pending()", f"{LARGE_DEMO} at level 0.25", timeout=120)
    shown = b.eval("window.isoscope.onframe = null, window.__shown")
    every = b.eval("window.isoscope.stats().every")
    if not shown[0][0] or shown[0][1] != 4 * every or shown[-1] != [False, every]:
        fail(f"{LARGE_DEMO}: a new level showed {shown} ([draft, every] a frame), not a draft at every "
             f"{4 * every} and then the frame at every {every}")
    print(f"web-test: {LARGE_DEMO} at level 0.25: a draft at a stride of {4 * every} slices first, then the frame "
          f"at {every}")
    check_scene(b, f"{LARGE_DEMO} at level 0.25", page_frame(b), flags + ["--level", "0.25"], sim, tmp, "large-level")


def check_audio(b, base, sim, tmp):
    """Turn "play as audio" on: the buffer the page hands WebAudio is
    `wav`'s frame at the AudioContext's rate; a new level, a new one."""
    b.send("Page.navigate", {"url": f"{base}?demo=hydrogen:32&size={SIZE}"})
    b.wait(READY, "hydrogen to show for audio")
    click(b, "audio-on")
    for level, flags in [(None, []), ("0.2", ["--level", "0.2"])]:
        if level is not None:
            frames = b.eval("window.isoscope.audio.frames")
            b.eval("(() => { const s = document.getElementById('level'); s.value = '0.2'; "
                   "s.dispatchEvent(new Event('input')); })()")
            b.wait(f"window.isoscope.audio.frames > {frames} && !window.isoscope.pending()",
                   "the audio of the new level", timeout=30)
            # A last request may still be under way for an earlier frame.
            time.sleep(0.2)
            b.wait("!window.isoscope.pending()", "the page to settle")
        else:
            b.wait("window.isoscope.audio.frames > 0 || "
                   "document.getElementById('audio-status').textContent.startsWith('no audio')",
                   "the page to play audio", timeout=30)
        shown = b.eval("document.getElementById('audio-status').textContent")
        if shown.startswith("no audio"):
            fail(f"the page plays no audio: {shown}")
        rate = b.eval("window.isoscope.audio.rate()")
        got = base64.b64decode(b.eval("window.isoscope.audio.pcm()"))
        n = len(got) // 4
        out = tmp / f"audio{len(flags)}.wav"
        done = subprocess.run([sim, "wav", "--demo", "hydrogen:32", *flags, "--audio-rate", str(rate), "--seconds",
                               str(2 * n / rate), "-o", str(out)], check=True, capture_output=True, text=True)
        with wave.open(str(out)) as w:
            want = w.readframes(n)
        g = memoryview(got).cast("h")
        w = memoryview(want).cast("h")
        if len(w) != len(g):
            fail(f"audio: the page's frame is {n} samples, the WAV file's shorter ({len(w) // 2})")
        worst = max(abs(a - c) for a, c in zip(g, w))
        said = next(line for line in done.stderr.splitlines() if "wrote" in line)
        if f"one frame is {n} samples" not in said or worst > 1:
            fail(f"audio{' at level ' + level if level else ''}: the page's {n}-sample frame at {rate} Hz differs "
                 f"from wav's by up to {worst} LSB of 16 bits ({said})")
        print(f"web-test: audio{' at level ' + level if level else ''}: the page plays {n} samples a frame at "
              f"{rate} Hz ({shown}), within {worst} LSB of `wav --audio-rate {rate}`'s 16-bit PCM")
    click(b, "audio-on")
    if b.eval("window.isoscope.audio.playing()"):
        fail("audio: still playing after turning it off")


def main():
    if len(sys.argv) < 2:
        fail("usage: web_test.py SIM_BINARY [DATA_DIR]")
    sim = sys.argv[1]
    data = Path(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[2] else None
    with web_driver.session(sim) as (b, base, tmp):
        for i, (name, query, flags) in enumerate(SCENES):
            b.send("Page.navigate", {"url": f"{base}?{query}&size={SIZE}"})
            b.wait(READY, f"{name} to show")
            check_scene(b, name, page_frame(b), flags, sim, tmp, f"scene{i}", GOLDEN if i == 0 else None)
            if "--board" in flags:
                check_exports(b, name, flags, sim, tmp, f"scene{i}", query.split("&")[0][5:].replace(":", "-"),
                              svg=False)
        # The controls: drag on the screen (40 px right, 20 px down: yaw
        # and pitch +20 and +10 degrees at half a degree a pixel), then
        # the level slider to 0.2; the page then draws render's scene.
        b.send("Page.navigate", {"url": f"{base}?demo=hydrogen:32&size={SIZE}"})
        b.wait(READY, "hydrogen to show")
        frames = b.eval("window.isoscope.frames")
        drag(b)
        b.eval("(() => { const s = document.getElementById('level'); s.value = '0.2'; "
               "s.dispatchEvent(new Event('input')); })()")
        # A redraw after the slider's event has both changes.
        b.wait(f"window.isoscope.frames > {frames} && !window.isoscope.pending() && "
               "(() => { const v = window.isoscope.view(); return v.yaw === 50 && v.pitch === 30; })()",
               "the dragged view and the new level to show", timeout=30)
        dragged = ["--demo", "hydrogen:32", "--yaw", "50", "--pitch", "30", "--level", "0.2"]
        check_scene(b, "hydrogen 32^3 dragged and at level 0.2", page_frame(b), dragged, sim, tmp, "dragged")
        check_exports(b, "hydrogen 32^3 dragged and at level 0.2", dragged, sim, tmp, "dragged", "hydrogen-32")
        check_audio(b, base, sim, tmp)
        check_large(b, sim, tmp)
        if data and (data / FILE_SCENE).exists():
            path = data / FILE_SCENE
            open_file(b, base, path, f"size={SIZE}")
            b.wait(f"(() => {{ const i = window.isoscope.info(); return window.isoscope.error !== null || "
                   f"(i && i.name === {json.dumps(FILE_SCENE)} && window.isoscope.frames >= 2 && "
                   "!window.isoscope.pending()); })()",
                   f"{FILE_SCENE} to load")
            check_scene(b, f"{FILE_SCENE} from the file input", page_frame(b), [str(path)], sim, tmp, "file")
            check_exports(b, f"{FILE_SCENE} from the file input", [str(path)], sim, tmp, "file",
                          FILE_SCENE.rsplit(".", 1)[0])
            # Turned: the page starts from the memory the head needed (its
            # surface does not fit the host's first size), and must still
            # draw render's frame.
            frames = b.eval("window.isoscope.frames")
            drag(b)
            b.wait(f"window.isoscope.frames > {frames} && !window.isoscope.pending() && "
                   "(() => { const v = window.isoscope.view(); return v.yaw === 50 && v.pitch === 30; })()",
                   f"{FILE_SCENE} turned to show", timeout=60)
            check_scene(b, f"{FILE_SCENE} dragged", page_frame(b), [str(path), "--yaw", "50", "--pitch", "30"],
                        sim, tmp, "file-dragged")
        else:
            print(f"web-test: note: no {FILE_SCENE} in the data folder; the file input is not tested")
        # A bad file: a clear error in the page, no crash.
        bad = tmp / "broken.nrrd"
        bad.write_bytes(b"NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n\x00\x00")
        open_file(b, base, bad, f"size={SIZE}")
        b.wait("window.isoscope.error !== null", "the page to report the broken file")
        shown = b.eval("document.getElementById('error').hidden ? '' : "
                       "document.getElementById('error').textContent")
        if "broken.nrrd" not in shown or "truncated" not in shown:
            fail(f"the broken file's error is not shown clearly: {shown!r}")
        print(f"web-test: a broken file shows: {shown}")
        # The board over Web Serial: the page's sender against the virtual
        # board (scripts/web_serial.py).
        web_serial.check(b, base, sim, tmp, render, data)
    print("web-test: ok")

if __name__ == "__main__":
    main()
