#!/usr/bin/env python3
"""Chart of `voxcone study memory`: voxel-field memory and build time against level.

usage: plot_memory.py STUDY.json OUT_STEM
Writes OUT_STEM.png, OUT_STEM.svg and OUT_STEM.plotted.json (the exact series drawn, so tests
can check the chart against the study's numbers). Run with Debian's /usr/bin/python3 and
python3-matplotlib.
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Memory of the study we compare with, for the same dragon (MB).
REFERENCE_MB = {8: 228.06, 9: 476.31, 10: 1469.22}
GRIDS = ["topology", "opacity", "normal", "axes", "radiance", "radiance_back", "cone_table"]


def series(study):
    rows = [r for r in study["rows"] if "error" not in r]
    levels = [r["level"] for r in rows]
    out = {
        "levels": levels,
        "total_mb": [r["total_bytes"] / 1e6 for r in rows],
        "peak_rss_mb": [r["peak_rss_bytes"] / 1e6 for r in rows],
        "voxelize_s": [r["voxelize_seconds"] for r in rows],
        "inject_s": [r["inject_seconds"] for r in rows],
        "mip_s": [r["mip_seconds"] for r in rows],
        "prepare_s": [r.get("prepare_seconds", 0.0) for r in rows],
        "estimate_mb": [r.get("estimate", {}).get("field_bytes", 0) / 1e6 for r in rows],
        "photons_stored": [r.get("photons_stored", 0) for r in rows],
        "reference_levels": sorted(REFERENCE_MB),
        "reference_mb": [REFERENCE_MB[k] for k in sorted(REFERENCE_MB)],
        "failed_levels": [r["level"] for r in study["rows"] if "error" in r],
    }
    for g in GRIDS:
        out[g + "_mb"] = [r.get("bytes", {}).get(g, 0) / 1e6 for r in rows]
    return out


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    with open(argv[1]) as f:
        study = json.load(f)
    s = series(study)
    if not s["levels"]:
        print("plot_memory.py: no successful rows to plot", file=sys.stderr)
        return 1
    fig, (ax_mem, ax_time) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax_mem.plot(s["levels"], s["total_mb"], "o-", color="tab:blue", lw=2, label="voxcone: all grids + mips")
    for g, style in zip(GRIDS, [":", "--", "-.", (0, (3, 1, 1, 1)), (0, (5, 2)), (0, (1, 2)), (0, (2, 1))]):
        ax_mem.plot(s["levels"], s[g + "_mb"], linestyle=style, lw=1, label=g)
    ax_mem.plot(s["levels"], s["peak_rss_mb"], "s-", color="tab:gray", lw=1, ms=4, label="voxcone: peak RSS")
    ax_mem.plot(s["levels"], s["estimate_mb"], "x--", color="tab:purple", lw=1, ms=5,
                label="estimate before voxelizing (every voxel lit)")
    ax_mem.plot(s["reference_levels"], s["reference_mb"], "D--", color="tab:red", lw=1.5,
                label="reference study (same dragon)")
    for lv, mb in zip(s["reference_levels"], s["reference_mb"]):
        ax_mem.annotate("%.0f" % mb, (lv, mb), textcoords="offset points", xytext=(4, 4), fontsize=7, color="tab:red")
    for lv, mb in zip(s["levels"], s["total_mb"]):
        ax_mem.annotate("%.1f" % mb, (lv, mb), textcoords="offset points", xytext=(4, -11), fontsize=7,
                        color="tab:blue")
    ax_mem.set_yscale("log")
    ax_mem.set_xlabel("voxel level L (2^L voxels across)")
    ax_mem.set_ylabel("memory (MB)")
    ax_mem.set_title("voxel field memory: " + str(study.get("scene", "")).split("/")[-1])
    ax_mem.grid(True, which="both", alpha=0.3)
    ax_mem.legend(fontsize=6, loc="upper left", ncol=2)

    ax_time.plot(s["levels"], s["voxelize_s"], "o-", label="voxelize")
    photons = study.get("photons", 0)
    stored = max(s["photons_stored"]) if s["photons_stored"] else 0
    label = ("inject %d photons" % photons) if isinstance(photons, int) and photons > 0 else (
        "inject the scene's photons (%d stored)" % stored)
    ax_time.plot(s["levels"], s["inject_s"], "s-", label=label)
    ax_time.plot(s["levels"], s["mip_s"], "^-", label="mips")
    ax_time.plot(s["levels"], s["prepare_s"], "k.-", lw=1.5, label="photons + voxelize + inject + mips")
    ax_time.set_yscale("log")
    ax_time.set_xlabel("voxel level L")
    ax_time.set_ylabel("time (s)")
    ax_time.set_title("build time")
    ax_time.grid(True, which="both", alpha=0.3)
    ax_time.legend(fontsize=7)
    if s["failed_levels"]:
        fig.text(0.01, 0.01, "failed levels: " + ", ".join(map(str, s["failed_levels"])), fontsize=7, color="tab:red")
    fig.tight_layout()
    stem = argv[2]
    fig.savefig(stem + ".png", dpi=120)
    fig.savefig(stem + ".svg")
    with open(stem + ".plotted.json", "w") as f:
        json.dump(s, f, indent=1)
    print("wrote %s.png, %s.svg" % (stem, stem))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
