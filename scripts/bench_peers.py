"""Contouring speed of isoscope beside its peers, on one machine in one run.

Run by scripts/bench-peers (which builds isoscope-sim, writes the demo volume
as raw f32 with isoscope's own code, and makes the venv); not meant to be run
by hand, though `python bench_peers.py --help` says what it takes.

The workload: every axis slice of an N^3 f32 volume (the gyroid demo, written
by `write_demo`, read by every tool from the same file): N x-y slices
vol[z,:,:], N x-z slices vol[:,y,:] and N y-z slices vol[:,:,x], contoured at
one level (0), one thread. A slice of nx x ny samples has (nx-1)(ny-1) cells,
so the workload is 3N(N-1)^2 cells for every tool, and every `*_mcells`
figure is those cells / seconds / 1e6. Each figure is the best of --reps runs,
taken round by round (each tool once a round, so that a machine whose speed
drifts slows all of them alike).

What each tool's time covers:
  isoscope_*       isoscope-sim's own `--stats` `seconds`: the contouring of
                   all slices alone (`contour --format none`: every point is
                   computed and folded into a checksum, nothing written). It
                   does not include reading the file, which isoscope-sim has
                   loaded before its clock starts; it does include starting
                   and joining its worker threads. isoscope reads the slices
                   straight from the volume, no per-slice copy (it sweeps
                   each plane in bands of rows, x innermost).
  vtk_fe2d_*       the sum over slices of vtkFlyingEdges2D's Update() alone.
                   Not timed: copying the slice into a contiguous array and
                   wrapping it as one vtkImageData (done just before, so the
                   slice is warm in cache). Timed: VTK's pipeline overhead
                   and building the output vtkPolyData (points + 2-point
                   lines; ComputeScalars off, as isoscope outputs no scalars).
                   VTK's SMP backend is set to Sequential (one thread).
  contourpy_*      the sum over slices of contour_generator(...).lines(level)
                   alone, serial algorithm, line_type ChunkCombinedOffset.
                   Not timed: the contiguous copy and building the generator
                   (which converts the slice to float64 and makes the x, y
                   grids), done just before each slice.
  *_10_mcells      the same slices with ten levels at once (isoscope: ten
                   --level; VTK: SetNumberOfContours(10) and SetValue; contourpy:
                   .lines(v) for each of the ten), still counted as 3N(N-1)^2
                   cells: per pass over the data, not per level.
  isoscope_2t_mcells, scaling_2t
                   isoscope with --threads 2, and its ratio to one thread.
  isoscope_skip_mcells
                   isoscope at a level above the volume's maximum: no cell is
                   crossed, so this is the cost of deciding that.
  bandwidth_gb_s   a streaming read of the whole volume from memory: the best
                   of numpy's add.reduce and maximum.reduce over the
                   contiguous volume (one read of N^3 x 4 bytes), in 1e9 B/s.
  read_bound_mcells
                   cells / (3 x volume bytes / bandwidth) / 1e6: the speed if
                   contouring cost nothing but reading the volume once per
                   plane orientation at that bandwidth.
  skip_to_bound    isoscope_skip_mcells / read_bound_mcells (1 = as fast as
                   the reads alone; the issue's goal is >= 0.5).
  ratio_to_best    isoscope_mcells / max(vtk_fe2d_mcells, contourpy_mcells).
  same_volume      ok when isoscope-sim contours each raw file exactly as its
                   own --demo gyroid:N (the same crossing cells and commands).
  crosscheck       ok when, on every slice of a 64^3 gyroid at levels 0 and
                   0.3, the contour points on grid edges agree: at least 99%
                   of isoscope's have a VTK and a contourpy point within
                   ~1e-3 voxel and the other way round, slice by slice; and
                   the total contour length over all slices agrees within
                   0.5%. Else the script fails. (Segment counts are not
                   compared: Zyda's subgrid is a cell cut into four
                   triangles about a centre node, the mean of its corners, so
                   isoscope's polylines also pass through points on the
                   spokes inside each crossing cell: about twice the peers'
                   segments for very nearly the same curve.)
  crosscheck_points
                   how many of isoscope's edge points were compared.
"""

import argparse
import datetime
import math
import os
import platform
import re
import subprocess
import sys
import time

import contourpy
import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkSMPTools, vtkVersion
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkFiltersCore import vtkFlyingEdges2D


def slices(vol):
    """Every axis slice, as (plane, index, view): x-y, then x-z, then y-z."""
    nz, ny, nx = vol.shape
    for z in range(nz):
        yield "xy", z, vol[z, :, :]
    for y in range(ny):
        yield "xz", y, vol[:, y, :]
    for x in range(nx):
        yield "yz", x, vol[:, :, x]


def cells_of(vol):
    nz, ny, nx = vol.shape
    return nz * (ny - 1) * (nx - 1) + ny * (nz - 1) * (nx - 1) + nx * (nz - 1) * (ny - 1)


# --- VTK ----------------------------------------------------------------------


def vtk_image(a):
    """A 2D vtkImageData holding a contiguous copy of slice `a` (rows, cols)."""
    a = np.ascontiguousarray(a)
    rows, cols = a.shape
    img = vtkImageData()
    img.SetDimensions(cols, rows, 1)
    arr = numpy_support.numpy_to_vtk(a.ravel(), deep=1)
    arr.SetName("v")
    img.GetPointData().SetScalars(arr)
    return img


def vtk_filter(levels):
    fe = vtkFlyingEdges2D()
    fe.ComputeScalarsOff()
    fe.SetNumberOfContours(len(levels))
    for i, v in enumerate(levels):
        fe.SetValue(i, float(v))
    return fe


def vtk_seconds(vol, levels):
    fe = vtk_filter(levels)
    total = 0.0
    for _, _, s in slices(vol):
        img = vtk_image(s)
        fe.SetInputData(img)
        t0 = time.perf_counter()
        fe.Update()
        total += time.perf_counter() - t0
    return total


def vtk_lines(a, level):
    """The contour of slice `a` as polylines, in (column, row) coordinates."""
    fe = vtk_filter([level])
    fe.SetInputData(vtk_image(a))
    fe.Update()
    out = fe.GetOutput()
    if out.GetNumberOfPoints() == 0:
        return []
    pts = numpy_support.vtk_to_numpy(out.GetPoints().GetData())[:, :2].astype(np.float64)
    conn = numpy_support.vtk_to_numpy(out.GetLines().GetConnectivityArray())
    offs = numpy_support.vtk_to_numpy(out.GetLines().GetOffsetsArray())
    return [pts[conn[offs[c] : offs[c + 1]]] for c in range(len(offs) - 1)]


# --- contourpy ----------------------------------------------------------------


def cp_generator(a):
    return contourpy.contour_generator(
        z=np.ascontiguousarray(a),
        name="serial",
        line_type=contourpy.LineType.ChunkCombinedOffset,
    )


def contourpy_seconds(vol, levels):
    total = 0.0
    lv = [float(v) for v in levels]
    for _, _, s in slices(vol):
        gen = cp_generator(s)
        t0 = time.perf_counter()
        for v in lv:
            gen.lines(v)
        total += time.perf_counter() - t0
    return total


def contourpy_lines(a, level):
    """The contour of slice `a` as polylines, in (column, row) coordinates."""
    points, offsets = cp_generator(a).lines(float(level))
    out = []
    for pts, offs in zip(points, offsets):
        if pts is not None:
            out += [pts[offs[i] : offs[i + 1]] for i in range(len(offs) - 1)]
    return out


# --- isoscope -----------------------------------------------------------------


def iso_args(sim, raw, n, levels, threads):
    args = [sim, "contour", raw, "--dims", f"{n}x{n}x{n}", "--dtype", "f32"]
    for v in levels:
        args += ["--level", repr(float(v))]
    return args + ["--threads", str(threads)]


def iso_stats(sim, raw, n, levels, threads):
    """isoscope-sim's --stats lines of one contouring run, as a dict."""
    r = subprocess.run(
        iso_args(sim, raw, n, levels, threads) + ["--format", "none", "--stats"],
        capture_output=True,
        text=True,
        check=True,
    )
    stats = dict(re.findall(r"^(\w+)=(\S+)$", r.stderr, re.M))
    return {k: float(v) for k, v in stats.items()}


def same_as_demo(sim, raw, n, level):
    """Whether isoscope-sim contours the raw file exactly as its own
    `--demo gyroid:N` (the same cells crossed, the same commands): that the
    file holds the demo's samples, as far as contouring can tell."""
    from_file = iso_stats(sim, raw, n, [level], 1)
    r = subprocess.run(
        [sim, "contour", "--demo", f"gyroid:{n}", "--level", repr(level), "--threads", "1"]
        + ["--format", "none", "--stats"],
        capture_output=True,
        text=True,
        check=True,
    )
    demo = {k: float(v) for k, v in re.findall(r"^(\w+)=(\S+)$", r.stderr, re.M)}
    keys = ("cells", "crossing_cells", "commands")
    return all(from_file[k] == demo[k] for k in keys)


def iso_seconds(sim, raw, n, levels, threads, cells):
    s = iso_stats(sim, raw, n, levels, threads)
    if int(s["cells"]) != cells:
        sys.exit(f"bench-peers: isoscope counted {int(s['cells'])} cells, expected {cells}")
    return s["seconds"]


# In-plane (column, row) coordinates of each plane's slices, as numpy views
# them in slices(): x-y slice vol[z] has columns x, rows y; x-z: x, z; y-z: y, z.
IN_PLANE = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


def iso_lines(sim, raw, n, level):
    """{(plane, index): polylines in (column, row) coordinates} from the CSV."""
    r = subprocess.run(
        iso_args(sim, raw, n, [level], 1) + ["--format", "csv"], capture_output=True, text=True, check=True
    )
    out = {}
    for line in r.stdout.splitlines()[1:]:
        _, axis, index, op, x, y, z = line.split(",")
        xyz = (float(x), float(y), float(z))
        c, r_ = IN_PLANE[axis]
        p = (xyz[c], xyz[r_])
        lines = out.setdefault((axis, int(index)), [])
        if op == "M":
            lines.append([p])
        elif op == "L":
            lines[-1].append(p)
        # "P": a single node exactly at the level; the peers draw nothing there.
    return {k: [np.array(pl) for pl in v] for k, v in out.items()}


# --- the rest -----------------------------------------------------------------


def best(reps, f):
    return min(f() for _ in range(reps))


def best_of_rounds(reps, fs):
    """The fewest seconds of each of `fs` over `reps` rounds, each round
    timing every one of them once, in turn."""
    secs = [[] for _ in fs]
    for _ in range(reps):
        for f, s in zip(fs, secs):
            s.append(f())
    return [min(s) for s in secs]


def bandwidth(vol, reps):
    """Bytes per second of a streaming read of the contiguous volume."""
    flat = vol.ravel()
    secs = []
    for reduce in (np.add.reduce, np.maximum.reduce):
        for _ in range(reps):
            t0 = time.perf_counter()
            reduce(flat)
            secs.append(time.perf_counter() - t0)
    return flat.nbytes / min(secs)


def edge_points(lines):
    """The distinct points of polylines that lie on grid edges (one coordinate
    whole), and the lines' total length. isoscope cuts each cell into four
    triangles about its centre, so its polylines also pass through points
    inside cells; the
    points on the grid's edges are linear interpolation along those edges for
    every tool, so they must agree."""
    if not lines:
        return np.zeros((0, 2)), 0.0
    pts = np.concatenate(lines)
    length = sum(float(np.linalg.norm(np.diff(pl, axis=0), axis=1).sum()) for pl in lines)
    on_edge = (np.abs(pts - np.round(pts)) < 1e-6).any(axis=1)
    return np.unique(np.round(pts[on_edge], 5), axis=0), length


def matched(a, b, tol=1e-3):
    """How many points of `a` have a point of `b` within about `tol` (on a
    grid of `tol`: the same or a neighbouring grid square)."""
    if len(a) == 0 or len(b) == 0:
        return 0
    qa, qb = np.floor(a / tol).astype(np.int64), np.floor(b / tol).astype(np.int64)
    span = int(max(qa.max(), qb.max())) + 3
    key = lambda q: (q[:, 0] + 1) * span + (q[:, 1] + 1)  # noqa: E731
    kb = np.unique(key(qb))
    hit = np.zeros(len(a), dtype=bool)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            hit |= np.isin(key(qa + np.array([dx, dy])), kb, assume_unique=False)
    return int(hit.sum())


def crosscheck(sim, raw, n, levels):
    """Contour every slice of a small volume with all three tools and compare
    their edge points slice by slice (at least 99% of each tool's points
    within 1e-3 voxel of the other's) and their total contour length (within
    0.5%). Returns (points compared, failures)."""
    vol = np.fromfile(raw, "<f4").reshape(n, n, n)
    bad, compared = [], 0
    for level in levels:
        iso = iso_lines(sim, raw, n, level)
        totals = {"isoscope": 0.0, "vtk": 0.0, "contourpy": 0.0}
        for plane, index, s in slices(vol):
            ip, il = edge_points(iso.get((plane, index), []))
            totals["isoscope"] += il
            compared += len(ip)
            for name, lines in (("vtk", vtk_lines(s, level)), ("contourpy", contourpy_lines(s, level))):
                pp, pl = edge_points(lines)
                totals[name] += pl
                need_i, need_p = 0.99 * len(ip), 0.99 * len(pp)
                if matched(ip, pp) < need_i or matched(pp, ip) < need_p:
                    bad.append(
                        f"{plane} {index} level {level}: isoscope has {len(ip)} edge points, {name} {len(pp)}, "
                        f"{matched(ip, pp)} and {matched(pp, ip)} matched"
                    )
        for name in ("vtk", "contourpy"):
            if abs(totals[name] - totals["isoscope"]) > 0.005 * totals["isoscope"]:
                bad.append(f"level {level}: total length isoscope {totals['isoscope']:.3f}, {name} {totals[name]:.3f}")
    return compared, bad


def machine():
    """The CPU as /proc/cpuinfo names it, with its family and model, and the
    CPUs this process may use."""
    cpus = len(os.sched_getaffinity(0))
    try:
        with open("/proc/cpuinfo") as f:
            info = f.read().split("\n\n")[0]
    except OSError:
        return f"{platform.machine()}, {cpus} CPUs"
    field = lambda k: (re.search(rf"^{k}\s*:\s*(.*)$", info, re.M) or [None, "?"])[1].strip()  # noqa: E731
    virt = ", virtual machine" if re.search(r"\bhypervisor\b", info) else ""
    return f"{field('model name')} (family {field('cpu family')} model {field('model')}{virt}), {cpus} CPUs"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sim", required=True, help="the isoscope-sim binary")
    ap.add_argument("--raw", required=True, help="the volume: N^3 little-endian f32, x fastest")
    ap.add_argument("--n", type=int, required=True)
    ap.add_argument("--check-raw", required=True, help="a small volume for the cross-check")
    ap.add_argument("--check-n", type=int, required=True)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--level", type=float, default=0.0)
    a = ap.parse_args()

    vtkSMPTools().SetBackend("Sequential")
    say = lambda k, v: print(f"{k}={v}", flush=True)  # noqa: E731
    sim_version = subprocess.run([a.sim, "--version"], capture_output=True, text=True).stdout.split()
    say("date", datetime.datetime.now().astimezone().isoformat(timespec="seconds"))
    say("machine", machine())
    say("isoscope_version", sim_version[-1] if sim_version else "unknown")
    say("vtk_version", vtkVersion.GetVTKVersion())
    say("vtk_smp_backend", vtkSMPTools().GetBackend())
    say("contourpy_version", contourpy.__version__)
    say("numpy_version", np.__version__)
    say("python_version", platform.python_version())

    same = same_as_demo(a.sim, a.raw, a.n, a.level) and same_as_demo(a.sim, a.check_raw, a.check_n, 0.3)
    say("same_volume", "ok" if same else "FAILED")
    if not same:
        sys.exit("bench-peers: isoscope-sim contours the raw file differently from its --demo")
    compared, bad = crosscheck(a.sim, a.check_raw, a.check_n, [0.0, 0.3])
    for b in bad[:10]:
        print(f"bench-peers: cross-check: {b}", file=sys.stderr)
    say("crosscheck_points", compared)
    say("crosscheck", "ok" if not bad else f"FAILED({len(bad)})")
    if bad:
        sys.exit(1)

    n, reps = a.n, a.reps
    vol = np.fromfile(a.raw, "<f4").reshape(n, n, n)
    cells = cells_of(vol)
    lo, hi = float(vol.min()), float(vol.max())
    # Ten levels evenly inside the range, exact in f32 so every tool gets the same.
    ten = [float(np.float32(lo + (hi - lo) * (i + 1) / 11)) for i in range(10)]
    skip = float(np.float32(hi + 1.0))
    mc = lambda secs: cells / secs / 1e6  # noqa: E731
    say("volume", f"gyroid:{n} f32 {vol.nbytes} bytes, range {lo:.6g}..{hi:.6g}")
    say("slices", 3 * n)
    say("cells", cells)
    say("level", a.level)
    say("levels_10", ",".join(repr(v) for v in ten))
    say("reps", reps)

    one = [a.level]
    # Round by round (isoscope, VTK, contourpy, then again), the best of
    # each: a machine whose speed drifts over a minute slows all three
    # alike, not the one timed then.
    iso_s, vtk_s, cp_s = best_of_rounds(reps, [
        lambda: iso_seconds(a.sim, a.raw, n, one, 1, cells),
        lambda: vtk_seconds(vol, one),
        lambda: contourpy_seconds(vol, one),
    ])
    iso, vtk_mc, cp = mc(iso_s), mc(vtk_s), mc(cp_s)
    say("isoscope_mcells", f"{iso:.1f}")
    say("vtk_fe2d_mcells", f"{vtk_mc:.1f}")
    say("contourpy_mcells", f"{cp:.1f}")
    say("ratio_to_best", f"{iso / max(vtk_mc, cp):.2f}")

    one_t, two_t = best_of_rounds(reps, [
        lambda: iso_seconds(a.sim, a.raw, n, one, 1, cells),
        lambda: iso_seconds(a.sim, a.raw, n, one, 2, cells),
    ])
    say("isoscope_2t_mcells", f"{mc(two_t):.1f}")
    say("scaling_2t", f"{one_t / two_t:.2f}")

    iso10, vtk10, cp10 = best_of_rounds(reps, [
        lambda: iso_seconds(a.sim, a.raw, n, ten, 1, cells),
        lambda: vtk_seconds(vol, ten),
        lambda: contourpy_seconds(vol, ten),
    ])
    say("isoscope_10_mcells", f"{mc(iso10):.1f}")
    say("vtk_fe2d_10_mcells", f"{mc(vtk10):.1f}")
    say("contourpy_10_mcells", f"{mc(cp10):.1f}")

    skip_mc = mc(best(reps, lambda: iso_seconds(a.sim, a.raw, n, [skip], 1, cells)))
    bw = bandwidth(vol, max(reps, 5))
    bound = cells / (3 * vol.nbytes / bw) / 1e6
    say("isoscope_skip_mcells", f"{skip_mc:.1f}")
    say("bandwidth_gb_s", f"{bw / 1e9:.2f}")
    say("read_bound_mcells", f"{bound:.1f}")
    say("skip_to_bound", f"{skip_mc / bound:.2f}")


if __name__ == "__main__":
    main()
