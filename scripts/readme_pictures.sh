#!/bin/sh
# Renders the README's B-mode pictures into docs/images/: the default frame and the
# temporal view (through the skull) beside their ground truth, the temporal view to the
# far skull, the point-target grid and the radial array. Usage: scripts/readme_pictures.sh [build-dir]
set -eu
build=${1:-build}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# The default frame (grey, as three channels) beside the colour preview of its labels.
"$build/sonotrace" simulate -q --labels --out "$tmp/default"
oiiotool "$tmp/default/bmode.png" --ch 0,0,0 "$tmp/default/bmode_labels_preview.png" \
    --mosaic:pad=8 2x1 -o docs/images/bmode-default.png
# The temporal view: the phased probe on the right temple, imaging through the skull
# (the view's gain, 60 dB: the skull costs about 27 dB two-way); and to 175 mm, the far
# side of the skull.
"$build/sonotrace" simulate -q --labels --view temporal --out "$tmp/temporal"
oiiotool "$tmp/temporal/bmode.png" --ch 0,0,0 "$tmp/temporal/bmode_labels_preview.png" \
    --mosaic:pad=8 2x1 -o docs/images/bmode-temporal.png
"$build/sonotrace" simulate -q --view temporal --depth 175 --out "$tmp/far"
cp "$tmp/far/bmode.png" docs/images/bmode-temporal-175.png
# 0.1 mm wires (phantoms/point_grid.json): the two-way PSF across depth and width.
"$build/sonotrace" simulate -q --phantom phantoms/point_grid.json --quality high --depth 64 \
    --pixel 0.1 --gain 34 --out "$tmp/points"
cp "$tmp/points/bmode.png" docs/images/bmode-point-grid.png
# The radial array (probe/arrays/radial.cpp) in phantoms/radial_ring.json: wires, a cyst
# and a vessel all around the 12 mm tip, beside the labels.
"$build/sonotrace" simulate -q --phantom phantoms/radial_ring.json --labels --out "$tmp/radial"
oiiotool "$tmp/radial/bmode.png" --ch 0,0,0 "$tmp/radial/bmode_labels_preview.png" \
    --mosaic:pad=8 2x1 -o docs/images/bmode-radial.png
