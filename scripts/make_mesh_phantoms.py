#!/usr/bin/env python3
"""Writes the procedural organ meshes of phantoms/meshes/ (OBJ, millimetres).

    scripts/make_mesh_phantoms.py [OUT_DIR]      (default: phantoms/meshes)

Each mesh is closed and star-shaped about its centre (or a swept tube), so it cannot cross
itself: a liver (an ellipsoid with low-order lobes), a kidney (an ellipsoid dented at its
hilum) and a portal vein (a bent tube with capped ends). The output depends on nothing
but this file: running it again writes the same bytes. phantoms/abdomen_meshes.json
places them.
"""
import math
import os
import sys


def icosphere(levels):
    """Unit vectors and counter-clockwise (outward) triangles of a subdivided icosahedron."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    v = [normalize(p) for p in v]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(levels):
        middle = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                v.append(normalize(tuple(x + y for x, y in zip(v[a], v[b]))))
                middle[key] = len(v) - 1
            return middle[key]

        finer = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = finer
    return v, f


def normalize(p):
    n = math.sqrt(sum(x * x for x in p))
    return tuple(x / n for x in p)


def star_shaped(centre, radii, bump, levels=4):
    """Vertices centre + radii * u * (1 + bump(u)) over the icosphere's directions u."""
    directions, faces = icosphere(levels)
    vertices = [tuple(centre[a] + radii[a] * u[a] * (1.0 + bump(u)) for a in range(3))
                for u in directions]
    return vertices, faces


def tube(path, radius, sides=24):
    """A closed tube along the polyline `path`: a ring of `sides` vertices per point (in
    the plane across the local direction), the ends capped by a fan about their centres."""
    vertices, faces = [], []
    frame = None
    for i, p in enumerate(path):
        a = path[max(i - 1, 0)]
        b = path[min(i + 1, len(path) - 1)]
        d = normalize(tuple(y - x for x, y in zip(a, b)))
        if frame is None:  # any vector across the first direction
            helper = (0.0, 0.0, 1.0) if abs(d[2]) < 0.9 else (1.0, 0.0, 0.0)
            frame = normalize(cross(d, helper))
        # Carried along: the previous across-vector with its component along d removed.
        frame = normalize(tuple(f - dot(frame, d) * x for f, x in zip(frame, d)))
        other = cross(d, frame)
        for k in range(sides):
            phi = 2.0 * math.pi * k / sides
            vertices.append(tuple(p[a] + radius * (math.cos(phi) * frame[a] +
                                                   math.sin(phi) * other[a]) for a in range(3)))
    rings = len(path)
    for i in range(rings - 1):
        for k in range(sides):
            a, b = i * sides + k, i * sides + (k + 1) % sides
            faces += [(a, b, b + sides), (a, b + sides, a + sides)]
    for end, ring in ((0, 0), (1, rings - 1)):
        vertices.append(path[ring])
        centre = len(vertices) - 1
        for k in range(sides):
            a, b = ring * sides + k, ring * sides + (k + 1) % sides
            faces.append((centre, b, a) if end == 0 else (centre, a, b))
    return vertices, faces


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def write_obj(path, vertices, faces, comment):
    with open(path, "w", encoding="ascii") as out:
        out.write(f"# {comment}\n# written by scripts/make_mesh_phantoms.py\n")
        for p in vertices:
            out.write("v %.4f %.4f %.4f\n" % p)
        for f in faces:
            out.write("f %d %d %d\n" % tuple(i + 1 for i in f))


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "phantoms", "meshes")
    os.makedirs(out, exist_ok=True)

    def liver_lobes(u):  # a broad right lobe, a thinner left one, a flattened underside
        x, y, z = u
        return 0.12 * x * (1.0 - y * y) - 0.10 * max(y, 0.0) ** 3 + 0.04 * math.cos(3.0 * z + x)

    write_obj(os.path.join(out, "liver.obj"),
              *star_shaped((80.0, 58.0, 30.0), (58.0, 30.0, 36.0), liver_lobes),
              "liver: an ellipsoid with lobes, centre (80, 58, 30) mm")

    def hilum(u):  # the dent where the renal vessels enter, on the medial side
        d2 = (u[0] + 0.9) ** 2 + u[1] ** 2 + u[2] ** 2
        return -0.30 * math.exp(-d2 / 0.25)

    write_obj(os.path.join(out, "kidney.obj"),
              *star_shaped((0.0, 0.0, 0.0), (24.0, 13.0, 13.0), hilum),
              "kidney about the origin (its phantom places it): 48 x 26 x 26 mm, hilum at -x")

    arc = [(55.0 + 30.0 * math.sin(s), 72.0 - 16.0 * math.cos(s), 30.0 + 6.0 * s)
           for s in [(-0.6 + 1.8 * i / 30.0) for i in range(31)]]
    write_obj(os.path.join(out, "portal_vein.obj"), *tube(arc, 4.0),
              "portal vein: a tube of radius 4 mm along an arc through the liver")


if __name__ == "__main__":
    main()
