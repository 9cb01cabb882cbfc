#!/usr/bin/env python3
"""Checks that the libraries' includes point down the stack (docs/architecture.md).

    scripts/check_layers.py [--self-test]

Every #include "..." of a library's sources (tests and benchmarks aside) must name a
header of the same library or of one lower in LAYERS; a header of a library on the same
level (siblings: imaging and phantoms) or above fails, listed with its file. --self-test
checks the checker on made-up includes, one allowed and two that must fail.
"""
import os
import re
import subprocess
import sys

# (folder prefix, library, level): the most specific prefix wins. A library may include
# its own headers and those of libraries on lower levels only.
LAYERS = [
    ("tissue/base/", "sonotrace_base", 0),
    ("tissue/", "sonotrace_tissue", 1),
    ("probe/", "sonotrace_probe", 2),
    ("simulator/", "sonotrace_simulator", 3),
    ("phantoms/", "sonotrace_phantoms", 4),
    ("imaging/", "sonotrace_imaging", 4),
    ("imaging/scene/", "sonotrace_scene", 5),
    ("imaging/dataset/", "sonotrace_dataset", 6),
    ("phantoms/validation/", "sonotrace_validation", 6),
    ("ui/cli/", "sonotrace_ui", 7),
    # The GUI and the Python module still build on the command line's library.
    ("ui/gui/", "sonotrace_gui_core", 8),
    ("ui/python/", "sonotrace_python", 8),
]
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def library(path):
    best = None
    for prefix, name, level in LAYERS:
        if path.startswith(prefix) and (best is None or len(prefix) > len(best[0])):
            best = (prefix, name, level)
    return best


def violations(includes):
    """includes: (file, included header) pairs; returns the ones that point up or sideways."""
    out = []
    for source, header in includes:
        a, b = library(source), library(header)
        if a is None or b is None or a[1] == b[1]:
            continue
        if b[2] >= a[2]:
            out.append(f"{source}: includes {header} ({b[1]}, level {b[2]}) from {a[1]} "
                       f"(level {a[2]})")
    return out


def source_files(root):
    """The repository's C++ files: git's list, or the tree's outside build folders."""
    listed = subprocess.run(["git", "-C", root, "ls-files", "*.h", "*.cpp"],
                            capture_output=True, text=True)
    if listed.returncode == 0 and listed.stdout.strip():
        return listed.stdout.split()
    files = []
    for folder in sorted({prefix.split("/")[0] for prefix, _, _ in LAYERS}):
        for here, _, names in os.walk(os.path.join(root, folder)):
            files += [os.path.relpath(os.path.join(here, n), root) for n in names
                      if n.endswith((".h", ".cpp"))]
    return files


def repository_includes(root):
    files = source_files(root)
    pairs = []
    for f in files:
        if library(f) is None:
            continue
        with open(os.path.join(root, f), encoding="utf-8", errors="replace") as text:
            for line in text:
                m = INCLUDE.match(line)
                if m:
                    pairs.append((f, m.group(1)))
    return pairs


def self_test():
    allowed = [("imaging/bmode.cpp", "simulator/step.h")]
    up = [("probe/beam.cpp", "imaging/psf.h")]
    sideways = [("imaging/bmode.cpp", "phantoms/phantom.h")]
    assert violations(allowed) == [], violations(allowed)
    assert len(violations(up)) == 1 and len(violations(sideways)) == 1
    assert library("imaging/scene/scene.cpp")[1] == "sonotrace_scene"


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    self_test()
    if "--self-test" in sys.argv[1:]:
        print("check_layers: self-test passed")
        return 0
    pairs = repository_includes(root)
    bad = violations(pairs)
    for line in bad:
        print(line, file=sys.stderr)
    if bad:
        print(f"check_layers: {len(bad)} includes point up or sideways", file=sys.stderr)
        return 1
    print(f"check_layers: {len(pairs)} includes, all pointing down")
    return 0


if __name__ == "__main__":
    sys.exit(main())
