#!/usr/bin/env python3
"""Charts of the batch studies of `voxcone study` (speed-accuracy, photons, levels).

usage: plot_study.py STUDY.json OUT_STEM
- speed-accuracy: relMSE against total time (log-log) and 8-bit sRGB PSNR against time; one
  colour per method, its Pareto front (no other render of the method is both faster and more
  accurate) drawn as a line, marker area proportional to the render's peak RSS.
- photons: MSE and PSNR against photon count, pm and voxcone (the study we compare with went
  from 1000 to 5000 photons; the reference here is converged path tracing).
- levels: voxcone's time, voxel-field memory and error against voxel level.
- structures: per mesh, build time, memory and render time of each acceleration structure
  (bars, log scale), the ratio to the HBVH written on each bar.
- scaling: speedup against thread count (with the ideal line) and build / render time against
  triangle count (log-log, with the fitted exponent).
Writes OUT_STEM.png, OUT_STEM.svg and OUT_STEM.plotted.json (the exact series drawn, for the
tests). Debian's /usr/bin/python3 with python3-matplotlib.
"""
import json
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLOURS = {"path": "tab:gray", "pm": "tab:red", "voxcone": "tab:blue", "voxcone-auto": "tab:cyan",
           "whitted": "tab:green", "path+denoise": "black", "voxcone+denoise": "tab:purple"}


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


def by_method(study, x):
    """Per method, rows sorted by `x`: x, mse, psnr, relmse, seconds, field MB."""
    out = {}
    for r in sorted(study["rows"], key=lambda r: (r["method"], r[x])):
        m = out.setdefault(r["method"], {x: [], "mse": [], "psnr": [], "relmse": [], "seconds": [], "field_mb": []})
        m[x].append(r[x])
        m["mse"].append(r["mse"])
        m["psnr"].append(r["psnr_srgb8"] if r["psnr_srgb8"] is not None else math.nan)
        m["relmse"].append(r["relmse"])
        m["seconds"].append(r["seconds"])
        m["field_mb"].append(r["field_bytes"] / 1e6)
    return out


def plot_photons(study, stem):
    s = by_method(study, "photons")
    fig, (ax_mse, ax_psnr) = plt.subplots(1, 2, figsize=(11, 4.2))
    for method, m in sorted(s.items()):
        c = COLOURS.get(method, "black")
        ax_mse.plot(m["photons"], m["mse"], "o-", color=c, label=method)
        ax_psnr.plot(m["photons"], m["psnr"], "o-", color=c, label=method)
    for ax in (ax_mse, ax_psnr):
        ax.set_xscale("log")
        ax.set_xlabel("photons emitted")
        ax.axvspan(1000, 5000, color="tab:orange", alpha=0.1, label="range of the study we compare with")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    ax_mse.set_yscale("log")
    ax_mse.set_ylabel("MSE against the reference")
    ax_psnr.set_ylabel("PSNR, 8-bit sRGB (dB)")
    fig.suptitle("error against photon count: %s" % study.get("scene", ""), fontsize=10)
    return fig, s


def plot_levels(study, stem):
    s = by_method(study, "level")
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for method, m in sorted(s.items()):
        c = COLOURS.get(method, "black")
        axes[0].plot(m["level"], m["seconds"], "o-", color=c, label=method)
        axes[1].plot(m["level"], m["field_mb"], "o-", color=c, label=method)
        axes[2].plot(m["level"], m["relmse"], "o-", color=c, label=method)
    for ax, label in zip(axes, ["total time (s)", "voxel field (MB)", "relMSE against the reference"]):
        ax.set_xlabel("voxel level (2^level voxels across)")
        ax.set_ylabel(label)
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("voxel resolution: %s" % study.get("scene", ""), fontsize=10)
    return fig, s


ACCEL_COLOURS = {"hbvh": "tab:blue", "bvh": "tab:orange", "kdtree": "tab:green"}


def plot_structures(study):
    meshes = []
    for r in study["rows"]:
        if r["mesh"] not in meshes:
            meshes.append(r["mesh"])
    accels = []
    for r in study["rows"]:
        if r["accel"] not in accels:
            accels.append(r["accel"])
    s = {}
    for a in accels:
        rows = {r["mesh"]: r for r in study["rows"] if r["accel"] == a}
        s[a] = {k: [rows[m][k] if m in rows else None for m in meshes]
                for k in ("triangles", "build_s", "accel_mb", "render_s")}
    s["meshes"] = meshes
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    width = 0.8 / max(1, len(accels))
    for ax, key, label in zip(axes, ("build_s", "accel_mb", "render_s"),
                              ("build time (s)", "structure memory (MB)", "render time (s)")):
        for i, a in enumerate(accels):
            xs = [j + (i - (len(accels) - 1) / 2) * width for j in range(len(meshes))]
            vals = [v if v is not None else math.nan for v in s[a][key]]
            ax.bar(xs, vals, width, color=ACCEL_COLOURS.get(a, "gray"), label=a)
            base = s.get("hbvh", {}).get(key)
            if base:
                for x, v, b in zip(xs, vals, base):
                    if b and v == v:
                        ax.text(x, v, "%.2fx" % (v / b), ha="center", va="bottom", fontsize=7)
        ax.set_xticks(range(len(meshes)))
        ax.set_xticklabels(["%s\n%s tris" % (m, "{:,}".format(int(t)) if t else "?")
                            for m, t in zip(meshes, s[accels[0]]["triangles"])], fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(True, axis="y", which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("acceleration structures: %s, %s spp, %s (ratios to the HBVH)"
                 % (study.get("method", ""), study.get("spp", ""), study.get("res", "")), fontsize=10)
    return fig, s


def plot_scaling(study):
    s = {"threads": {}, "triangles": {}, "triangle_exponents": study.get("triangle_exponents", {})}
    for r in sorted(study["threads"], key=lambda r: (r["method"], r["threads"])):
        m = s["threads"].setdefault(r["method"], {"threads": [], "total_s": [], "speedup": []})
        m["threads"].append(r["threads"])
        m["total_s"].append(r["total_s"])
        m["speedup"].append(r.get("speedup"))
    for r in sorted(study["triangles"], key=lambda r: (r["method"], r["triangles"])):
        m = s["triangles"].setdefault(r["method"], {"triangles": [], "build_s": [], "render_s": [], "total_s": []})
        for k in m:
            m[k].append(r[k])
    fig, (ax_t, ax_n) = plt.subplots(1, 2, figsize=(11, 4.2))
    tmax = 1
    for method, m in sorted(s["threads"].items()):
        c = COLOURS.get(method, "black")
        ax_t.plot(m["threads"], [v if v is not None else math.nan for v in m["speedup"]], "o-", color=c, label=method)
        tmax = max([tmax] + m["threads"])
    ax_t.plot([1, tmax], [1, tmax], "--", color="gray", lw=1, label="ideal")
    ax_t.set_xlabel("threads (machine: %s hardware threads)" % study.get("hardware_threads", "?"))
    ax_t.set_ylabel("speedup of the total time over 1 thread")
    ax_t.set_title(study.get("scene", ""), fontsize=9)
    for method, m in sorted(s["triangles"].items()):
        c = COLOURS.get(method, "black")
        k = s["triangle_exponents"].get(method, {})
        ax_n.plot(m["triangles"], m["render_s"], "o-", color=c,
                  label="%s render (k=%.2f)" % (method, k.get("render") or math.nan))
        ax_n.plot(m["triangles"], m["build_s"], "s--", color=c, alpha=0.6,
                  label="%s structure build (k=%.2f)" % (method, k.get("build") or math.nan))
    ax_n.set_xscale("log")
    ax_n.set_yscale("log")
    ax_n.set_xlabel("triangles (generated knot in the Cornell room)")
    ax_n.set_ylabel("time (s); time ~ triangles^k")
    for ax in (ax_t, ax_n):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("scaling: threads and triangles", fontsize=10)
    return fig, s


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    with open(argv[1]) as f:
        study = json.load(f)
    if not study.get("rows", study.get("threads")):
        print("plot_study.py: no successful renders to plot", file=sys.stderr)
        return 1
    kind = study.get("study", "speed-accuracy")
    if kind == "photons":
        fig, s = plot_photons(study, argv[2])
    elif kind == "levels":
        fig, s = plot_levels(study, argv[2])
    elif kind == "structures":
        fig, s = plot_structures(study)
    elif kind == "scaling":
        fig, s = plot_scaling(study)
    else:
        fig, s = plot_speed_accuracy(study)
    fig.tight_layout()
    fig.savefig(argv[2] + ".png", dpi=120)
    fig.savefig(argv[2] + ".svg")
    with open(argv[2] + ".plotted.json", "w") as f:
        json.dump(s, f)
    print("wrote %s.png, %s.svg" % (argv[2], argv[2]))
    return 0


def plot_speed_accuracy(study):
    s = series(study)
    rss_max = max(max(m["peak_rss_mb"]) for m in s.values())
    fig, (ax_err, ax_psnr) = plt.subplots(1, 2, figsize=(11, 4.4))
    for method, m in sorted(s.items()):
        c = COLOURS.get(method, "black")
        sizes = [12 + 120 * r / rss_max for r in m["peak_rss_mb"]]
        ax_err.scatter(m["seconds"], m["relmse"], s=sizes, color=c, alpha=0.55, label=method)
        # Denoised fronts dashed: the same method's colour family, the race against denoised path.
        style = "--" if method.endswith("+denoise") else "-"
        ax_err.plot(m["front_seconds"], m["front_relmse"], style, color=c, lw=1.5)
        psnr = [p if p is not None else math.nan for p in m["psnr"]]
        ax_psnr.scatter(m["seconds"], psnr, s=sizes, color=c, alpha=0.55, label=method)
        ax_psnr.plot(m["front_seconds"], m["front_psnr"], style, color=c, lw=1.5)
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
    return fig, s


if __name__ == "__main__":
    sys.exit(main(sys.argv))
