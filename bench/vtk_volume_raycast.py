#!/usr/bin/env python3
"""VTK's CPU ray caster (vtkFixedPointVolumeRayCastMapper) on the PBVR benchmark's view:
the Colin27 head (mricron-data), the `head` transfer function, Blinn-Phong shading under
a headlight, the octant facing the camera cut away, 512 x 512: the time per frame that
issue 56 measures PBVR against (bench_pbvr reports PBVR's).

Needs Debian's python3-vtk9 and an X server (offscreen through Xvfb):
    xvfb-run -a /usr/bin/python3 bench/vtk_volume_raycast.py [frames] [out.png]

The transfer function is read from its one definition (imaging/pbvr/colour_tf.cpp) and
windowed as `ColourTransferFunction::bind` does: values normalised between the volume's
0 and 0.99 quantiles. Its opacity is per 1 mm (`unit_length_mm`), as VTK's scalar opacity
unit distance. The camera is `pbvr::fit_camera` at kHeadAzimuthDeg / kHeadElevationDeg
(235, 18), 30 degree field of view. Prints one JSON line: the median and the spread of the
time per frame over `frames` renders (the azimuth nudged by 0.01 degrees each, so each is
a new ray cast), and the threads VTK used.
"""
import json
import math
import os
import re
import sys
import time

import numpy as np
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
VOLUME = "/usr/share/mricron/templates/ch2.nii.gz"  # tissue::kDefaultVolumePath
AZIMUTH, ELEVATION, FOV = 235.0, 18.0, 30.0  # pbvr::kHeadAzimuthDeg, kHeadElevationDeg
SHADING = {"ambient": 0.35, "diffuse": 0.65, "specular": 0.25, "power": 24.0}  # pbvr::Shading


def head_preset():
    """The `head` preset's JSON, from its definition in colour_tf.cpp."""
    with open(os.path.join(HERE, "..", "imaging", "pbvr", "colour_tf.cpp")) as f:
        source = f.read()
    match = re.search(r'kHeadPreset = R"\((\{.*?\})\)";', source, re.S)
    return json.loads(match.group(1))


def forward(azimuth, elevation):  # pbvr::OrbitCamera::forward
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), -math.sin(e)])


def main():
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    out_png = sys.argv[2] if len(sys.argv) > 2 else None
    reader = vtk.vtkNIFTIImageReader()
    reader.SetFileName(VOLUME)
    reader.Update()
    image = reader.GetOutput()
    values = numpy_support.vtk_to_numpy(image.GetPointData().GetScalars()).astype(np.float64)
    preset = head_preset()
    norm = preset["normalization"]
    low, high = np.quantile(values, [norm["low_quantile"], norm["high_quantile"]])

    colour = vtk.vtkColorTransferFunction()
    opacity = vtk.vtkPiecewiseFunction()
    for p in preset["points"]:
        raw = low + p["value"] * (high - low)
        colour.AddRGBPoint(raw, *p["colour"])
        opacity.AddPoint(raw, p["opacity"])
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(preset["unit_length_mm"])
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOn()
    prop.SetAmbient(SHADING["ambient"])
    prop.SetDiffuse(SHADING["diffuse"])
    prop.SetSpecular(SHADING["specular"])
    prop.SetSpecularPower(SHADING["power"])

    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputConnection(reader.GetOutputPort())
    mapper.SetAutoAdjustSampleDistances(0)
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    qform = reader.GetQFormMatrix() or reader.GetSFormMatrix()
    if qform is not None:
        volume.SetUserMatrix(qform)
    to_world = np.array([[volume.GetMatrix().GetElement(r, c) for c in range(4)]
                         for r in range(4)])

    # pbvr::fit_camera: the box's centre, at the distance where 0.8 x its half diagonal
    # fills the field of view.
    bounds = image.GetBounds()
    lo, hi = np.array(bounds[0::2]), np.array(bounds[1::2])
    centre_local = 0.5 * (lo + hi)
    target = (to_world @ np.append(centre_local, 1.0))[:3]
    distance = 0.8 * 0.5 * np.linalg.norm(hi - lo) / math.sin(math.radians(0.5 * FOV))

    # pbvr::facing_octant: the octant of the box on the camera's side is not drawn.
    to_eye_local = np.linalg.solve(to_world[:3, :3], -forward(AZIMUTH, ELEVATION))
    mapper.CroppingOn()
    mapper.SetCroppingRegionPlanes(centre_local[0], hi[0], centre_local[1], hi[1],
                                   centre_local[2], hi[2])
    facing = [1 if to_eye_local[a] > 0 else 0 for a in range(3)]
    flags = 0
    for k in range(3):
        for j in range(3):
            for i in range(3):
                if [i, j, k] != facing:
                    flags |= 1 << (i + 3 * j + 9 * k)
    mapper.SetCroppingRegionFlags(flags)

    renderer = vtk.vtkRenderer()
    renderer.AddVolume(volume)
    renderer.SetBackground(0.0, 0.0, 0.0)
    renderer.LightFollowCameraOn()
    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.AddRenderer(renderer)
    window.SetSize(512, 512)
    camera = renderer.GetActiveCamera()
    camera.SetViewAngle(FOV)
    camera.SetViewUp(0.0, 0.0, 1.0)

    def place(azimuth):
        eye = target - forward(azimuth, ELEVATION) * distance
        camera.SetFocalPoint(*target)
        camera.SetPosition(*eye)
        renderer.ResetCameraClippingRange()

    place(AZIMUTH)
    window.Render()  # the first frame builds VTK's tables: not timed
    times = []
    for n in range(frames):
        place(AZIMUTH + 0.01 * (n + 1))
        start = time.perf_counter()
        window.Render()
        times.append(1e3 * (time.perf_counter() - start))
    if out_png:
        place(AZIMUTH)
        window.Render()
        grab = vtk.vtkWindowToImageFilter()
        grab.SetInput(window)
        grab.Update()
        writer = vtk.vtkPNGWriter()
        writer.SetFileName(out_png)
        writer.SetInputConnection(grab.GetOutputPort())
        writer.Write()
    times.sort()
    print(json.dumps({"image": "512x512", "frames": frames,
                      "ms_per_frame_median": times[len(times) // 2],
                      "ms_min": times[0], "ms_max": times[-1],
                      "threads": mapper.GetNumberOfThreads(),
                      "sample_distance_mm": mapper.GetSampleDistance()}))


if __name__ == "__main__":
    main()
