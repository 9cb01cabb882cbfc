#!/usr/bin/env python3
"""Fuzzes what the Python module takes from its user: keyword arguments
(`sonotrace.sweep(**keywords)` checks them and prepares the run exactly as `simulate`
does, without drawing a frame; `Scene.frame(**keywords)` on a loaded scene, drawing the
frame when they are sound) and shard files (`sonotrace.read_shard`, on mutations of
real shards; half of them sealed with a sound header over the mutated bytes, so that they
pass the checksum and reach h5py). Every call must return or raise sonotrace.InputError:
any other exception, a hang, or the interpreter's death is a finding, reported with the
case that caused it (kept in DIR/crashes).

  tests/fuzz/fuzz_python.py --cases 300 --seed 1     # what ctest runs (python.fuzz)
  tests/fuzz/fuzz_python.py --seconds 3600           # an hour (docs/reliability.md)

Needs SONOTRACE_BINARY, SONOTRACE_SOURCE_DIR and SONOTRACE_PYTHON_DIR (ctest sets them).
The cases run in a child interpreter so that its death is seen and reported."""
import argparse
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time

BINARY = os.environ["SONOTRACE_BINARY"]
SOURCE = os.environ["SONOTRACE_SOURCE_DIR"]
CYST = SOURCE + "/phantoms/cyst_and_stone.json"
STRINGS = ["", "%s%s%s%s%n", "%99999999d.png", "x" * 5000, "\0", "a\0b", "../../etc/passwd",
           "/dev/zero", "/dev/null", "nan", "inf", "-inf", "1e309", "-1", "0", "3",
           "18446744073709551616", "1,2", "1,2,3", ",", ";", "linear", "convex", "phased",
           "radial", "interactive", "standard", "high", "head-craniotomy", "temporal",
           "lateral:4:1", "lateral:1e9:1", "axial:-3:0.5", "attenuation,speckle",
           "\u2603", "0x10", " 5", "5 ", "--seed", "-q", "True", CYST, SOURCE, SOURCE + "/phantoms"]
NUMBERS = [0, 1, -1, 2, 3, 20, 40, 2 ** 31, 2 ** 63, 2 ** 64, -2 ** 63, 10 ** 30, 1e23, 0.5,
           -0.0, float("nan"), float("inf"), -float("inf"), 1e-320, 1e308]


def option_names():
    """The options of `sonotrace simulate`, from its own --help."""
    text = subprocess.run([BINARY, "simulate", "--help"], capture_output=True, text=True).stdout
    names = sorted(set(re.findall(r"--([a-z][a-z0-9-]*)", text)) - {"help"})
    return [n.replace("-", "_") for n in names]


def a_value(rng, extra_strings):
    kind = rng.random()
    if kind < 0.35:
        return rng.choice(STRINGS + extra_strings)
    if kind < 0.65:
        return rng.choice(NUMBERS)
    if kind < 0.75:
        return rng.choice([True, False])
    if kind < 0.85:
        items = [a_value(rng, extra_strings) for _ in range(rng.randrange(0, 4))]
        return items if rng.random() < 0.5 else tuple(items)
    if kind < 0.9:
        return None
    if kind < 0.95:
        return {"a": 1}
    return b"\xff\x00bytes"


def keyword_case(rng, names, extra_strings):
    keywords = {}
    if rng.random() < 0.8:  # mostly a quick phantom, so that valid runs stay fast
        keywords = {"phantom": CYST, "quality": "interactive", "depth": 30, "focus": 20}
    for _ in range(rng.randrange(1, 4)):
        keywords[rng.choice(names)] = a_value(rng, extra_strings)
    if rng.random() < 0.03:
        keywords[rng.choice(["colour", "x" * 300, "seed\0", "_", "--seed"])] = 1
    return keywords


def mutate(rng, data):
    data = bytearray(data)
    for _ in range(rng.randrange(1, 4)):
        op = rng.randrange(6)
        at = rng.randrange(len(data)) if data else 0
        if op == 0:  # flip bytes
            for _ in range(rng.randrange(1, 17)):
                if data:
                    data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif op == 1:  # truncate
            del data[at:]
        elif op == 2:  # insert
            data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
        elif op == 3:  # a copied chunk
            n = rng.randrange(1, 512)
            src = rng.randrange(max(1, len(data)))
            data[at:at + n] = data[src:src + n]
        elif op == 4:  # zeros or 0xff over a range
            n = rng.randrange(1, 256)
            data[at:at + n] = bytes([rng.choice([0, 255])]) * n
        else:  # a boundary value in a little-endian 8-byte field
            value = rng.choice([0, 1, 2 ** 31, 2 ** 32 - 1, 2 ** 63, 2 ** 64 - 1])
            data[at:at + 8] = value.to_bytes(8, "little")
    return bytes(data)


def child(args):
    # The cases run under a cap on their address space: a case that asks for gigabytes is a
    # finding (MemoryError), not a machine the kernel's OOM killer must rescue (a shard
    # whose layout made HDF5 allocate 22 GB took other processes with it).
    import resource
    cap = 8 << 30
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    sys.path.insert(0, os.environ["SONOTRACE_PYTHON_DIR"])
    sys.path.insert(0, SOURCE + "/tests/python")
    import sonotrace
    from shard_seal import sealed

    work = args.work
    fifo = os.path.join(work, "fifo")
    os.mkfifo(fifo)
    extra = [fifo, work]
    spec = {"frames": 3, "frames_per_shard": 2, "seed": 1, "image": {"width": 24, "height": 20},
            "sources": [{"phantom": CYST}], "transducer": {"depth": 25, "focus": 20},
            "quality": "interactive", "write": ["bmode", "labels", "envelope"]}
    with open(os.path.join(work, "spec.json"), "w") as f:
        json.dump(spec, f)
    subprocess.run([BINARY, "dataset", os.path.join(work, "spec.json"), "--out",
                    os.path.join(work, "dataset"), "-q"], check=True)
    shards = [open(os.path.join(work, "dataset", f"shard_0000{k}.h5"), "rb").read()
              for k in range(2)]
    names = option_names()
    scene = sonotrace.Scene(phantom=CYST, quality="interactive", depth=30, focus=20)
    rng = random.Random(args.seed)
    deadline = time.time() + args.seconds if args.seconds else None
    counts = {"keywords": 0, "scene": 0, "shards": 0, "accepted": 0, "refused": 0}
    case_file = os.path.join(work, "case")
    n = 0
    while (deadline is None and n < args.cases) or (deadline is not None and time.time() < deadline):
        n += 1
        kind = rng.random()
        if kind < 0.15:
            keywords = {}
            for _ in range(rng.randrange(1, 4)):
                keywords[rng.choice(names)] = a_value(rng, extra)
            with open(case_file, "w") as f:
                f.write("sonotrace.Scene(phantom=CYST, quality='interactive', depth=30, "
                        "focus=20).frame(**" + repr(keywords) + ")\n")
            call = lambda: scene.frame(**keywords)  # noqa: E731
            counts["scene"] += 1
        elif kind < 0.5:
            keywords = keyword_case(rng, names, extra)
            with open(case_file, "w") as f:
                f.write("sonotrace.sweep(**" + repr(keywords) + ")\n")
            call = lambda: sonotrace.sweep(**keywords)  # noqa: E731
            counts["keywords"] += 1
        else:
            data = mutate(rng, rng.choice(shards))
            if rng.random() < 0.5:
                data = sealed(data[512:], 0, 0)
            path = os.path.join(work, "case.h5")
            with open(path, "wb") as f:
                f.write(data)
            with open(case_file, "w") as f:
                f.write("sonotrace.read_shard(<the file case.h5 beside this one>)\n")
            call = lambda: sonotrace.read_shard(path)  # noqa: E731
            counts["shards"] += 1
        try:
            call()
            counts["accepted"] += 1
        except sonotrace.InputError:
            counts["refused"] += 1
        except Exception as e:  # a finding: not the module's error type
            with open(case_file, "a") as f:
                f.write(f"raised {type(e).__name__}: {e}\n")
            print(f"finding: {type(e).__name__}: {e}", file=sys.stderr)
            return 1
    print(json.dumps(dict(counts, cases=n)))
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=300)
    parser.add_argument("--seconds", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--crashes", default="build-fuzz/crashes")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--work", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args)
    with tempfile.TemporaryDirectory(prefix="sonotrace-fuzz-python-") as work:
        command = [sys.executable, __file__, "--child", "--work", work, "--seed", str(args.seed),
                   "--cases", str(args.cases), "--seconds", str(args.seconds)]
        limit = (args.seconds or 2.0 * args.cases) + 300
        started = time.time()
        try:
            run = subprocess.run(command, capture_output=True, text=True, timeout=limit)
            status, out, err = run.returncode, run.stdout, run.stderr
        except subprocess.TimeoutExpired as e:
            status, out, err = "hang", e.stdout or "", e.stderr or ""
        if status == 0:
            print(f"python: {out.strip()} in {time.time() - started:.0f} s, no finding")
            return 0
        how = (f"killed by signal {signal.Signals(-status).name}" if isinstance(status, int) and
               status < 0 else f"exit {status}")
        os.makedirs(args.crashes, exist_ok=True)
        kept = os.path.join(args.crashes, f"python-seed{args.seed}")
        os.makedirs(kept, exist_ok=True)
        for name in ["case", "case.h5"]:
            if os.path.exists(os.path.join(work, name)):
                with open(os.path.join(work, name), "rb") as src:
                    open(os.path.join(kept, name), "wb").write(src.read())
        case = open(os.path.join(kept, "case")).read() if os.path.exists(
            os.path.join(kept, "case")) else "?"
        print(f"python: FINDING ({how}); the case, kept in {kept}:\n{case}\n{err[-3000:]}",
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
