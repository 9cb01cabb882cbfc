#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz: clang, ASan+UBSan) and runs each for SECONDS
# (default 10), seeded with tests/fuzz/seeds and the repository's own inputs. Exit status
# non-zero when a target finds a crash (its reproducer is left in build-fuzz/crashes).
#
#   scripts/fuzz.sh          # 10 s per target: what the test command runs
#   scripts/fuzz.sh 3600     # an hour per target: the figures in docs/reliability.md
#   SONOTRACE_FUZZ_TARGETS="nifti image" scripts/fuzz.sh 3600   # only these targets
#   SONOTRACE_FUZZ_TIMEOUT=30 ...                                 # a slower input may pass
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-10}"
# A fixed seed: the test command's run is the same every time (a finding reproduces);
# SONOTRACE_FUZZ_SEED=0 draws one.
seed="${SONOTRACE_FUZZ_SEED:-1}"
dir="${SONOTRACE_FUZZ_DIR:-build-fuzz}"
jobs="${SONOTRACE_JOBS:-$(nproc)}"
# Seconds one input may take before libFuzzer calls it a hang: raise it only for a run that
# shares a loaded machine (and say so beside its figures).
timeout="${SONOTRACE_FUZZ_TIMEOUT:-10}"
say() { printf '\033[1msonotrace fuzz:\033[0m %s\n' "$*" >&2; }

# Every tests/fuzz/fuzz_<target>.cpp is a target (tests/fuzz/CMakeLists.txt builds them all).
all_targets="$(cd tests/fuzz && ls fuzz_*.cpp | sed 's/^fuzz_//; s/\.cpp$//' | tr '\n' ' ')"
targets="${SONOTRACE_FUZZ_TARGETS:-$all_targets}"
for target in $targets; do
  case " $all_targets " in
    *" $target "*) ;;
    *) say "unknown target '$target' (SONOTRACE_FUZZ_TARGETS): one of $all_targets"; exit 1 ;;
  esac
done

cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_COMPILER=clang \
  -DCMAKE_CXX_COMPILER=clang++ -DSONOTRACE_FUZZ=ON -DSONOTRACE_BUILD_TESTS=OFF \
  -DSONOTRACE_BUILD_BENCH=OFF >/dev/null
say "building the fuzz targets in $dir"
cmake --build "$dir" -j "$jobs" --target fuzz_all

seeds() {  # the repository's own files for a target, beside tests/fuzz/seeds/<target>
  case "$1" in
    json | phantom) echo phantoms ;;
    dataset_spec) echo phantoms/datasets ;;
    dicom_series) echo tests/fuzz/seeds/dicom ;;
    transfer_function) echo tissue/presets ;;
    mesh) echo phantoms/meshes ;;
  esac
}
mkdir -p "$dir/crashes"
status=0
for target in $targets; do
  corpus="$dir/corpus/$target"
  mkdir -p "$corpus"
  inputs=("$corpus")
  [ -d "tests/fuzz/seeds/$target" ] && inputs+=("tests/fuzz/seeds/$target")
  extra="$(seeds "$target")"
  [ -n "$extra" ] && inputs+=("$extra")
  log="$dir/fuzz_$target.log"
  if ASAN_OPTIONS=detect_leaks=1 LSAN_OPTIONS=suppressions=tests/fuzz/lsan.supp \
      UBSAN_OPTIONS=print_stacktrace=1 "$dir/tests/fuzz/fuzz_$target" \
      -seed="$seed" -max_total_time="$seconds" -max_len=65536 -timeout="$timeout" -rss_limit_mb=4096 \
      -artifact_prefix="$dir/crashes/${target}-" -print_final_stats=1 "${inputs[@]}" >"$log" 2>&1; then
    runs="$(grep -m1 'stat::number_of_executed_units' "$log" | awk '{print $2}')"
    cov="$(grep -o 'cov: [0-9]*' "$log" | tail -1)"
    say "$target: ${runs:-?} runs in ${seconds} s, ${cov:-cov: ?}, no crash"
  else
    say "$target: CRASH, see $log and $dir/crashes/"
    tail -n 30 "$log" >&2
    status=1
  fi
done
# The Python module's inputs (tests/fuzz/fuzz_python.py), with the Release build's module:
# the sanitizer build has none (Python cannot load ASan).
release="${SONOTRACE_RELEASE_DIR:-build}"
if ls "$release"/python/sonotrace/_sonotrace*.so >/dev/null 2>&1 && [ -z "${SONOTRACE_FUZZ_TARGETS:-}" ]; then
  if SONOTRACE_BINARY="$release/sonotrace" SONOTRACE_SOURCE_DIR="$PWD" \
      SONOTRACE_PYTHON_DIR="$release/python" python3 tests/fuzz/fuzz_python.py \
      --seconds "$seconds" --seed "$seed" --crashes "$dir/crashes" >&2; then :; else status=1; fi
else
  say "python: skipped (no Python module in $release/python, or SONOTRACE_FUZZ_TARGETS set)"
fi
exit "$status"
