#!/usr/bin/env bash
# The GUI screenshots of the README and docs/guide/gui.md, under Xvfb (Mesa):
#   scripts/gui_pictures.sh [build-dir]
set -euo pipefail
build="${1:-build}"
shot() {  # NAME ARGS...
  local name="$1"
  shift
  xvfb-run -a -s "-screen 0 1600x960x24" "$build/sonotrace-gui" --size 1600x960 "$@" \
    --screenshot "docs/images/$name.png" 2>/dev/null
  rm -f "docs/images/$name.json"
}
shot gui_head --frames 3
shot gui_temporal --scene head-temporal --frames 3 --explain "depth attenuation and TGC"
shot gui_volume --scene /usr/share/mricron/templates/ch2.nii.gz --tf mri-t1-head --probe convex \
  --frames 2 --context-renderer gpu
shot gui_mirror --scene phantom:mirror --frames 3
shot gui_explain --scene phantom:cyst_and_stone --explain "acoustic shadowing" --frames 3
shot gui_meshes --scene phantom:abdomen_meshes --frames 3
