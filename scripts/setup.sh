#!/usr/bin/env bash
# sonotrace set-up: installs the Debian 12 packages that are missing (apt only when
# something is missing, so a second run is fast), configures and builds (Release,
# ccache), then runs what was asked.
#
#   scripts/setup.sh demo      build and run the default simulation
#   scripts/setup.sh test      build and run every test (CI runs this: .ci/run)
#   scripts/setup.sh sanitize  the ASan+UBSan build and its tests, then fuzz every parser
#   scripts/setup.sh build     only install and build
#   scripts/setup.sh install [PREFIX]   build, then install the programs, the phantom
#                              catalogue and the Python module under PREFIX (/usr/local)
#
# Environment: SONOTRACE_JOBS (default: all cores), SONOTRACE_BUILD_DIR (default: build).
set -euo pipefail

cd "$(dirname "$0")/.."
mode="${1:-demo}"
jobs="${SONOTRACE_JOBS:-$(nproc)}"
build_dir="${SONOTRACE_BUILD_DIR:-build}"

packages=(
  # toolchain
  g++ cmake ninja-build ccache pkg-config
  # libraries (OpenCV only in the modules we link: core, imgproc, videoio)
  libniftiio-dev libznz-dev zlib1g-dev libopenimageio-dev
  # nifti1_io.h includes nifti1.h, which only libnifti2-dev installs
  libnifti2-dev
  # OpenImageIO's CMake config checks that its tools (/usr/bin/iconvert, ...) exist;
  # without this package find_package(OpenImageIO) fails on a fresh machine
  openimageio-tools
  libopencv-core-dev libopencv-imgproc-dev libopencv-videoio-dev
  libglm-dev libcli11-dev nlohmann-json3-dev libtbb-dev
  # `sonotrace dataset`: HDF5 shards, read back by the Python tests with h5py
  libhdf5-dev python3 python3-h5py python3-numpy python3-pytest
  # ... spread over MPI ranks
  libopenmpi-dev openmpi-bin
  # the Python module (pybind11 needs Python's headers)
  pybind11-dev python3-dev
  # DICOM series as input volumes
  libgdcm-dev
  # surface meshes (STL, OBJ, PLY) as phantom shapes
  libassimp-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  # the teaching GUI (Dear ImGui ships its GLFW/OpenGL3 backends as sources), and Xvfb
  # with Mesa to run it headless in the tests; EGL for `render --renderer gpu` without a
  # display (Mesa's software rasteriser where there is no GPU)
  libimgui-dev libglfw3-dev libgl-dev libegl-dev libegl-mesa0 xvfb xauth libgl1-mesa-dri
  fonts-dejavu-core
  # the embedded default volume: Colin27 T1 head MRI
  mricron-data
)
# The tests check sonotrace.torch's FrameDataset against the dataset's shards; PyTorch
# stays optional for users (the module imports it only there).
if [ "$mode" = test ]; then packages+=(python3-torch); fi
# The sanitizer run also fuzzes every input parser (scripts/fuzz.sh: clang's libFuzzer).
if [ "$mode" = sanitize ]; then packages+=(clang libclang-rt-14-dev); fi

say() { printf '\033[1msonotrace setup:\033[0m %s\n' "$*" >&2; }

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  say "installing ${#missing[@]} missing Debian packages: ${missing[*]}"
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { say "not root and no sudo: install ${missing[*]} by hand"; exit 1; }
    sudo_cmd=(sudo)
  fi
  "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  say "all Debian packages present"
fi

configure_and_build() {  # <dir> <cmake args...>
  local dir="$1"
  shift
  cmake -S . -B "$dir" -G Ninja -DSONOTRACE_WERROR=ON "$@" >/dev/null
  say "building in $dir with $jobs jobs"
  cmake --build "$dir" -j "$jobs"
}

if [ "$mode" = sanitize ]; then
  # Not batched (SONOTRACE_UNITY_BUILD=OFF): each file compiles alone, so this build also
  # checks that every file includes what it uses.
  configure_and_build "$build_dir-asan" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSONOTRACE_SANITIZE=ON \
    -DSONOTRACE_BUILD_BENCH=OFF -DSONOTRACE_UNITY_BUILD=OFF
  say "running the test suite under AddressSanitizer + UndefinedBehaviorSanitizer"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir "$build_dir-asan" -j "$jobs" --output-on-failure -LE slow
  # 10 s per target; the hour-long runs behind the figures in docs/reliability.md are
  # `scripts/fuzz.sh 3600`.
  say "fuzzing every input parser for 10 s each (libFuzzer, ASan+UBSan)"
  SONOTRACE_FUZZ_DIR="$build_dir-fuzz" ./scripts/fuzz.sh 10
  say "the sanitizer build's tests and the fuzzers passed"
  exit 0
fi

configure_and_build "$build_dir" -DCMAKE_BUILD_TYPE=Release
# `import sonotrace` from the repository: a link to the Python package in build/python
# (elsewhere: PYTHONPATH=<this repository>/build/python). The module of earlier versions
# (a lone sonotrace*.so) would hide it.
rm -f sonotrace.cpython-*.so "$build_dir"/python/sonotrace.cpython-*.so
[ -d "$build_dir/python/sonotrace" ] && ln -sfn "$build_dir/python/sonotrace" sonotrace

case "$mode" in
  build) ;;
  install)
    prefix="${2:-/usr/local}"
    say "installing under $prefix"
    cmake --install "$build_dir" --prefix "$prefix"
    say "done: $prefix/bin/sonotrace; Python: PYTHONPATH=$prefix/lib/python3/dist-packages"
    ;;
  demo)
    say "running: $build_dir/sonotrace simulate --out out --labels"
    "$build_dir/sonotrace" simulate --out out --labels
    say "done: open out/bmode.png (intraoperative B-mode of the Colin27 head through a craniotomy), out/bmode_labels_preview.png (ground truth) and out/bmode.json"
    ;;
  test)
    say "running the test suite (Release)"
    # The sanitizer build and the fuzzers are `setup.sh sanitize`: on CI's two cores they
    # would more than double this command's time (a clean build with ASan takes longer
    # than the Release build and its tests together).
    ctest --test-dir "$build_dir" -j "$jobs" --output-on-failure
    say "all tests passed"
    ;;
  *)
    echo "usage: $0 [demo|test|sanitize|build|install [PREFIX]]" >&2
    exit 2
    ;;
esac
