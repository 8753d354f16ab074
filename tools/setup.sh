#!/usr/bin/env bash
# voxcone set-up on a new Debian 12 machine: install what is missing, build, then render or test.
#   tools/setup.sh render [voxcone render args...]   release build, renders the default scene
#   tools/setup.sh test                               release build with tests, runs ctest
#   tools/setup.sh models                             npm and node if missing, then tools/fetch_models.sh
#   tools/setup.sh deps | build                       only install / only build
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(build-essential cmake ninja-build pkg-config git
  libopenvdb-dev libopenvdb-tools libboost-iostreams-dev libopenimageio-dev libopenexr-dev libpng-dev libjpeg-dev zlib1g-dev libglm-dev libtbb-dev
  libtinyobjloader-dev libtinygltf-dev libstb-dev libcli11-dev nlohmann-json3-dev libpugixml-dev libgtest-dev libbenchmark-dev libxxhash-dev)

install_deps() {
  local missing=()
  for p in "${PACKAGES[@]}" "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "installing: ${missing[*]}" >&2
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

build() {
  local tests=$1
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DVOXCONE_BUILD_TESTS="$tests" >/dev/null
  local jobs
  jobs=$(nproc)
  if [ "$tests" = ON ]; then cmake --build build -j "$jobs"; else cmake --build build -j "$jobs" --target voxcone; fi
}

cmd=${1:-render}
shift || true
case "$cmd" in
  deps) install_deps "$@" ;;
  build) install_deps; build ON ;;
  render)
    install_deps python3-matplotlib
    build OFF
    ./build/voxcone render "$@"
    ;;
  test)
    # Embree: `--accel embree` and its tests; slurm-wlm and munge: the Slurm self-test
    # (ctest SlurmSelftest starts its own one-node cluster); oiiotool: the test that reads an
    # output's attributes and layers as a user would.
    install_deps python3-matplotlib libembree-dev slurm-wlm munge openimageio-tools
    build ON
    ctest --test-dir build --output-on-failure -j "$(nproc)"
    ;;
  models)
    # fetch_models.sh runs `npm pack` and node; a machine with node from elsewhere (its own npm)
    # keeps it: only missing commands are installed.
    need=(gzip tar)
    command -v node >/dev/null 2>&1 || need+=(nodejs)
    command -v npm >/dev/null 2>&1 || need+=(npm)
    install_deps "${need[@]}"
    bash tools/fetch_models.sh
    ;;
  *) echo "usage: tools/setup.sh render|test|models|deps|build" >&2; exit 2 ;;
esac
