#!/bin/sh
# Renders the README's B-mode pictures into docs/images/: the default frame and the
# temporal view (through the skull) beside their ground truth, the temporal view to the
# far skull, the point-target grid, the radial array and frames of the example dataset at
# its 128 x 128 pixels. Usage: scripts/readme_pictures.sh [build-dir]
set -eu
build=${1:-build}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# The default frame (grey, as three channels) beside the colour preview of its labels.
"$build/sonotrace" simulate -q --labels --out "$tmp/default"
oiiotool "$tmp/default/bmode.png" --ch 0,0,0 "$tmp/default/bmode_labels_preview.png" \
    --mosaic:pad=8 2x1 -o docs/images/bmode-default.png
# The temporal view: the phased probe on the right temple, imaging through the skull
# (the view's gain, scene::kTemporalGainDb); and to 175 mm, the far
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
# The example dataset's first four frames (128 x 128, as a network sees them), each pixel
# drawn as 2 x 2 so that the pixels show.
"$build/sonotrace" dataset -q phantoms/datasets/example.json --out "$tmp/dataset"
python3 - "$tmp/dataset/shard_00000.h5" "$tmp/frame" <<'PY'
import sys
import h5py
with h5py.File(sys.argv[1], "r") as f:
    for i, grey in enumerate(f["bmode"][:4]):  # uint8 grey levels
        with open(f"{sys.argv[2]}{i}.pgm", "wb") as out:
            out.write(b"P5 %d %d 255\n" % (grey.shape[1], grey.shape[0]) + grey.tobytes())
PY
oiiotool "$tmp/frame0.pgm" "$tmp/frame1.pgm" "$tmp/frame2.pgm" "$tmp/frame3.pgm" \
    --mosaic:pad=4 4x1 --resample 1048x264 --ch 0,0,0 -o docs/images/dataset-frames.png
# The randomised dataset's first eight frames (docs/guide/dataset.md): frequency, F-number,
# TGC, receiver noise and tissue properties drawn per frame.
"$build/sonotrace" dataset -q phantoms/datasets/randomised.json --out "$tmp/randomised"
python3 - "$tmp/randomised/shard_00000.h5" "$tmp/random" <<'PY'
import sys
import h5py
with h5py.File(sys.argv[1], "r") as f:
    for i, grey in enumerate(f["bmode"][:8]):
        with open(f"{sys.argv[2]}{i}.pgm", "wb") as out:
            out.write(b"P5 %d %d 255\n" % (grey.shape[1], grey.shape[0]) + grey.tobytes())
PY
oiiotool "$tmp"/random[0-7].pgm --mosaic:pad=4 4x2 --resample 1044x524 --ch 0,0,0 \
    -o docs/images/dataset-randomised.png
# The ground truth --labels writes beside a frame of the mesh abdomen: the frame, the true
# depth of what each pixel shows (0-200 mm as black to white), its echogenicity (0-1) and
# the shape instances (each index a grey step).
"$build/sonotrace" simulate -q --phantom phantoms/abdomen_meshes.json --labels --out "$tmp/truth"
oiiotool "$tmp/truth/bmode_depth.exr" --mulc 0.005 --ch 0,0,0 -d uint8 -o "$tmp/depth.png"
oiiotool "$tmp/truth/bmode_echogenicity.exr" --ch 0,0,0 -d uint8 -o "$tmp/echo.png"
oiiotool "$tmp/truth/bmode_instances.png" --mulc 6000 --ch 0,0,0 -d uint8 -o "$tmp/instances.png"
oiiotool "$tmp/truth/bmode.png" --ch 0,0,0 "$tmp/depth.png" "$tmp/echo.png" "$tmp/instances.png" \
    --mosaic:pad=8 4x1 --resize 1200x0 -o docs/images/truth-maps.png
