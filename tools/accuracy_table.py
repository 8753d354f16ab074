#!/usr/bin/env python3
"""Every method's render time against its error, measured against a converged reference.

    tools/accuracy_table.py SCENE.json REFERENCE.exr OUTDIR [--threads N] [--target-db DB]
                            [--figure-photons N] [--quick] [--res WxH]

Rows: voxcone (defaults at 2, 4, 8, 16 and 64 spp; its most accurate settings: every pixel
gathering 16 times with 16 narrower cones at 64 spp; gather = hit with 16 cones),
pm (defaults, 16 spp) and two path-tracing ladders (4 ... 1024 spp): the default (Owen-scrambled
Sobol) sampler and the independent one, so that the sampler's gain is measured in the same run;
where the denoiser's weights are fetched (tools/fetch_models.sh; --no-denoise leaves them out),
the fair race: path+denoise (1 ... 64 spp) and voxcone+denoise (1 ... 16 spp), `render
--denoise`. For every row that is not path it gives the time path needs to reach the same
relMSE (a denoised row: denoised path's), interpolated log-log between the
two path renders around it ('>' or '<' where it lies outside the ladder: extrapolated), and,
for the target PSNR, the time path and voxcone (defaults) need to reach it (interpolated
linearly in PSNR against log time).

--figure-photons N renders pm and voxcone (16 spp) with the same N photons and writes their
false-colour relative-error images on one scale (the larger 99th percentile of the two), the
study's "traditional vs cones" figure; OUTDIR/figure.png puts both images, the reference and the
error maps side by side when oiiotool is installed.

Writes OUTDIR/table.md and OUTDIR/table.json; total time = everything from loading the scene to
writing the images (the sidecar's total_seconds), the median of --repeat runs for renders under
5 s (the images are deterministic: only the time varies). Read ratios within one run: timings
on a shared machine vary.
"""

import argparse
import json
import math
import os
import shutil
import subprocess
import sys


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def render(args, name, method, spp, options, sampler="sobol", denoise=False):
    out = os.path.join(args.outdir, name + ".exr")
    cmd = [args.bin, "render", args.scene, "--method", method, "--spp", str(spp), "-t", str(args.threads), "-q",
           "-o", out, "--options", json.dumps(options), "--sampler", sampler]
    cmd += ["--res", args.res] if args.res else []
    cmd += ["--denoise"] if denoise else []
    times = []
    while True:
        run(cmd)
        with open(os.path.join(args.outdir, name + ".json")) as f:
            sidecar = json.load(f)
        times.append(sidecar["timings"]["total_seconds"])
        if len(times) >= args.repeat or times[0] >= 5.0:
            break
    metrics = json.loads(run([args.bin, "compare", out, args.reference, "--json"]))
    return {"name": name, "method": method + ("+denoise" if denoise else ""), "sampler": sampler, "spp": spp, "options": options,
            "seconds": sorted(times)[len(times) // 2], "runs": times, "relmse": metrics["relmse"],
            "psnr_srgb8": metrics["psnr_srgb8"], "relerr_p99": metrics["relerr_p99"], "exr": out}


def interpolate(points, x, xkey, ykey, logx, logy):
    """y at x from (x, y) points sorted by x: linear in (log) x and (log) y between the two
    around it, extrapolated from the nearest two outside; returns (y, 'in' | '<' | '>')."""
    pts = sorted(points, key=lambda p: p[xkey])
    if len(pts) < 2:
        raise ValueError("interpolation needs two points")
    fx = (lambda v: math.log(v)) if logx else (lambda v: v)
    fy = (lambda v: math.log(v)) if logy else (lambda v: v)
    gy = (lambda v: math.exp(v)) if logy else (lambda v: v)
    where = "in"
    if x < pts[0][xkey]:
        lo, hi, where = pts[0], pts[1], "<"
    elif x > pts[-1][xkey]:
        lo, hi, where = pts[-2], pts[-1], ">"
    else:
        for lo, hi in zip(pts, pts[1:]):
            if lo[xkey] <= x <= hi[xkey]:
                break
    if fx(hi[xkey]) == fx(lo[xkey]):
        return lo[ykey], where
    u = (fx(x) - fx(lo[xkey])) / (fx(hi[xkey]) - fx(lo[xkey]))
    return gy(fy(lo[ykey]) + u * (fy(hi[ykey]) - fy(lo[ykey]))), where


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene")
    p.add_argument("reference")
    p.add_argument("outdir")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--target-db", type=float, default=35.0)
    p.add_argument("--target-ratio", type=float, default=0.1, help="the ratio voxcone / path the issue asks for")
    p.add_argument("--repeat", type=int, default=3, help="runs per render under 5 s; the median time is kept")
    p.add_argument("--figure-photons", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="few, cheap rows (for the tests)")
    p.add_argument("--res", help="resolution WIDTHxHEIGHT instead of the scene's (the reference's)")
    p.add_argument("--no-denoise", action="store_true", help="no path+denoise and voxcone+denoise rows")
    p.add_argument("--bin", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "voxcone"))
    args = p.parse_args()
    os.makedirs(args.outdir, exist_ok=True)

    if args.quick:
        others = [("voxcone-d1", "voxcone", 1, {"level": 5, "photons": 20000}),
                  ("voxcone-d4", "voxcone", 4, {"level": 5, "photons": 20000}), ("pm-d2", "pm", 2, {"photons": 20000})]
        path_spp = [1, 4, 16]
        voxcone_default = ["voxcone-d1", "voxcone-d4"]
    else:
        others = [("voxcone-d2", "voxcone", 2, {}), ("voxcone-d4", "voxcone", 4, {}), ("voxcone-d8", "voxcone", 8, {}),
                  ("voxcone-d16", "voxcone", 16, {}), ("voxcone-d64", "voxcone", 64, {}),
                  ("voxcone-best64", "voxcone", 64, {"gather_spacing": 1, "gathers": 16, "filter": 8, "cones": 16}),
                  ("voxcone-hit16", "voxcone", 16, {"gather": "hit", "cones": 16}), ("pm-d16", "pm", 16, {})]
        path_spp = [4, 8, 16, 32, 64, 256, 1024]
        voxcone_default = ["voxcone-d2", "voxcone-d4", "voxcone-d8", "voxcone-d16", "voxcone-d64"]

    weights = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "models", "oidn",
                           "rt_hdr_alb_nrm.tza")
    denoise = not args.no_denoise and os.path.exists(weights)
    if args.quick:
        denoised = [("voxcone-dn1", "voxcone", 1, {"level": 5, "photons": 20000})]
        path_dn_spp = [1, 4]
    else:
        denoised = [("voxcone-dn%d" % spp, "voxcone", spp, {}) for spp in (1, 2, 4, 8, 16)]
        path_dn_spp = [1, 2, 4, 8, 16, 64]

    def race(rows, ladder):
        for r in rows:
            t, where = interpolate(ladder, r["relmse"], "relmse", "seconds", True, True)
            # relMSE falls with time: below the ladder's smallest relMSE path needs more time.
            r["path_seconds_same_relmse"] = t
            r["path_extrapolated"] = {"<": ">", ">": "<", "in": ""}[where]

    rows = [render(args, *o) for o in others]
    paths = [render(args, "path%d" % spp, "path", spp, {}) for spp in path_spp]
    race(rows, paths)
    independent = [render(args, "path-independent%d" % spp, "path", spp, {}, "independent") for spp in path_spp]
    rows += paths + independent
    if denoise:
        vd = [render(args, *o, denoise=True) for o in denoised]
        pd = [render(args, "path-dn%d" % spp, "path", spp, {}, denoise=True) for spp in path_dn_spp]
        race(vd, pd)
        rows += vd + pd

    target = {"db": args.target_db}
    path_t, path_where = interpolate(paths, args.target_db, "psnr_srgb8", "seconds", False, True)
    indep_t, indep_where = interpolate(independent, args.target_db, "psnr_srgb8", "seconds", False, True)
    vc = [r for r in rows if r["name"] in voxcone_default]
    vc_t, vc_where = interpolate(vc, args.target_db, "psnr_srgb8", "seconds", False, True)
    target.update({"path_seconds": path_t, "path_extrapolated": path_where != "in",
                   "voxcone_seconds": vc_t, "voxcone_extrapolated": vc_where != "in",
                   "ratio": vc_t / path_t, "path_independent_seconds": indep_t,
                   "path_independent_extrapolated": indep_where != "in"})

    figure = None
    if args.figure_photons > 0:
        n = args.figure_photons
        fig = [render(args, "figure-pm", "pm", 16, {"photons": n}),
               render(args, "figure-voxcone", "voxcone", 16, {"photons": n})]
        scale = max(f["relerr_p99"] for f in fig)
        for f in fig:
            f["error_png"] = f["exr"][:-4] + "-error.png"
            run([args.bin, "compare", f["exr"], args.reference, "--error-scale", repr(scale), "--error-image",
                 f["error_png"]])
        figure = {"photons": n, "error_scale": scale, "renders": fig}
        if shutil.which("oiiotool"):
            ref_png = os.path.join(args.outdir, "reference.png")
            run(["oiiotool", args.reference, "--colorconvert", "linear", "sRGB", "-o", ref_png])
            figure["png"] = os.path.join(args.outdir, "figure.png")
            run(["oiiotool", fig[0]["exr"][:-4] + ".png", fig[1]["exr"][:-4] + ".png", ref_png, fig[0]["error_png"],
                 fig[1]["error_png"], ref_png, "--mosaic", "3x2", "-o", figure["png"]])

    lines = ["| method | spp | options | total s | relMSE | PSNR dB | path s at same relMSE (denoised: path+denoise) "
             "| ratio |",
             "|---|---:|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        same = r.get("path_seconds_same_relmse")
        lines.append("| %s | %d | %s | %.2f | %.5f | %.2f | %s | %s |" % (
            r["method"] + ("" if r["sampler"] == "sobol" else " (%s)" % r["sampler"]), r["spp"], json.dumps(r["options"]) if r["options"] else "defaults", r["seconds"], r["relmse"],
            r["psnr_srgb8"], "" if same is None else "%s%.2f" % (r["path_extrapolated"], same),
            "" if same is None else "%.2f" % (same / r["seconds"])))
    lines.append("")
    lines.append("Time to %.1f dB: path %s%.2f s, voxcone (defaults) %s%.2f s: voxcone takes %.3fx path's time "
                 "(target: at most %.2gx)." % (args.target_db, "~" if target["path_extrapolated"] else "",
                                                 path_t, "~" if target["voxcone_extrapolated"] else "", vc_t,
                                                 target["ratio"], args.target_ratio))
    lines.append("Path's time to %.1f dB by sampler: sobol %s%.2f s, independent %s%.2f s (sobol takes %.2fx the "
                 "time)." % (args.target_db, "~" if target["path_extrapolated"] else "", path_t,
                             "~" if target["path_independent_extrapolated"] else "", indep_t, path_t / indep_t))
    if figure:
        lines.append("Figure (%d photons, 16 spp, error scale %.4g): pm relMSE %.5f, voxcone relMSE %.5f." % (
            figure["photons"], figure["error_scale"], figure["renders"][0]["relmse"], figure["renders"][1]["relmse"]))
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.outdir, "table.md"), "w") as f:
        f.write(text)
    with open(os.path.join(args.outdir, "table.json"), "w") as f:
        json.dump({"scene": args.scene, "reference": args.reference, "threads": args.threads, "rows": rows,
                   "target": target, "figure": figure}, f, indent=1)
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
