#!/usr/bin/env python3
"""Paired A/B comparison of two Google Benchmark binaries on a noisy machine.

Runs the two binaries back to back, one benchmark each time, swapping the order every
pair (A B, B A, A B, ...), and prints the per-pair ratio B/A of a rate counter and its
median. Slow drifts of the machine's speed then cancel within a pair.

    bench/abba.py OLD_BINARY NEW_BINARY PAIRS [FILTER] [--counter steps/s] [--min-time 0.3]

`--counter time` compares the benchmark's own time per iteration instead (as a rate,
iterations per second: a ratio above 1 is faster).

Bench commands that print a JSON line instead (bench_pbvr): `--json FIELD` takes FIELD of
the last JSON line the binary prints, run with the arguments `--args` gives; a field in
milliseconds or seconds (`ms_...`, `..._s`) is a time and compared as its inverse.

    bench/abba.py OLD/bench_pbvr NEW/bench_pbvr 8 --json ms_per_repetition_median \\
        --args "repetitions 12"
"""
import argparse
import json
import shlex
import re
import statistics
import subprocess


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("a", help="the earlier binary (A)")
    parser.add_argument("b", help="the later binary (B)")
    parser.add_argument("pairs", type=int, help="number of pairs")
    parser.add_argument("filter", nargs="?", default="Trace3D_Colin27",
                        help="--benchmark_filter (one benchmark)")
    parser.add_argument("--counter", default="steps/s", help="rate counter to compare")
    parser.add_argument("--min-time", default="0.3", help="--benchmark_min_time, seconds")
    parser.add_argument("--json", metavar="FIELD",
                        help="compare FIELD of the last JSON line of a bench command")
    parser.add_argument("--args", default="", help="with --json: the bench command's arguments")
    args = parser.parse_args()
    pattern = re.compile(re.escape(args.counter) + r"=([0-9.]+)([kMG]?)")
    scale = {"": 1.0, "k": 1e3, "M": 1e6, "G": 1e9}

    def json_rate(binary):
        out = subprocess.run([binary] + shlex.split(args.args), capture_output=True, text=True,
                             check=True).stdout
        lines = [line for line in out.splitlines() if line.startswith("{")]
        if not lines or args.json not in json.loads(lines[-1]):
            raise SystemExit(f"{binary}: no JSON line with '{args.json}'")
        value = float(json.loads(lines[-1])[args.json])
        is_time = args.json.startswith("ms_") or args.json.endswith("_s")
        return 1.0 / value if is_time else value

    def rate(binary):
        if args.json:
            return json_rate(binary)
        out = subprocess.run([binary, "--benchmark_filter=" + args.filter,
                              "--benchmark_min_time=" + args.min_time],
                             capture_output=True, text=True, check=True).stdout
        if args.counter == "time":  # "<name> <time> <unit> <cpu> <unit> <iterations>"
            units = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
            for line in out.splitlines():
                fields = line.split()
                if len(fields) >= 3 and fields[2] in units:
                    return 1.0 / (float(fields[1]) * units[fields[2]])
            raise SystemExit(f"{binary}: no time for '{args.filter}'")
        match = pattern.search(out)
        if not match:
            raise SystemExit(f"{binary}: no '{args.counter}' counter for '{args.filter}'")
        return float(match.group(1)) * scale[match.group(2)]

    def shown(value):  # with the counter's own prefix: 43.2 M steps/s, 15.3 frames/s
        if args.json:  # the field as printed (a time, not its inverse)
            is_time = args.json.startswith("ms_") or args.json.endswith("_s")
            return f"{1.0 / value if is_time else value:11.4g}"
        for prefix, factor in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
            if value >= factor:
                return f"{value / factor:9.2f} {prefix}"
        return f"{value:9.2f}  "

    a_rates, b_rates, ratios = [], [], []
    for pair in range(args.pairs):
        first_a = pair % 2 == 0
        first = rate(args.a if first_a else args.b)
        second = rate(args.b if first_a else args.a)
        a, b = (first, second) if first_a else (second, first)
        a_rates.append(a)
        b_rates.append(b)
        ratios.append(b / a)
        print(f"{shown(a)} {shown(b)}  ratio {b / a:.3f}", flush=True)
    print(f"median A {shown(statistics.median(a_rates))}, B {shown(statistics.median(b_rates))},"
          f" median ratio {statistics.median(ratios):.3f} (mean {statistics.mean(ratios):.3f},"
          f" {min(ratios):.3f}-{max(ratios):.3f}) over {args.pairs} pairs")


if __name__ == "__main__":
    main()
