#!/usr/bin/env bash
# UI frame rate of sonotrace-gui with live B-mode updates, under Xvfb with Mesa
# (llvmpipe): the probe slides +-15 mm along the surface by itself (--animate), so every
# UI frame asks for a new interactive frame. Prints one JSON record per scene.
#   bench/gui_fps.sh [build-dir] [ui-frames]
set -euo pipefail
build="${1:-build}"
frames="${2:-600}"
for scene in head-craniotomy phantom:cyst_and_stone; do
  xvfb-run -a -s "-screen 0 1600x960x24" "$build/sonotrace-gui" --scene "$scene" --animate \
    --ui-frames "$frames" --json - 2>/dev/null
done
