#!/usr/bin/env bash
# Renders one scene with every method and prints time against error, measured against a
# converged reference image:  tools/accuracy_table.sh SCENE.json REFERENCE.exr OUTDIR [THREADS]
# Rows: voxcone (defaults, 4 and 16 spp; gather = hit with 16 cones), pm (16 spp), path (16, 64, 256 spp).
# Total time = photon tracing + voxelization + rendering, as `voxcone render` prints it.
set -euo pipefail
scene=$1 ref=$2 out=$3 threads=${4:-0}
bin=${VOXCONE:-$(dirname "$0")/../build/voxcone}
mkdir -p "$out"
printf '%-8s %-34s %9s %10s %9s\n' method settings total_s relMSE psnr_db
run() {
  local name=$1 method=$2 spp=$3 opts=$4 line
  line=$("$bin" render "$scene" --method "$method" --spp "$spp" -t "$threads" -q -o "$out/$name.exr" --options "$opts" | tail -1)
  local total=${line##*total }
  local metrics
  metrics=$("$bin" compare "$out/$name.exr" "$ref" --json)
  python3 - "$method" "spp $spp $opts" "${total% s}" "$metrics" <<'PY'
import json, sys
m = json.loads(sys.argv[4])
print(f"{sys.argv[1]:<8} {sys.argv[2]:<34} {float(sys.argv[3]):9.2f} {m['relmse']:10.5f} {m['psnr_srgb8']:9.2f}")
PY
}
run voxcone4 voxcone 4 '{}'
run voxcone16 voxcone 16 '{}'
run voxcone-hit4 voxcone 4 '{"gather":"hit","cones":16,"photons":200000,"light_samples":4}'
run voxcone-hit16 voxcone 16 '{"gather":"hit","cones":16,"photons":200000}'
run pm16 pm 16 '{}'
for spp in 16 64 256; do run path$spp path "$spp" '{}'; done
