#!/bin/sh
# Renders one B-mode picture per catalogue phantom into docs/images/phantoms/ (the pictures
# of phantoms/README.md). Usage: scripts/phantom_pictures.sh [build-dir]
set -eu
build=${1:-build}
out=docs/images/phantoms
mkdir -p "$out"
render() {  # name, extra simulate options
    name=$1
    shift
    "$build/sonotrace" simulate -q --phantom "phantoms/$name.json" "$@" \
        --out "$out/.tmp-$name"
    mv "$out/.tmp-$name/bmode.png" "$out/$name.png"
    rm -rf "$out/.tmp-$name"
}
# Linear 7.6 MHz phantoms: soft tissue or liver, TGC for ~0.5 dB/(cm MHz), gain for mid-grey.
render cyst_and_stone --quality high --depth 50 --gain 56 --tgc 0:0,50:38
render parallel_plates --quality high --depth 40 --gain 20 --tgc none
render mirror --quality high --depth 50 --gain 56 --tgc 0:0,50:38
render speed_layer --quality high --depth 40 --gain 56 --tgc 0:0,40:33
render refraction --quality high --depth 45 --gain 56 --tgc 0:0,45:37
render qa_multipurpose --quality high --depth 60 --gain 56 --tgc 0:0,60:49
# Convex 3.5 MHz abdomen.
render abdominal --depth 150 --quality standard --gain 50 --tgc 0:0,150:55
# Organs from surface meshes (phantoms/meshes/), convex 3.5 MHz.
render abdomen_meshes
