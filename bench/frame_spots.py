#!/usr/bin/env python3
"""Issue 52's measures of a head frame, on the grey levels the PNG holds (level x range / 255
dB), over seeds: lone bright spots in the parenchyma and the ventricles' contrast.

    bench/frame_spots.py [--view temporal] [--seeds 16] [--first-seed 1] [--group 4]
                         [--labels true|echo] [--option key=value ...]

Spots: the frame is cut into 1 mm patches; a patch of parenchyma (every pixel brain, 1 mm
clear of any other label: interfaces are not spots) whose level (10 log10 of its mean
intensity) is more than 15 dB above the median level of the parenchyma patches within
5 mm of it (the issue's 10 mm neighbourhood) is a spot. Ventricles: the CSF's connected
components of at least 20 mm^2 (not the thin sulci), eroded by 1 mm, against the
parenchyma eroded by 1 mm, per group of seeds (their frames pooled): as the mean grey
level in dB (what the eye compares) and, in brackets, as mean intensities. Sulci: the
same of the pia-arachnoid's samples (imaging/sulcal_membranes.h: the 0.5 mm band of the
sulcal CSF along the cortex) against the parenchyma. --labels echo measures against the
labels where the echoes show the anatomy (frame.echo_labels) instead of where it lies.
Runs the Python module (SONOTRACE_PYTHON_DIR, default build/python).
"""
import argparse
import os
import sys
from collections import deque

import numpy as np

BRAIN, CSF, PIA = 7, 8, 14  # the labels' legend (the frame's sidecar)


def erode(mask, radius):
    """mask eroded by a disc of `radius` pixels (outside the frame counts as outside)."""
    out = mask.copy()
    h, w = mask.shape
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dx * dx + dy * dy > radius * radius:
                continue
            shifted = np.zeros_like(mask)
            ys, yd = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy), slice(-dy, h))
            xs, xd = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx), slice(-dx, w))
            shifted[yd, xd] = mask[ys, xs]
            out &= shifted
    return out


def large_components(mask, min_pixels):
    """The 4-connected components of `mask` with at least min_pixels pixels."""
    seen = np.zeros_like(mask)
    keep = np.zeros_like(mask)
    h, w = mask.shape
    for y0, x0 in zip(*np.nonzero(mask)):
        if seen[y0, x0]:
            continue
        component, queue = [], deque([(y0, x0)])
        seen[y0, x0] = True
        while queue:
            y, x = queue.popleft()
            component.append((y, x))
            for ny, nx in ((y + 1, x), (y - 1, x), (y, x + 1), (y, x - 1)):
                if 0 <= ny < h and 0 <= nx < w and mask[ny, nx] and not seen[ny, nx]:
                    seen[ny, nx] = True
                    queue.append((ny, nx))
        if len(component) >= min_pixels:
            ys, xs = zip(*component)
            keep[list(ys), list(xs)] = True
    return keep


def measure(frame, dynamic_range_db, pixel_mm, at_echo):
    grey = np.asarray(frame.bmode, dtype=np.float64)
    labels = np.asarray(frame.echo_labels if at_echo else frame.labels)
    intensity = 10.0 ** (grey * dynamic_range_db / 255.0 / 10.0)
    mm = int(round(1.0 / pixel_mm))
    parenchyma = erode(labels == BRAIN, mm)
    ventricles = erode(large_components(labels == CSF, int(20.0 / pixel_mm**2)), mm)
    # 1 mm patches of parenchyma and their levels.
    rows, cols = grey.shape[0] // mm, grey.shape[1] // mm
    level = np.full((rows, cols), np.nan)
    for r in range(rows):
        for c in range(cols):
            block = (slice(r * mm, (r + 1) * mm), slice(c * mm, (c + 1) * mm))
            if parenchyma[block].all():
                level[r, c] = 10.0 * np.log10(intensity[block].mean())
    spots, worst = [], 0.0
    for r, c in zip(*np.nonzero(~np.isnan(level))):
        around = level[max(r - 5, 0):r + 6, max(c - 5, 0):c + 6]
        excess = level[r, c] - np.nanmedian(around)
        worst = max(worst, excess)
        if excess > 15.0:
            spots.append((r * mm, c * mm, excess))
    db = grey * dynamic_range_db / 255.0
    return {
        "ventricles_db": db[ventricles].sum(), "parenchyma_db": db[parenchyma].sum(),
        "sulci_db": db[labels == PIA].sum(), "sulci_pixels": int((labels == PIA).sum()),
        "ventricles": intensity[ventricles].sum(), "ventricle_pixels": int(ventricles.sum()),
        "parenchyma": intensity[parenchyma].sum(), "parenchyma_pixels": int(parenchyma.sum()),
        "patches": int((~np.isnan(level)).sum()), "spots": spots, "worst": worst,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--view", default="craniotomy", help="the head view (simulate --view)")
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--group", type=int, default=4, help="seeds per contrast group")
    parser.add_argument("--labels", choices=("true", "echo"), default="true",
                        help="the label map measured against: the anatomy where it lies, or "
                             "where the echoes show it (frame.echo_labels)")
    parser.add_argument("--option", action="append", default=[],
                        help="another simulate option, key=value (repeatable)")
    args = parser.parse_args()
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path.insert(0, os.environ.get("SONOTRACE_PYTHON_DIR",
                                      os.path.join(here, "..", "build", "python")))
    import sonotrace
    options = dict(kv.split("=", 1) for kv in args.option)
    groups, spots, patches, worst = [], 0, 0, 0.0
    by_depth = {}  # spots by 5 mm band of depth, and how far off the frame's axis (mm)
    group = None
    for k in range(args.seeds):
        seed = args.first_seed + k
        frame = sonotrace.simulate(view=args.view, labels=True, seed=seed, **options)
        image = frame.sidecar["image"]
        m = measure(frame, image["dynamic_range_db"], image["pixel_spacing_mm"][0],
                    args.labels == "echo")
        spots += len(m["spots"])
        pixel = image["pixel_spacing_mm"][0]
        for y, x, _ in m["spots"]:
            depth = image["origin_mm"][1] + y * pixel
            lateral = abs(image["origin_mm"][0] + x * pixel)
            band = by_depth.setdefault(int(depth // 5) * 5, [])
            band.append(lateral / max(depth, 1e-9))
        patches += m["patches"]
        worst = max(worst, m["worst"])
        where = ", ".join(f"({x}, {y}) px +{e:.0f} dB" for y, x, e in m["spots"][:6])
        print(f"seed {seed}: {len(m['spots'])} spots of {m['patches']} patches, "
              f"largest excess {m['worst']:.1f} dB{': ' + where if where else ''}", flush=True)
        if k % args.group == 0:
            group = {"v": 0.0, "vn": 0, "p": 0.0, "pn": 0, "vdb": 0.0, "pdb": 0.0, "sdb": 0.0,
                     "sn": 0, "first": seed}
            groups.append(group)
        group["vdb"] += m["ventricles_db"]
        group["pdb"] += m["parenchyma_db"]
        group["v"] += m["ventricles"]
        group["vn"] += m["ventricle_pixels"]
        group["p"] += m["parenchyma"]
        group["pn"] += m["parenchyma_pixels"]
        group["sdb"] += m["sulci_db"]
        group["sn"] += m["sulci_pixels"]
    for g in groups:
        if g["vn"] and g["pn"]:
            contrast = 10.0 * np.log10((g["v"] / g["vn"]) / (g["p"] / g["pn"]))
            seen = g["vdb"] / g["vn"] - g["pdb"] / g["pn"]
            print(f"seeds {g['first']}-{g['first'] + args.group - 1}: ventricles "
                  f"{seen:+.1f} dB ({contrast:+.1f} dB in intensity) against the parenchyma "
                  f"({g['vn']} and {g['pn']} pixels)")
        if g["sn"] and g["pn"]:
            print(f"seeds {g['first']}-{g['first'] + args.group - 1}: sulci "
                  f"{g['sdb'] / g['sn'] - g['pdb'] / g['pn']:+.1f} dB against the parenchyma "
                  f"({g['sn']} pixels)")
    for depth in sorted(by_depth):
        tangents = by_depth[depth]
        print(f"  {depth:3d}-{depth + 5:3d} mm: {len(tangents):5d} spots, "
              f"median |x| / depth {np.median(tangents):.2f}")
    print(f"{args.view}: {spots} spots over {patches} patches of {args.seeds} frames, "
          f"largest excess {worst:.1f} dB")


if __name__ == "__main__":
    main()
