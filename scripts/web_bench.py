#!/usr/bin/env python3
"""Frame times of the web app in headless Chromium on this machine.

Called by scripts/web-bench (which builds the page and the host tool).
Drives the page with scripts/web_driver.py (the browser test's driver) and
reports, as key=value lines and then as a Markdown table for docs/web.md:

- rotating (the page's spin: every frame a new view, built and drawn
  again): hydrogen 32^3, and the MRI head brainsmall.den if DATA_DIR has
  it, opened through the file input. Per frame: the time from the page
  asking its worker for the frame to the pixels on the canvas (`frame`),
  the library's build and draw within it, and the frames a second the
  page reached (frames over the time from the first to the last);
- a level change on a 128^3 volume (gyroid:128): the time from the level
  slider's input event to the first picture on the canvas (a draft, a
  quarter of the slices, when the page makes one: after a frame that took
  100 ms or more to build) and to the frame itself.

Medians and the worst of N. A measurement, not a test: nothing fails for
being slow. Standard library only.

Usage: web_bench.py SIM_BINARY [DATA_DIR] [--frames N] [--levels N] [--size PIXELS]
"""

import argparse
import datetime
import json
import os
import platform
import statistics
import time
from pathlib import Path

import web_driver
from web_driver import READY, fail, open_file

web_driver.PROG = "web-bench"
FILE_SCENE = "brainsmall.den"
LEVEL_DEMO = "gyroid:128"
# Frames left out at the start of a rotation: the first after a load, and
# the engine's code warming up.
WARMUP = 5

# Collect the next `n` frames' times while spinning: [frame ms, build ms,
# draw ms (phosphor and pixels), the time it was shown].
ROTATE = """new Promise((resolve) => {
  const out = [];
  window.isoscope.onframe = (s, ms) => {
    out.push([ms, s.build_ms, s.draw_ms + s.pixels_ms, performance.now()]);
    if (out.length === %d) { window.isoscope.onframe = null; resolve(out); }
  };
  const spin = document.getElementById('spin');
  if (!spin.checked) spin.click();
})"""

# Move the level slider to `level` and time it to the frame: [input to
# canvas ms, frame ms, build ms, draw ms], then the same of the first
# picture shown (the frame itself, or a draft of it) and whether it was a
# draft.
LEVEL = """new Promise((resolve) => {
  const slider = document.getElementById('level');
  const t0 = performance.now();
  let first = null;
  window.isoscope.onframe = (s, ms) => {
    const row = [performance.now() - t0, ms, s.build_ms, s.draw_ms + s.pixels_ms];
    if (first === null) first = [...row, s.draft];
    if (s.draft) return;
    window.isoscope.onframe = null;
    resolve([...row, ...first]);
  };
  slider.value = String(%s);
  slider.dispatchEvent(new Event('input'));
})"""


def settle(b, what):
    b.wait(READY, what, timeout=120)
    err = b.eval("window.isoscope.error")
    if err:
        fail(f"{what}: the page shows an error: {err}")
    b.wait("!window.isoscope.pending()", what, timeout=120)


def rotate(b, tag, frames):
    """Spin the page's volume and time `frames` frames after the warm-up."""
    rows = b.eval(ROTATE % (frames + WARMUP), timeout=600)[WARMUP:]
    b.eval("document.getElementById('spin').click()")
    ms = [r[0] for r in rows]
    span = (rows[-1][3] - rows[0][3]) / 1000
    stats = b.eval("window.isoscope.stats()")
    return {
        f"{tag}_points": stats["points"],
        f"{tag}_samples": stats["samples"],
        f"{tag}_every": stats["every"],
        f"{tag}_frames": len(rows),
        f"{tag}_frame_ms_median": statistics.median(ms),
        f"{tag}_frame_ms_worst": max(ms),
        f"{tag}_build_ms_median": statistics.median(r[1] for r in rows),
        f"{tag}_draw_ms_median": statistics.median(r[2] for r in rows),
        f"{tag}_fps": (len(rows) - 1) / span if span > 0 else float("nan"),
    }


def level_changes(b, tag, n):
    """Move the level slider `n` times between two levels of the volume."""
    info = b.eval("window.isoscope.info()")
    lo, hi = info["range"]
    first = info["default_levels"][0]
    other = first + 0.1 * (hi - lo)
    rows = [b.eval(LEVEL % json.dumps(other if i % 2 == 0 else first), timeout=600) for i in range(n)]
    stats = b.eval("window.isoscope.stats()")
    drafts = [r for r in rows if r[8]]
    out = {
        f"{tag}_points": stats["points"],
        f"{tag}_samples": stats["samples"],
        f"{tag}_every": stats["every"],
        f"{tag}_changes": n,
        f"{tag}_ms_median": statistics.median(r[0] for r in rows),
        f"{tag}_ms_worst": max(r[0] for r in rows),
        f"{tag}_build_ms_median": statistics.median(r[2] for r in rows),
        f"{tag}_draw_ms_median": statistics.median(r[3] for r in rows),
        f"{tag}_drafts": len(drafts),
        f"{tag}_first_ms_median": statistics.median(r[4] for r in rows),
        f"{tag}_first_ms_worst": max(r[4] for r in rows),
    }
    if drafts:
        out[f"{tag}_draft_build_ms_median"] = statistics.median(r[6] for r in drafts)
        out[f"{tag}_draft_draw_ms_median"] = statistics.median(r[7] for r in drafts)
    return out


def machine():
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.node()} ({model}, {os.cpu_count()} cores)"


def fmt(v):
    return f"{v:.1f}" if isinstance(v, float) else str(v)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sim")
    ap.add_argument("data", nargs="?", default="")
    ap.add_argument("--frames", type=int, default=60, help="frames timed while rotating (default 60)")
    ap.add_argument("--levels", type=int, default=10, help="level changes timed (default 10)")
    ap.add_argument("--size", type=int, default=640, help="the picture, pixels a side (the page's default 640)")
    ap.add_argument("--painters", type=int, default=0,
                    help="painters of a band each (the page's ?painters=; default: the page's own)")
    args = ap.parse_args()
    if args.frames < 2 or args.levels < 1:
        fail("give at least 2 frames and 1 level change")
    data = Path(args.data) if args.data else None
    page = f"size={args.size}" + (f"&painters={args.painters}" if args.painters else "")
    out = {
        "date": datetime.date.today().isoformat(),
        "machine": machine(),
        "load_average": " ".join(f"{x:.2f}" for x in os.getloadavg()),
        "size": args.size,
        "painters": args.painters or "page default",
    }
    t0 = time.monotonic()
    with web_driver.session(args.sim) as (b, base, _tmp):
        out["chromium"] = b.send("Browser.getVersion", session=False)["product"]
        b.send("Page.navigate", {"url": f"{base}?demo=hydrogen:32&{page}"})
        settle(b, "hydrogen:32 to show")
        out.update(rotate(b, "hydrogen32_rotate", args.frames))
        if data and (data / FILE_SCENE).exists():
            open_file(b, base, data / FILE_SCENE, page)
            b.wait(f"(() => {{ const i = window.isoscope.info(); return window.isoscope.error !== null || "
                   f"(i && i.name === {json.dumps(FILE_SCENE)}); }})()", f"{FILE_SCENE} to load", timeout=120)
            settle(b, f"{FILE_SCENE} to show")
            out.update(rotate(b, "mri_rotate", args.frames))
        else:
            print(f"web-bench: note: no {FILE_SCENE} in the data folder (scripts/fetch-data); the MRI head is left out")
        b.send("Page.navigate", {"url": f"{base}?demo={LEVEL_DEMO}&{page}"})
        settle(b, f"{LEVEL_DEMO} to show")
        out.update(level_changes(b, "gyroid128_level", args.levels))
    out["bench_seconds"] = time.monotonic() - t0
    for k, v in out.items():
        print(f"{k}={fmt(v)}")

    print()
    print(f"Measured {out['date']} on {out['machine']}, load average {out['load_average']}, "
          f"{out['chromium']}, a {args.size}x{args.size} picture (`scripts/web-bench`, "
          f"{args.frames} frames, {args.levels} level changes):")
    print()
    print("| scene | points | samples | what is timed | median ms | worst ms | build ms | draw ms | frames/s |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = [("hydrogen32_rotate", "hydrogen 32^3, rotating", "a frame"),
            ("mri_rotate", f"MRI head `{FILE_SCENE}` 128x128x84, rotating, every {out.get('mri_rotate_every')}th slice",
             "a frame")]
    for tag, name, what in rows:
        if f"{tag}_frames" not in out:
            continue
        print(f"| {name} | {out[f'{tag}_points']:,} | {out[f'{tag}_samples']:,} | {what} | "
              f"{out[f'{tag}_frame_ms_median']:.0f} | {out[f'{tag}_frame_ms_worst']:.0f} | "
              f"{out[f'{tag}_build_ms_median']:.0f} | {out[f'{tag}_draw_ms_median']:.0f} | {out[f'{tag}_fps']:.1f} |")
    t = "gyroid128_level"
    print(f"| `{LEVEL_DEMO}`, level change, every {out[f'{t}_every']}th slice | {out[f'{t}_points']:,} | "
          f"{out[f'{t}_samples']:,} | slider to picture | {out[f'{t}_ms_median']:.0f} | {out[f'{t}_ms_worst']:.0f} | "
          f"{out[f'{t}_build_ms_median']:.0f} | {out[f'{t}_draw_ms_median']:.0f} | |")
    if out[f"{t}_drafts"]:
        print(f"| `{LEVEL_DEMO}`, level change, its draft first ({out[f'{t}_drafts']} of {out[f'{t}_changes']}) | | | "
              f"slider to draft | {out[f'{t}_first_ms_median']:.0f} | {out[f'{t}_first_ms_worst']:.0f} | "
              f"{out[f'{t}_draft_build_ms_median']:.0f} | {out[f'{t}_draft_draw_ms_median']:.0f} | |")


if __name__ == "__main__":
    main()
