#!/usr/bin/env python3
"""voxcone variants side by side: time against error, and the worst region, per variant.

    tools/variant_study.py SCENE.json REFERENCE.exr OUTDIR [--variant NAME=JSON ...]
                           [--spp 2,4,16,64] [--accurate JSON] [--regions N] [--threads N]

Every variant (voxcone options as JSON; default: box and Gaussian mips, `mip_filter`) renders at
each --spp with those options over voxcone's defaults, and once at --accurate (its most
accurate settings, 64 spp) merged with them. Per render: total time (median of --repeat runs
under 5 s, as tools/accuracy_table.py), relMSE, PSNR (8-bit sRGB) and the worst of the N x N
regions: the largest |test / reference - 1| of the regions' mean luminance, over regions whose
reference luminance is at least a tenth of the image's (dark corners' ratios are noise).

Writes OUTDIR/table.md, OUTDIR/table.json and, with python3-matplotlib, OUTDIR/chart.png
(PSNR against time, one line per variant, the accurate renders as markers; --replot redraws it
from table.json). Read differences
between variants within one run: timings on a shared machine vary.
"""

import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import accuracy_table  # noqa: E402  (render: one timed render and its metrics)

ACCURATE = {"gather_spacing": 1, "gathers": 16, "filter": 8, "cones": 16}


def luminance(rgb):
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]


def worst_region(args, exr):
    out = subprocess.run([args.bin, "compare", exr, args.reference, "--json", "--regions", str(args.regions)],
                         check=True, capture_output=True, text=True).stdout
    metrics = json.loads(out)
    image = luminance(metrics["mean_reference"])
    worst = 0.0
    for r in metrics["regions"]:
        ref = luminance(r["mean_reference"])
        if ref >= 0.1 * image:
            worst = max(worst, abs(luminance(r["mean_test"]) / ref - 1.0))
    return worst


def parse_variant(text):
    name, sep, options = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError("a variant is NAME=JSON, got '%s'" % text)
    try:
        value = json.loads(options)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError("variant %s: invalid JSON (%s)" % (name, e))
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("variant %s: options must be a JSON object" % name)
    return name, value


def chart(rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("no python3-matplotlib: chart skipped", file=sys.stderr)
        return False
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, name in enumerate(dict.fromkeys(r["variant"] for r in rows)):
        colour = "C%d" % i
        ladder = sorted((r for r in rows if r["variant"] == name and not r["accurate"]), key=lambda r: r["seconds"])
        ax.plot([r["seconds"] for r in ladder], [r["psnr_srgb8"] for r in ladder], "o-", color=colour, label=name)
        for r in ladder:
            ax.annotate("%d" % r["spp"], (r["seconds"], r["psnr_srgb8"]), fontsize=7, xytext=(3, -9),
                        textcoords="offset points")
        for r in rows:
            if r["variant"] == name and r["accurate"]:
                ax.plot([r["seconds"]], [r["psnr_srgb8"]], "*", color=colour, markersize=11,
                        label=name + " (most accurate)")
    ax.set_xscale("log")
    ax.set_xlabel("total seconds (log)")
    ax.set_ylabel("PSNR, 8-bit sRGB (dB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene")
    p.add_argument("reference")
    p.add_argument("outdir")
    p.add_argument("--variant", action="append", type=parse_variant, default=[],
                   help="NAME=JSON voxcone options (repeatable; default box={} gaussian={\"mip_filter\": \"gaussian\"})")
    p.add_argument("--spp", default="2,4,16,64", help="comma-separated spp of the defaults ladder")
    p.add_argument("--accurate", type=json.loads, default=ACCURATE,
                   help="options of the most accurate render (64 spp); {} skips it")
    p.add_argument("--regions", type=int, default=8)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--res", help="resolution WIDTHxHEIGHT instead of the scene's (the reference's)")
    p.add_argument("--bin", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "voxcone"))
    p.add_argument("--replot", action="store_true", help="only redraw OUTDIR/chart.png from OUTDIR/table.json")
    args = p.parse_args()
    if args.replot:
        with open(os.path.join(args.outdir, "table.json")) as f:
            sys.exit(0 if chart(json.load(f)["rows"], os.path.join(args.outdir, "chart.png")) else 1)
    variants = args.variant or [("box", {"mip_filter": "box"}), ("gaussian", {"mip_filter": "gaussian"})]
    if len({n for n, _ in variants}) != len(variants):
        p.error("variant names must differ")
    try:
        ladder = [int(s) for s in args.spp.split(",")]
    except ValueError:
        p.error("--spp: comma-separated integers, got '%s'" % args.spp)
    os.makedirs(args.outdir, exist_ok=True)

    rows = []
    for name, options in variants:
        jobs = [(spp, options, False) for spp in ladder]
        if args.accurate:
            jobs.append((64, dict(args.accurate, **options), True))
        for spp, opts, accurate in jobs:
            tag = "%s-%s%d" % (name, "accurate-" if accurate else "", spp)
            r = accuracy_table.render(args, tag, "voxcone", spp, opts)
            r.update(variant=name, accurate=accurate, worst_region=worst_region(args, r["exr"]))
            rows.append(r)
            print("%-24s %7.2f s  %6.2f dB  worst region %5.1f%%" % (tag, r["seconds"], r["psnr_srgb8"],
                                                                   100 * r["worst_region"]), file=sys.stderr)

    lines = ["| variant | spp | options | total s | relMSE | PSNR dB | worst region |",
             "|---|---:|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append("| %s | %d | %s | %.2f | %.5f | %.2f | %.1f%% |" % (
            r["variant"], r["spp"], json.dumps(r["options"]), r["seconds"], r["relmse"], r["psnr_srgb8"],
            100 * r["worst_region"]))
    lines.append("")
    lines.append("Worst region: the largest |test / reference - 1| of mean luminance over the %dx%d regions "
                 "holding at least a tenth of the image's mean luminance." % (args.regions, args.regions))
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.outdir, "table.md"), "w") as f:
        f.write(text)
    with open(os.path.join(args.outdir, "table.json"), "w") as f:
        json.dump({"scene": args.scene, "reference": args.reference, "threads": args.threads, "rows": rows}, f, indent=1)
    chart(rows, os.path.join(args.outdir, "chart.png"))
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
