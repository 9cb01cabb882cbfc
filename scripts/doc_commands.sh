#!/usr/bin/env bash
# Runs every command shown in the README's and the guides' ```sh blocks, as written, from a
# scratch copy of the checkout's layout (its own out/), so the documentation cannot name
# files we do not ship or options we do not have. A test runs it.
#
#   scripts/doc_commands.sh [BUILD_DIR] [FILES...]   # defaults: build, README.md docs/guide/*.md
#
# Not run, by kind: the set-up script (the test command itself is `setup.sh test`), the
# build commands (cmake, ctest: the build that runs this did them), the picture scripts
# (they rewrite docs/images), the whole validation suite (each case is a ctest). The GUI
# runs headless under xvfb-run (--screenshot) until it has shown two frames. ```python
# blocks run as one script each, after the commands before them, with Debian's python3
# (h5py, numpy).
set -euo pipefail
cd "$(dirname "$0")/.."
root="$PWD"
build="$(cd "${1:-build}" && pwd)"
shift || true
files=("$@")
[ ${#files[@]} -gt 0 ] || files=(README.md docs/guide/*.md)

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
for entry in "$root"/*; do
  [ "$(basename "$entry")" = build ] || ln -s "$entry" "$scratch/$(basename "$entry")"
done
ln -s "$build" "$scratch/build"

# The commands of the ```sh blocks, continuation lines joined, one per line; a ```python
# block becomes one line "python: <its lines joined by \x1f>".
commands() {
  awk '/^```sh$/ {inside = 1; next} /^```python$/ {python = 1; script = ""; next}
       /^```/ { if (python) print "python: " script; inside = 0; python = 0; next }
       python { script = script $0 "\x1f"; next }
       inside { if (sub(/\\$/, "")) { held = held $0; next } print held $0; held = "" }' "$1"
}
python="python3"
[ -x /usr/bin/python3 ] && python=/usr/bin/python3

failed=0 ran=0
for file in "${files[@]}"; do
  while IFS= read -r command; do
    trimmed="${command#"${command%%[![:space:]]*}"}"
    case "$trimmed" in
      "" | "#"*) continue ;;
      ./scripts/setup.sh* | cmake* | ctest*) continue ;;
      scripts/*pictures.sh*) continue ;;
      build/sonotrace-gui*)
        if [[ "$trimmed" != *--help* ]]; then
          command -v xvfb-run >/dev/null && [ -x "$build/sonotrace-gui" ] || continue
          trimmed="xvfb-run -a ${trimmed%%#*} --screenshot out/doc-gui.png --frames 2"
        fi ;;
      build/*)
        # Every validation case is a ctest of its own; the whole suite again here would
        # add half a minute to the test command and test nothing new.
        [[ "${trimmed%%#*}" =~ ^build/sonotrace\ validate\ *$ ]] && continue ;;
      mpirun\ *)
        command -v mpirun >/dev/null || continue
        # Open MPI refuses root without these; a user's shell has them or is not root.
        trimmed="OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 $trimmed" ;;
      "python: "*)
        printf '%s' "${trimmed#python: }" | tr '\037' '\n' >"$scratch/block.py"
        # The module of this build, whether or not the set-up script linked it.
        trimmed="PYTHONPATH=$build/python $python block.py" ;;
      *) echo "doc_commands: $file: a command of no known kind: $trimmed" >&2
         failed=$((failed + 1)); continue ;;
    esac
    ran=$((ran + 1))
    if ! (cd "$scratch" && bash -c "$trimmed") >"$scratch/log" 2>&1 </dev/null; then
      echo "doc_commands: $file: failed: $trimmed" >&2
      tail -n 5 "$scratch/log" >&2
      failed=$((failed + 1))
    fi
  done < <(commands "$file")
done
echo "doc_commands: ran $ran commands, $failed failed" >&2
[ "$failed" = 0 ]
