#!/usr/bin/env python3
"""The fair race: voxcone and path tracing, each raw and denoised (`render --denoise`), over
their spp ladders on a set of scenes, timed as a user waits (from starting the process to its
exit, the image written; the median of --repeat runs for renders under 5 s).

    tools/race_table.py OUTDIR SCENE.json=REFERENCE.exr [...] [--threads N] [--repeat N]
                        [--path-spp 1,2,...] [--voxcone-spp 1,2,...] [--options JSON] [--top-db 40]
    tools/race_table.py OUTDIR --replot      (the chart again from OUTDIR/race.json)

Per scene and front (path, path+denoise, voxcone, voxcone+denoise): each render's wall time,
relMSE, PSNR (8-bit sRGB) and worst 4x4 cell (suite_table.py's metrics). Then the race:
- every voxcone+denoise render against path+denoise's ladder: path+denoise's time to the same
  relMSE (log-log between the two renders around it, '>' / '<' outside the ladder) over
  voxcone+denoise's time, the speed-up;
- the fronts compared by PSNR: at each dB from the lowest both fronts reach to --top-db (or the
  highest both reach), each front's time (linear in dB, log in time, between its renders),
  and whether voxcone+denoise's lies below path+denoise's;
- PSNR flatters a smooth image that is wrong in places (a denoiser's failure): per front, the
  first render (by time) whose every 4x4 cell is within --cell-tol of the reference's mean.
Writes OUTDIR/race.md, OUTDIR/race.json and OUTDIR/race.png (PSNR against time, one panel per
scene, the four fronts) where matplotlib is installed. Read ratios within one run."""

import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import suite_table as st  # noqa: E402

FRONTS = ("path", "path+denoise", "voxcone", "voxcone+denoise")


def psnr_time(points, db):
    """Time a ladder needs for `db` (linear in dB, log in time between the two renders around
    it); None outside the ladder."""
    pts = sorted(points, key=lambda p: p["psnr"])
    for lo, hi in zip(pts, pts[1:]):
        if lo["psnr"] <= db <= hi["psnr"]:
            if hi["psnr"] == lo["psnr"]:
                return lo["seconds"]
            u = (db - lo["psnr"]) / (hi["psnr"] - lo["psnr"])
            return math.exp(math.log(lo["seconds"]) + u * (math.log(hi["seconds"]) - math.log(lo["seconds"])))
    return None


def scene_seed(scene):
    """The seed a render of `scene` takes by default: its render.seed, else 0 (a Mitsuba or
    glTF scene: 0)."""
    if not scene.endswith(".json"):
        return 0
    with open(scene) as f:
        return json.load(f).get("render", {}).get("seed", 0)


def front(points):
    """The Pareto front of a ladder: no other render both faster and more accurate."""
    out, best = [], -math.inf
    for p in sorted(points, key=lambda p: (p["seconds"], -p["psnr"])):
        if p["psnr"] > best:
            out.append(p)
            best = p["psnr"]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("pairs", nargs="*", help="SCENE.json=REFERENCE.exr")
    ap.add_argument("--replot", action="store_true", help="only draw OUTDIR/race.png from OUTDIR/race.json")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--path-spp", default="1,2,4,8,16,32,64")
    ap.add_argument("--voxcone-spp", default="1,2,4,8,16")
    ap.add_argument("--options", default="{}", help="voxcone options (JSON), raw and denoised")
    ap.add_argument("--top-db", type=float, default=40.0)
    ap.add_argument("--cell-tol", type=float, default=0.05)
    ap.add_argument("--seed", type=int, help="the renders' seed (default: the scenes' own); the references' must differ")
    ap.add_argument("--regions", type=int, default=4)
    ap.add_argument("--bin", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "voxcone"))
    args = ap.parse_intermixed_args()  # options before, between or after the pairs
    if args.replot:
        with open(os.path.join(args.outdir, "race.json")) as f:
            return plot(json.load(f)["scenes"], args.outdir)
    if not args.pairs:
        ap.error("give SCENE.json=REFERENCE.exr pairs (or --replot)")
    os.makedirs(args.outdir, exist_ok=True)
    ladders = {"path": [int(s) for s in args.path_spp.split(",")],
               "voxcone": [int(s) for s in args.voxcone_spp.split(",")]}
    scenes = []
    for pair in args.pairs:
        scene, ref = pair.split("=", 1)
        name = os.path.basename(scene)
        name = name[:-5] if name.endswith(".json") else name
        ref_seed = st.sidecar_seed(ref)
        if ref_seed is not None and ref_seed == (args.seed if args.seed is not None else scene_seed(scene)):
            sys.exit("race_table: %s was rendered with seed %s, the renders' own: give --seed or render it with "
                     "another seed" % (ref, ref_seed))
        runs = {}
        for f in FRONTS:
            method = f.split("+")[0]
            runs[f] = []
            for spp in ladders[method]:
                out = os.path.join(args.outdir, "%s-%s%d.exr" % (name, f.replace("+", "-"), spp))
                cmd = [args.bin, "render", scene, "--method", method, "--spp", str(spp), "-t", str(args.threads),
                       "-q", "-o", out]
                cmd += ["--options", args.options] if method == "voxcone" else []
                cmd += ["--denoise"] if f.endswith("+denoise") else []
                cmd += ["--seed", str(args.seed)] if args.seed is not None else []
                seconds, times = st.timed(cmd, 1)
                if seconds < 5.0 and args.repeat > 1:
                    seconds, more = st.timed(cmd, args.repeat - 1)
                    times += more
                    seconds = sorted(times)[len(times) // 2]
                with open(out[:-4] + ".json") as fj:
                    seed = json.load(fj).get("seed")
                if ref_seed is not None and seed == ref_seed:
                    sys.exit("race_table: %s was rendered with seed %s, the renders' own: give --seed or render it "
                             "with another seed" % (ref, seed))
                row = {"spp": spp, "seconds": seconds, "runs": times, **st.compare(args.bin, out, ref, args.regions)}
                del row["cells"]
                runs[f].append(row)
                print(json.dumps({"scene": name, "front": f, "spp": spp, "seconds": round(seconds, 3),
                                  "psnr": round(row["psnr"], 2), "worst_cell": round(row["worst_cell"], 3)}),
                      flush=True)
        # voxcone+denoise against path+denoise at equal relMSE.
        for r in runs["voxcone+denoise"]:
            t, where = st.interpolate(runs["path+denoise"], r["relmse"])
            r["path_denoise_seconds"], r["path_denoise_where"] = t, where
            r["speedup"] = t / r["seconds"]
        # The fronts by PSNR, whole dB from the lowest both reach to the top.
        fr = {f: front(runs[f]) for f in FRONTS}
        lo = math.ceil(max(min(p["psnr"] for p in fr["voxcone+denoise"]), min(p["psnr"] for p in fr["path+denoise"])))
        hi = min(args.top_db, max(p["psnr"] for p in fr["voxcone+denoise"]), max(p["psnr"] for p in fr["path+denoise"]))
        by_db = []
        db = lo
        while db <= hi + 1e-9:
            tv, tp = psnr_time(fr["voxcone+denoise"], db), psnr_time(fr["path+denoise"], db)
            by_db.append({"db": db, "voxcone_denoise_seconds": tv, "path_denoise_seconds": tp,
                          "ratio": tv / tp if tv and tp else None})
            db += 1.0
        cells_ok = {}
        for f in FRONTS:
            ok = [p for p in sorted(runs[f], key=lambda p: p["seconds"]) if abs(p["worst_cell"] - 1.0) <= args.cell_tol]
            cells_ok[f] = ok[0] if ok else None
        scenes.append({"scene": name, "reference": ref, "runs": runs, "by_db": by_db, "cells_within": cells_ok,
                       "voxcone_denoise_below": all(b["ratio"] is not None and b["ratio"] < 1.0 for b in by_db)
                       if by_db else None})

    lines = ["| scene | voxcone+denoise spp | s | PSNR dB | worst cell | path+denoise s at that relMSE | speed-up |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for s in scenes:
        for r in s["runs"]["voxcone+denoise"]:
            lines.append("| %s | %d | %.2f | %.2f | %.3f | %s%.2f | %.2f |" % (
                s["scene"], r["spp"], r["seconds"], r["psnr"], r["worst_cell"],
                r["path_denoise_where"].replace("in", ""), r["path_denoise_seconds"], r["speedup"]))
    lines += ["", "| scene | dB | voxcone+denoise s | path+denoise s | ratio |", "|---|---:|---:|---:|---:|"]
    for s in scenes:
        for b in s["by_db"]:
            fmt = lambda v: "-" if v is None else "%.2f" % v  # noqa: E731
            lines.append("| %s | %.0f | %s | %s | %s |" % (s["scene"], b["db"], fmt(b["voxcone_denoise_seconds"]),
                                                          fmt(b["path_denoise_seconds"]), fmt(b["ratio"])))
    lines += ["", "First render with every 4x4 cell within %g%% of the reference (spp, s, PSNR):" % (100 * args.cell_tol),
              "", "| scene | " + " | ".join(FRONTS) + " |", "|---|" + "---:|" * len(FRONTS)]
    for s in scenes:
        cell = lambda p: "none" if p is None else "%d spp, %.2f s, %.1f dB" % (p["spp"], p["seconds"], p["psnr"])  # noqa: E731
        lines.append("| %s | %s |" % (s["scene"], " | ".join(cell(s["cells_within"][f]) for f in FRONTS)))
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.outdir, "race.md"), "w") as f:
        f.write(text)
    with open(os.path.join(args.outdir, "race.json"), "w") as f:
        json.dump({"scenes": scenes, "threads": args.threads, "options": args.options}, f, indent=1)
    sys.stdout.write(text)
    return plot(scenes, args.outdir)


def plot(scenes, outdir):
    """OUTDIR/race.png: PSNR against wall time per scene, the four fronts (needs matplotlib)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("race_table: no matplotlib, no chart", file=sys.stderr)
        return 0
    colours = {"path": "tab:gray", "path+denoise": "black", "voxcone": "tab:blue", "voxcone+denoise": "tab:purple"}
    cols = min(3, len(scenes))
    rows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.flat[len(scenes):]:
        ax.set_visible(False)
    for ax, s in zip(axes.flat, scenes):
        for f in FRONTS:
            pts = sorted(s["runs"][f], key=lambda p: p["seconds"])
            ax.plot([p["seconds"] for p in pts], [p["psnr"] for p in pts], "o--" if f.endswith("denoise") else "o-",
                    color=colours[f], label=f, ms=3)
        ax.set_xscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("PSNR, 8-bit sRGB (dB)")
        ax.set_title(s["scene"], fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "race.png"), dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
