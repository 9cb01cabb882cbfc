#!/usr/bin/env bash
# The render guide's comparison of the five depth modes of fused rendering (figure 3 of
# Sakamoto & Koyamada): two intersecting tetrahedra with red and blue colour maps,
# rendered with each --depth-sampling mode and against the fused ray integral.
#   scripts/depth_mode_pictures.sh [build dir]   -> docs/images/depth_modes.png
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-build}/sonotrace"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
font=/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf
inputs=(--volume phantoms/pbvr/red_tetrahedron.vtk --tf phantoms/pbvr/red.json
        --volume phantoms/pbvr/blue_tetrahedron.vtk --tf phantoms/pbvr/blue.json
        --azimuth 30 --elevation 20 --width 256 --height 256 --subpixel 1 --radius-scale 1
        --repetitions 1000 --background 1,1,1 -q)
tiles=()
for mode in cdf entry middle exit random; do
    args=("${inputs[@]}" --depth-sampling "$mode" --out "$tmp/$mode.png" --json "$tmp/$mode.json")
    [ "$mode" = cdf ] && args+=(--reference "$tmp/reference.png" --reference-step 0.005)
    "$bin" render "${args[@]}"
    tiles+=("$tmp/$mode.png" "--text:x=8:y=22:size=18:color=0,0,0:font=$font" "$mode")
done
oiiotool "$tmp/reference.png" "--text:x=8:y=22:size=18:color=0,0,0:font=$font" "reference" \
    "${tiles[@]}" --mosaic 3x2 -o docs/images/depth_modes.png
echo "wrote docs/images/depth_modes.png"
