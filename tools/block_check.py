#!/usr/bin/env python3
"""Compare an image with a reference block by block, through `voxcone compare --regions`:
the image mean's luminance ratio and every block's, the worst block and how many lie outside
a tolerance. Exit 1 when the mean or a block is outside its bound.

    python3 tools/block_check.py TEST.exr REF.exr [--grid 8] [--mean-tol 0.02] [--block-tol 0.05]
        [--voxcone build/voxcone]

A 256x256 image with --grid 8 has 32x32-pixel blocks. Ratios are of Rec. 709 luminance."""

import argparse
import json
import subprocess
import sys


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("test")
    ap.add_argument("ref")
    ap.add_argument("--grid", type=int, default=8)
    ap.add_argument("--mean-tol", type=float, default=0.02)
    ap.add_argument("--block-tol", type=float, default=0.05)
    ap.add_argument("--voxcone", default="build/voxcone")
    a = ap.parse_args()
    out = subprocess.run([a.voxcone, "compare", a.test, a.ref, "--json", "--regions", str(a.grid)],
                         check=True, capture_output=True, text=True).stdout
    d = json.loads(out)
    mean = lum(d["mean"]) / lum(d["mean_reference"])
    ratios = [(lum(r["mean_test"]) / lum(r["mean_reference"]), r) for r in d["regions"]
              if lum(r["mean_reference"]) > 0]
    worst = max(ratios, key=lambda x: abs(x[0] - 1.0))
    outside = [x for x in ratios if abs(x[0] - 1.0) > a.block_tol]
    psnr = "inf" if d["psnr_srgb8"] is None else f"{d['psnr_srgb8']:.2f}"  # None: the images are equal
    print(f"{a.test} vs {a.ref}: PSNR {psnr} dB, relMSE {d['relmse']:.4g}")
    print(f"  image mean ratio {mean:.4f} (bound 1 +/- {a.mean_tol})")
    print(f"  blocks {len(ratios)}: ratio min {min(r for r, _ in ratios):.4f}, max {max(r for r, _ in ratios):.4f}; "
          f"worst {worst[0]:.4f} at x {worst[1]['x0']}-{worst[1]['x1']}, y {worst[1]['y0']}-{worst[1]['y1']}; "
          f"{len(outside)} outside 1 +/- {a.block_tol}")
    for row in range(a.grid):
        print("   " + " ".join(f"{ratios[row * a.grid + c][0]:.3f}" for c in range(a.grid)
                                if row * a.grid + c < len(ratios)))
    return 0 if abs(mean - 1.0) <= a.mean_tol and not outside else 1


if __name__ == "__main__":
    sys.exit(main())
