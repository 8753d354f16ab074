#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer (float-cast-overflow included) with clang in
# build-asan/: the fast tests under them, then each loader's libFuzzer target (PLY, OBJ, scene
# JSON, Mitsuba XML) for a bounded time from a seed corpus (data/ and tests/fuzz/seeds/). Fails on any report.
# Writes build-asan/fuzz-summary.txt (executions and coverage per target); a crash input is kept
# as build-asan/fuzz-<target>/crash-* (make it a regression test).
#   tools/sanitize.sh [SECONDS_PER_FUZZER]   (default 60)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}

bash tools/setup.sh deps clang
san="-fsanitize=address,undefined,float-cast-overflow -fno-sanitize=vptr -fno-sanitize-recover=all -fno-omit-frame-pointer"
san="$san -fsanitize-ignorelist=$PWD/tools/sanitize-ignorelist.txt"
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS="$san -fsanitize=fuzzer-no-link" -DCMAKE_EXE_LINKER_FLAGS="$san" \
  -DVOXCONE_BUILD_TESTS=ON -DVOXCONE_BUILD_FUZZERS=ON >/dev/null
cmake --build build-asan -j "$(nproc)"

export ASAN_OPTIONS=abort_on_error=1:detect_leaks=1:allocator_may_return_null=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# The fast tests: everything but the dragon, the studies, the batches, the denoiser on renders
# and the scene-accuracy suites (minutes under ASan, and no loader or field code of their own:
# PhotonRadiance* and VoxelCone* run the same code on small scenes, Denoiser* the network on
# small images).
./build-asan/voxcone_tests --gtest_brief=1 \
  --gtest_filter='-*Dragon*:DenoiserWeights*:*Study*:Batch*:AccuracyTable*:*Slow*:Cli*:AutoSettings*:Scaling*:Structures*:FailureSuite*:CanonicalScenes*'

summary=build-asan/fuzz-summary.txt
: >"$summary"
status=0
for target in ply obj scene mitsuba; do
  corpus=build-asan/fuzz-$target
  rm -rf "$corpus" && mkdir -p "$corpus"
  cp tests/fuzz/seeds/$target/* "$corpus"/
  case $target in
    ply) cp data/meshes/*.ply "$corpus"/; ./build-asan/voxcone generate-mesh --triangles 64 -o "$corpus/generated.ply" >/dev/null ;;
    obj) cp data/meshes/*.obj "$corpus"/; { cat data/meshes/cube.obj; printf '\0'; cat data/meshes/cube.mtl; } >"$corpus/cube-with-mtl.obj" ;;
    scene) cp data/scenes/*.json "$corpus"/ ;;
    mitsuba) cp data/scenes/*.xml "$corpus"/ ;;
  esac
  log=build-asan/fuzz-$target.log
  if ! (cd "$corpus" && ../fuzz_$target -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
          -print_final_stats=1 . >"../fuzz-$target.log" 2>&1); then
    echo "fuzz_$target: FAILED (build-asan/fuzz-$target.log, crash input in $corpus)" | tee -a "$summary"
    tail -40 "$log"
    status=1
    continue
  fi
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo 0)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo 0)
  units=$(ls "$corpus" | wc -l)
  echo "fuzz_$target: ${seconds} s, $runs executions, coverage $cov edges ($ft features), corpus $units inputs, no report" | tee -a "$summary"
done
exit $status
