#!/usr/bin/env bash
# Install a build into a temporary prefix and use the installed voxcone from another folder:
# its version, a render of an installed scene, and a study whose chart script it must find
# beside itself (share/voxcone/tools). Usage: tools/check_install.sh BUILD_DIR. Exit 0 on success.
set -euo pipefail
build=${1:?usage: check_install.sh BUILD_DIR}
tmp=$(mktemp -d "${TMPDIR:-/tmp}/voxcone-install.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
fail() { echo "check_install.sh: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
bin="$tmp/prefix/bin/voxcone"
share="$tmp/prefix/share/voxcone"
for f in "$bin" "$share/tools/plot_study.py" "$share/tools/plot_memory.py" "$share/tools/fetch_models.sh" \
         "$share/data/scenes/cornell-box.json" "$share/data/scenes/cornell-dragon.json"; do
  [ -e "$f" ] || fail "not installed: ${f#$tmp/prefix/}"
done
mkdir "$tmp/elsewhere"
cd "$tmp/elsewhere"
unset VOXCONE_DATA_DIR
"$bin" --version | grep -q '^voxcone ' || fail "--version"
"$bin" render "$share/data/scenes/cornell-box.json" --method path --res 8x8 --spp 1 -q -o img >/dev/null
[ -s img.exr ] && [ -s img.json ] || fail "render of the installed scene wrote no image"
grep -q "\"scene\": \"$share/data/scenes/cornell-box.json\"" img.json || fail "sidecar scene path"
# The quick structures study draws its chart with the installed tools/plot_study.py.
if /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  "$bin" study structures --quick --accels hbvh -t 1 -o study >/dev/null
  [ -s study/structures.png ] || fail "the installed chart script drew no chart"
fi
# A copy of the executable with no data beside it says so in one line, exit 2.
cp "$bin" "$tmp/lonely"
if out=$("$tmp/lonely" study structures --quick --accels hbvh -o study2 2>&1 >/dev/null); then fail "no data: exit 0"; fi
echo "$out" | grep -q "set VOXCONE_DATA_DIR" || fail "no data: message was: $out"
echo "check_install.sh: installed tree works ($tmp/prefix)"
