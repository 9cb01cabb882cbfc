#!/usr/bin/env bash
# `cmake --install` into a temporary prefix, then the installed programs run from a
# directory outside the source tree: a phantom frame, a catalogue phantom by name (trace
# --config fig2), a validation case (its default catalogue), `import sonotrace`, and a C++
# program built against the installed package (tests/package_consumer: find_package).
# Nothing installed may name the source tree: the binaries are searched for its path.
#
#   tests/install_test.sh BUILD_DIR SOURCE_DIR [SANITIZED]
# SANITIZED (ON): the sanitizers record every instrumented file's path in the binary, so
# the search for the source tree is skipped; the runs from the prefix are not.
set -euo pipefail
build="$1" source="$2" sanitized="${3:-OFF}"
prefix="$(mktemp -d)" work="$(mktemp -d)"
trap 'rm -rf "$prefix" "$work"' EXIT
cmake --install "$build" --prefix "$prefix" >/dev/null
cd "$work"
unset SONOTRACE_DATA
fail() { echo "install_test: $*" >&2; exit 1; }

for binary in "$prefix"/bin/* "$prefix"/lib/python3/dist-packages/sonotrace/*.so; do
  [ -e "$binary" ] && [ "$sanitized" != ON ] || continue
  # Debug information names the sources by design; the code and data must not.
  objcopy --strip-debug "$binary" "$work/stripped"
  if grep -q -F "$source" "$work/stripped"; then fail "$binary names the source tree $source"; fi
done
[ ! -e "$prefix/bin/sonotrace-source-dir" ] || fail "the build tree's marker was installed"

phantoms="$prefix/share/sonotrace/phantoms"
"$prefix/bin/sonotrace" simulate -q --phantom "$phantoms/cyst_and_stone.json" --quality interactive \
  --out frame || fail "simulate from the prefix"
[ -s frame/bmode.png ] || fail "no frame"
"$prefix/bin/sonotrace" trace -q --config fig2 --particles 200 --out trace || fail "trace --config fig2"
"$prefix/bin/sonotrace" validate --case critical_angle >/dev/null || fail "validate from the prefix"
# The Python package (not in the sanitizer build: Python cannot load ASan).
if [ "$sanitized" != ON ]; then
  package="$prefix/lib/python3/dist-packages/sonotrace"
  [ -e "$package/__init__.py" ] && [ -e "$package/torch.py" ] && ls "$package"/_sonotrace*.so >/dev/null ||
    fail "the Python package is not installed whole in $package"
  python=python3
  [ -x /usr/bin/python3 ] && python=/usr/bin/python3
  PYTHONPATH="$prefix/lib/python3/dist-packages" "$python" -c "
import sonotrace
frame = sonotrace.simulate(phantom='$phantoms/point_grid.json', quality='interactive', depth=25)
assert frame.bmode.size > 0
" || fail "import sonotrace from the prefix"
fi
# A user's CMake project: headers, libraries and dependencies from the prefix alone.
consumer_build="$work/consumer-build"
cmake -S "$source/tests/package_consumer" -B "$consumer_build" -G Ninja \
  -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null || fail "find_package(sonotrace)"
cmake --build "$consumer_build" >/dev/null || fail "building against the package"
"$consumer_build/consumer" || fail "the C++ program built against the package"
echo "install_test: installed, ran from $prefix" >&2
