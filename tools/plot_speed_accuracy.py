#!/usr/bin/env python3
"""Chart of `voxcone study speed-accuracy`: render time against error for every method.

usage: plot_speed_accuracy.py STUDY.json OUT_STEM
Left: relMSE against total time (log-log), right: 8-bit sRGB PSNR against time; one colour per
method, its Pareto front (no other render of the method is both faster and more accurate) drawn
as a line, marker area proportional to the render's peak RSS. Writes OUT_STEM.png, OUT_STEM.svg
and OUT_STEM.plotted.json (the exact series drawn, for the tests). Debian's /usr/bin/python3
with python3-matplotlib.
"""
import json
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLOURS = {"path": "tab:gray", "pm": "tab:red", "voxcone": "tab:blue", "whitted": "tab:green"}


def series(study):
    out = {}
    for r in study["rows"]:
        m = out.setdefault(r["method"], {"seconds": [], "relmse": [], "psnr": [], "peak_rss_mb": [],
                                         "front_seconds": [], "front_relmse": [], "front_psnr": []})
        m["seconds"].append(r["seconds"])
        m["relmse"].append(r["relmse"])
        m["psnr"].append(r["psnr_srgb8"])
        m["peak_rss_mb"].append(r["peak_rss_bytes"] / 1e6)
    for method, m in out.items():
        front = sorted((r["seconds"], r["relmse"], r["psnr_srgb8"]) for r in study["rows"]
                       if r["method"] == method and r["pareto"])
        m["front_seconds"] = [f[0] for f in front]
        m["front_relmse"] = [f[1] for f in front]
        m["front_psnr"] = [f[2] for f in front]
    return out


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    with open(argv[1]) as f:
        study = json.load(f)
    s = series(study)
    if not s:
        print("plot_speed_accuracy.py: no successful renders to plot", file=sys.stderr)
        return 1
    rss_max = max(max(m["peak_rss_mb"]) for m in s.values())
    fig, (ax_err, ax_psnr) = plt.subplots(1, 2, figsize=(11, 4.4))
    for method, m in sorted(s.items()):
        c = COLOURS.get(method, "black")
        sizes = [12 + 120 * r / rss_max for r in m["peak_rss_mb"]]
        ax_err.scatter(m["seconds"], m["relmse"], s=sizes, color=c, alpha=0.55, label=method)
        ax_err.plot(m["front_seconds"], m["front_relmse"], "-", color=c, lw=1.5)
        psnr = [p if p is not None else math.nan for p in m["psnr"]]
        ax_psnr.scatter(m["seconds"], psnr, s=sizes, color=c, alpha=0.55, label=method)
        ax_psnr.plot(m["front_seconds"], m["front_psnr"], "-", color=c, lw=1.5)
    ax_err.set_xscale("log")
    ax_err.set_yscale("log")
    ax_err.set_xlabel("total time (s)")
    ax_err.set_ylabel("relMSE against the reference")
    ax_err.set_title("error against time (lines: Pareto fronts)")
    ax_psnr.set_xscale("log")
    ax_psnr.set_xlabel("total time (s)")
    ax_psnr.set_ylabel("PSNR, 8-bit sRGB (dB)")
    ax_psnr.set_title("marker area: peak RSS (max %.0f MB)" % rss_max)
    for ax in (ax_err, ax_psnr):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("speed against accuracy: %s" % study.get("scene", ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(argv[2] + ".png", dpi=120)
    fig.savefig(argv[2] + ".svg")
    with open(argv[2] + ".plotted.json", "w") as f:
        json.dump(s, f)
    print("wrote %s.png, %s.svg" % (argv[2], argv[2]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
