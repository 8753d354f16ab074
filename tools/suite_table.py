#!/usr/bin/env python3
"""voxcone against path on a set of scenes: wall-clock time, error, worst 4x4 cell, and the time
path needs for the same error.

    tools/suite_table.py OUTDIR SCENE.json=REFERENCE.exr [...] [--threads N] [--options JSON]
                         [--path-spp 4,8,...] [--regions N] [--closed SCENE.json=OPEN.json]

Per scene: voxcone's default render (--method voxcone, whatever method the scene names; its
scene's spp, --options added), timed as a user waits
for it: from starting the process to its exit, the image written (the median of --repeat runs);
then path at each --path-spp, timed the same way. Metrics from `voxcone compare --json
--regions N` against the reference: relMSE, PSNR (8-bit sRGB) and each cell's mean luminance
ratio (Rec. 709 weights); the worst cell is the one farthest from 1. Path's time to voxcone's
relMSE is interpolated log-log between the two path renders around it ('>' / '<': outside the
ladder, extrapolated); the speed-up is that time over voxcone's.

Each reference must come from another seed than the table's renders (the scenes' own, as
`voxcone render` takes them): with the same seed path's first N samples are the reference's
first N, its error against it too small by about N/REF_SPP of itself, and voxcone's camera
samples match the reference's too. The reference's sidecar (REFERENCE.json) is read for its seed;
the same seed is an error.

--closed A=B: scene A must render black; its mean over scene B's voxcone mean is reported (the
closed-door room against the open one).

Also reads each voxcone render's sidecar (stats.integrator): photons emitted, stored and in the
seen cells, the precomputed estimates, the field's bytes and active voxels per level. Writes OUTDIR/suite.md and OUTDIR/suite.json. Read ratios within one run."""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time

REC709 = (0.2126, 0.7152, 0.0722)


def lum(rgb):
    return sum(w * c for w, c in zip(REC709, rgb))


def timed(cmd, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, text=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


def compare(binary, test, ref, regions):
    out = subprocess.run([binary, "compare", test, ref, "--json", "--regions", str(regions)], check=True,
                         capture_output=True, text=True).stdout
    m = json.loads(out)
    cells = []
    for r in m.get("regions", []):
        lr = lum(r["mean_reference"])
        cells.append(lum(r["mean_test"]) / lr if lr > 0 else (1.0 if lum(r["mean_test"]) == 0 else math.inf))
    worst = max(cells, key=lambda c: abs(c - 1.0)) if cells else 1.0
    return {"relmse": m["relmse"], "psnr": m["psnr_srgb8"], "cells": cells, "worst_cell": worst,
            "mean": lum(m["mean"]), "mean_reference": lum(m["mean_reference"])}


def sidecar_seed(image):
    path = os.path.splitext(image)[0] + ".json"
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f).get("seed")


def interpolate(points, x):
    """Time at relMSE x, log-log between the two ladder points around it."""
    pts = sorted(points, key=lambda p: p["relmse"])
    where = "in"
    if x < pts[0]["relmse"]:
        lo, hi, where = pts[0], pts[1], ">"
    elif x > pts[-1]["relmse"]:
        lo, hi, where = pts[-2], pts[-1], "<"
    else:
        lo, hi = next((a, b) for a, b in zip(pts, pts[1:]) if a["relmse"] <= x <= b["relmse"])
    if lo["relmse"] == hi["relmse"]:
        return lo["seconds"], where
    u = (math.log(x) - math.log(lo["relmse"])) / (math.log(hi["relmse"]) - math.log(lo["relmse"]))
    return math.exp(math.log(lo["seconds"]) + u * (math.log(hi["seconds"]) - math.log(lo["seconds"]))), where


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("pairs", nargs="+", help="SCENE.json=REFERENCE.exr")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--options", default="{}", help="voxcone options (JSON) added to the defaults")
    ap.add_argument("--path-spp", default="4,8,16,32,64,128,256,512")
    ap.add_argument("--regions", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--closed", action="append", default=[], help="CLOSED.json=OPEN.json")
    ap.add_argument("--no-path", action="store_true", help="voxcone rows only")
    ap.add_argument("--bin", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "voxcone"))
    args = ap.parse_args()
    os.makedirs(args.outdir, exist_ok=True)
    rows = []
    for pair in args.pairs:
        scene, ref = pair.split("=", 1)
        # The scene's file name, less .json (a Mitsuba .xml keeps its extension: cornell-box.xml
        # beside cornell-box.json).
        name = os.path.basename(scene)
        name = name[:-5] if name.endswith(".json") else name
        out = os.path.join(args.outdir, name + "-voxcone.exr")
        cmd = [args.bin, "render", scene, "--method", "voxcone", "-t", str(args.threads), "-q", "-o", out,
               "--options", args.options]
        seconds, runs = timed(cmd, args.repeat)
        row = {"scene": name, "seconds": seconds, "runs": runs, **compare(args.bin, out, ref, args.regions)}
        with open(os.path.join(args.outdir, name + "-voxcone.json")) as f:
            sidecar = json.load(f)
        stats = sidecar.get("stats", {}).get("integrator", {})
        ref_seed = sidecar_seed(ref)
        if ref_seed is not None and ref_seed == sidecar.get("seed"):
            sys.exit("suite_table: %s was rendered with seed %s, the table's own: render it with another --seed" %
                     (ref, ref_seed))
        row["reference_seed"] = ref_seed
        row["photons"] = {k: stats.get(k) for k in ("emitted_global", "stored_global", "seen_photons", "emitted_caustic",
                                                     "stored_caustic", "hit_cache_entries")}
        row["active_voxels"] = stats.get("active_voxels")
        row["field_bytes"] = stats.get("field_bytes")
        if not args.no_path:
            ladder = []
            for spp in [int(s) for s in args.path_spp.split(",")]:
                pout = os.path.join(args.outdir, "%s-path%d.exr" % (name, spp))
                pcmd = [args.bin, "render", scene, "--method", "path", "--spp", str(spp), "-t", str(args.threads),
                        "-q", "-o", pout]
                ps, _ = timed(pcmd, 1 if spp > 32 else args.repeat)
                ladder.append({"spp": spp, "seconds": ps, **compare(args.bin, pout, ref, args.regions)})
                if ladder[-1]["relmse"] < 0.5 * row["relmse"] and len(ladder) >= 2:
                    break
            row["path"] = ladder
            row["path_seconds"], row["path_where"] = interpolate(ladder, row["relmse"])
            row["speedup"] = row["path_seconds"] / row["seconds"]
        rows.append(row)
        print(json.dumps({k: row[k] for k in ("scene", "seconds", "psnr", "relmse", "worst_cell")} |
                         ({"path_seconds": row["path_seconds"], "speedup": row["speedup"]} if "speedup" in row else {})),
              flush=True)
    closed = []
    for pair in args.closed:
        a, b = pair.split("=", 1)
        outs = []
        for s in (a, b):
            o = os.path.join(args.outdir, os.path.splitext(os.path.basename(s))[0] + "-closedcheck.exr")
            subprocess.run([args.bin, "render", s, "--method", "voxcone", "-t", str(args.threads), "-q", "-o", o,
                            "--options", args.options],
                           check=True, capture_output=True)
            outs.append(compare(args.bin, o, o, 1)["mean"])
        closed.append({"closed": a, "open": b, "closed_mean": outs[0], "open_mean": outs[1],
                       "ratio": outs[0] / outs[1] if outs[1] > 0 else math.inf})
        print(json.dumps(closed[-1]), flush=True)
    lines = ["| scene | voxcone s | PSNR dB | relMSE | worst cell | path s to that relMSE | speed-up |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        path = "%s%.2f" % (r.get("path_where", "in").replace("in", ""), r["path_seconds"]) if "path_seconds" in r else "-"
        lines.append("| %s | %.2f | %.2f | %.4g | %.3f | %s | %s |" % (
            r["scene"], r["seconds"], r["psnr"], r["relmse"], r["worst_cell"], path,
            "%.2f" % r["speedup"] if "speedup" in r else "-"))
    for c in closed:
        lines.append("\nclosed %s: mean %.3g, %.4f%% of %s's %.3g" % (
            os.path.basename(c["closed"]), c["closed_mean"], 100 * c["ratio"], os.path.basename(c["open"]), c["open_mean"]))
    with open(os.path.join(args.outdir, "suite.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(args.outdir, "suite.json"), "w") as f:
        json.dump({"rows": rows, "closed": closed, "threads": args.threads, "options": args.options}, f, indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
