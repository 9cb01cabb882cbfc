#!/usr/bin/env python3
"""Checks that the libraries' includes point down the stack (docs/architecture.md).

    scripts/check_layers.py [--self-test]

Every #include "..." of a library's sources (tests and benchmarks aside) must name a
header of the same library or of one lower in LAYERS; a header of a library on the same
level (siblings: imaging and phantoms) or above fails, listed with its file, and so does
an include from a folder of the design card into one after it (FOLDERS). The tests of a
module (tests/<folder>/, TEST_FOLDERS) link that module's library only and include nothing
above it. --self-test checks the checker on made-up includes and tests, some allowed and
some that must fail.
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
    ("imaging/", "sonotrace_imaging", 4),
    ("phantoms/", "sonotrace_phantoms", 4),
    ("phantoms/scene/", "sonotrace_scene", 5),
    ("phantoms/validation/", "sonotrace_validation", 6),
    ("ui/dataset/", "sonotrace_dataset", 6),
    # PBVR in OpenGL: imaging's particles drawn by the GUI and the command line.
    ("ui/gl/", "sonotrace_gl_pbvr", 5),
    ("ui/cli/", "sonotrace_ui", 7),
    # The GUI and the Python module fill frame requests themselves: they sit beside the
    # command line, not on it.
    ("ui/gui/", "sonotrace_gui_core", 7),
    ("ui/python/", "sonotrace_python", 7),
]
# The design card's folders in the same order: a folder's code includes nothing from a
# folder after it (so no library under imaging/ reaches into phantoms/ or ui/).
FOLDERS = ["tissue", "probe", "simulator", "imaging", "phantoms", "ui"]
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')
# Test folders and the one library the tests in each link (tests/CMakeLists.txt's
# sonotrace_test): a module's tests show what the module itself needs. The command line's
# run the binary and read its files.
TEST_FOLDERS = {
    "tissue": "sonotrace_tissue",
    "probe": "sonotrace_probe",
    "simulator": "sonotrace_simulator",
    "imaging": "sonotrace_imaging",
    "phantoms": "sonotrace_phantoms",
    "scene": "sonotrace_scene",
    "validation": "sonotrace_validation",
    "dataset": "sonotrace_dataset",
    "cli": "sonotrace_ui",
    "gui": "sonotrace_gui_core",
    "gl": "sonotrace_gl_pbvr",
}
TEST_RULE = re.compile(r"sonotrace_test\((\w+)\s+\w+\s+MODULES\s+([\w\s]+?)\s+SOURCES\s+([^)]+)\)")


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
        folder_a, folder_b = source.split("/")[0], header.split("/")[0]
        if FOLDERS.index(folder_b) > FOLDERS.index(folder_a):
            out.append(f"{source}: includes {header} from the folder {folder_b}/, which "
                       f"comes after {folder_a}/")
            continue
        if b[2] >= a[2]:
            out.append(f"{source}: includes {header} ({b[1]}, level {b[2]}) from {a[1]} "
                       f"(level {a[2]})")
    return out


def test_violations(cmake_text, includes_of):
    """cmake_text: tests/CMakeLists.txt; includes_of(test source) -> its included headers.
    Returns the tests that link another library than their folder's, or include a header
    of a library on the same level or above it."""
    levels = {name: level for _, name, level in LAYERS}
    out = []
    for name, modules, sources in TEST_RULE.findall(cmake_text):
        modules, sources = modules.split(), sources.split()
        folders = sorted({source.split("/")[0] for source in sources})
        if len(folders) != 1 or folders[0] not in TEST_FOLDERS:
            out.append(f"tests/CMakeLists.txt: {name}: its sources must lie in one of the "
                       f"folders {', '.join(TEST_FOLDERS)}, not {', '.join(folders)}")
            continue
        own = TEST_FOLDERS[folders[0]]
        if modules != [own]:
            out.append(f"tests/CMakeLists.txt: {name} (tests/{folders[0]}/) links "
                       f"{' '.join(modules)}; it must link {own} only")
        for source in sources:
            for header in includes_of(source):
                b = library(header)
                if b is not None and b[1] != own and b[2] >= levels[own]:
                    out.append(f"tests/{source}: includes {header} ({b[1]}, level {b[2]}), "
                               f"not below {own} (level {levels[own]})")
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
    # Allowed by the levels alone (7 over 5), refused by the folders' order.
    LAYERS.append(("imaging/made_up/", "made_up", 7))
    up_the_folders = [("imaging/made_up/x.cpp", "phantoms/scene/scene.h")]
    assert len(violations(up_the_folders)) == 1, violations(up_the_folders)
    LAYERS.pop()
    assert violations(allowed) == [], violations(allowed)
    assert len(violations(up)) == 1 and len(violations(sideways)) == 1
    assert library("phantoms/scene/scene.cpp")[1] == "sonotrace_scene"
    headers = {"simulator/a.cpp": ["simulator/tracer.h", "tissue/volume.h", "tests/test_util.h"],
               "simulator/b.cpp": ["phantoms/phantom.h"],
               "imaging/c.cpp": ["imaging/bmode.h"]}
    fine = "sonotrace_test(a quick MODULES sonotrace_simulator SOURCES simulator/a.cpp)"
    assert test_violations(fine, headers.get) == [], test_violations(fine, headers.get)
    for bad in ["sonotrace_test(b quick MODULES sonotrace_simulator SOURCES simulator/b.cpp)",
                "sonotrace_test(a quick MODULES sonotrace_phantoms SOURCES simulator/a.cpp)",
                "sonotrace_test(a quick MODULES sonotrace_simulator sonotrace_tissue\n"
                "               SOURCES simulator/a.cpp)",
                "sonotrace_test(c quick MODULES sonotrace_imaging SOURCES imaging/c.cpp simulator/a.cpp)"]:
        assert len(test_violations(bad, headers.get)) == 1, (bad, test_violations(bad, headers.get))


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    self_test()
    if "--self-test" in sys.argv[1:]:
        print("check_layers: self-test passed")
        return 0
    pairs = repository_includes(root)
    bad = violations(pairs)

    def includes_of(test_source):
        with open(os.path.join(root, "tests", test_source), encoding="utf-8") as text:
            return [m.group(1) for m in map(INCLUDE.match, text) if m]

    with open(os.path.join(root, "tests", "CMakeLists.txt"), encoding="utf-8") as cmake:
        cmake_text = cmake.read()
    tests = len(TEST_RULE.findall(cmake_text))
    bad += test_violations(cmake_text, includes_of)
    for line in bad:
        print(line, file=sys.stderr)
    if bad:
        print(f"check_layers: {len(bad)} includes point up or sideways", file=sys.stderr)
        return 1
    print(f"check_layers: {len(pairs)} includes, all pointing down; {tests} tests, each "
          f"linking its folder's library only")
    return 0


if __name__ == "__main__":
    sys.exit(main())
