#!/usr/bin/env bash
# A PICMUS-like acquisition (phantoms/picmus.json, the PICMUS probe): 75 plane waves over
# +-16 degrees, their channel data written (--channels) and beamformed, on all cores.
# Prints one JSON record per run: wall seconds, peak RSS, and the frame's stage timings.
#   bench/channel_frames.sh [build-dir] [runs]
set -euo pipefail
build="${1:-build}"
runs="${2:-3}"
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
for ((k = 0; k < runs; ++k)); do
  /usr/bin/time -f '%e %M' -o "$out/time" "$build/sonotrace" simulate -q \
    --phantom "$(dirname "$0")/../phantoms/picmus.json" --transmit plane:-16:16:75 --channels \
    --out "$out" --name picmus
  read -r wall rss < "$out/time"
  /usr/bin/python3 -c "
import json, sys
r = json.load(open('$out/picmus.json'))
t = r['timings_s']
print(json.dumps({'wall_s': $wall, 'peak_rss_mb': round($rss / 1024),
                  'channels_mb': round(4 * 75 * 128 * r['transmit']['channels']['samples'] / 2**20),
                  'stages_s': {k: round(v, 2) for k, v in t.items()}}))"
done
