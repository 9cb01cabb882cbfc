#!/usr/bin/env python3
"""sonotrace.Scene's frames against `sonotrace dataset`'s (issue 54's criteria):

1. frames/s of scene.frame(...) in a Python loop over new poses against frames/s of
   `sonotrace dataset` for the same frames (the poses, gains and seeds of the dataset's
   frame table), each rate per frame with the fixed costs (process start, scene load, the
   first frame's tables) removed: the dataset's as N / (T(2N) - T(N)) over two runs,
   Python's timed around the loop alone. Target: Python at least 90 % of the dataset's rate.
2. The first frame of a freshly loaded Scene against the next ones, each with a new seed
   (a training loop's frames: new beams, new speckle): the median over fresh processes of
   first / median(later). Seeds differ in cost (their paths), so process k starts at its
   own seed and every seed is once a first frame. Target: at most 1.10.

    PYTHONPATH=build/python python3 bench/scene_frames.py [--frames 48] [--processes 7]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

SOURCE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BINARY = os.environ.get("SONOTRACE_BINARY", os.path.join(SOURCE, "build", "sonotrace"))
PHANTOM = os.path.join(SOURCE, "phantoms", "cyst_and_stone.json")


def spec(frames):
    return {"frames": frames, "frames_per_shard": frames, "seed": 5,
            "image": {"width": 128, "height": 128},
            "sources": [{"phantom": PHANTOM}], "gain_db": [36, 48],
            "pose": {"lateral_mm": 4, "rotation_deg": 5}, "quality": "interactive",
            "write": ["bmode"]}


def run_dataset(directory, frames):
    path = os.path.join(directory, "spec%d.json" % frames)
    with open(path, "w") as f:
        json.dump(spec(frames), f)
    out = os.path.join(directory, "out%d" % frames)
    start = time.perf_counter()
    subprocess.run([BINARY, "dataset", path, "--out", out, "-q"], check=True)
    return time.perf_counter() - start, out


def pose_text(row):
    p, beam, lateral = row["position"], row["axial"], row["lateral"]
    numbers = lambda v: ",".join(repr(float(x)) for x in v)  # noqa: E731
    return "at=%s beam=%s lateral=%s" % (numbers(p), numbers(beam), numbers(lateral))


FIRST_FRAME = r"""
import sys, time, json, statistics
import sonotrace
scene = sonotrace.Scene(phantom=sys.argv[1], quality="interactive")
times = []
first = int(sys.argv[2])
for seed in range(first, first + 9):
    start = time.perf_counter()
    scene.frame(seed=seed)
    times.append(time.perf_counter() - start)
print(json.dumps(times))
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--processes", type=int, default=7)
    args = parser.parse_args()
    import h5py
    import sonotrace
    with tempfile.TemporaryDirectory() as directory:
        few, out = run_dataset(directory, args.frames)
        many, _ = run_dataset(directory, 2 * args.frames)
        dataset_rate = args.frames / (many - few)
        with h5py.File(os.path.join(out, "shard_00000.h5"), "r") as f:
            rows = f["frames"][:]
        scene = sonotrace.Scene(phantom=PHANTOM, quality="interactive",
                                pixel=float(rows["pixel_mm"][0]))
        start = time.perf_counter()
        for row in rows:
            scene.frame(pose=pose_text(row), gain=float(row["gain_db"]), seed=int(row["seed"]))
        python_rate = len(rows) / (time.perf_counter() - start)
    print("dataset: %d frames in %.2f s, %d in %.2f s: %.2f frames/s" %
          (2 * args.frames, many, args.frames, few, dataset_rate))
    print("Scene.frame loop: %.2f frames/s = %.3f of the dataset's (target >= 0.90)" %
          (python_rate, python_rate / dataset_rate))
    ratios = []
    for k in range(args.processes):
        result = subprocess.run([sys.executable, "-c", FIRST_FRAME, PHANTOM, str(3 + 9 * k)],
                                check=True,
                                capture_output=True, text=True, env=os.environ)
        times = json.loads(result.stdout)
        ratios.append(times[0] / statistics.median(times[1:]))
    print("first frame / later frames (median over %d processes): %.3f (%s; target <= 1.10)"
          % (args.processes, statistics.median(ratios), ", ".join("%.2f" % r for r in ratios)))


if __name__ == "__main__":
    main()
