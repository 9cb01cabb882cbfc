#!/usr/bin/python3
"""VTK's CPU unstructured-grid ray caster on the mesh of `bench_pbvr tetra` (a cubic brick
of Colin27 split into tetrahedra), 512 x 512, for the comparison in bench/README.md.

Needs Debian's python3-vtk9 and an X server (offscreen through Xvfb):
    xvfb-run -a /usr/bin/python3 bench/vtk_unstructured_raycast.py [side]
Prints one JSON line: tetrahedra, milliseconds per frame (median of 5 after a warm-up).
"""
import json
import statistics
import sys
import time

import vtk

side = int(sys.argv[1]) if len(sys.argv) > 1 else 48

reader = vtk.vtkNIFTIImageReader()
reader.SetFileName("/usr/share/mricron/templates/ch2.nii.gz")
reader.Update()
dims = reader.GetOutput().GetDimensions()
low = [d // 2 - side // 2 for d in dims]
voi = vtk.vtkExtractVOI()
voi.SetInputConnection(reader.GetOutputPort())
voi.SetVOI(low[0], low[0] + side, low[1], low[1] + side, low[2], low[2] + side)
cast = vtk.vtkImageCast()
cast.SetInputConnection(voi.GetOutputPort())
cast.SetOutputScalarTypeToFloat()
tetrahedra = vtk.vtkDataSetTriangleFilter()  # voxels -> tetrahedra
tetrahedra.SetInputConnection(cast.GetOutputPort())
tetrahedra.Update()
grid = tetrahedra.GetOutput()

# The `head` preset of imaging/pbvr/colour_tf.cpp on raw intensities (its window: 0 to the
# 99th percentile, 164 on Colin27), opacity per 1 mm.
window = 164.0
points = [(0.00, (0.0, 0.0, 0.0), 0.0), (0.04, (0.95, 0.93, 0.86), 0.0),
          (0.07, (0.96, 0.94, 0.86), 0.6), (0.11, (0.96, 0.94, 0.86), 0.6),
          (0.15, (0.5, 0.6, 0.8), 0.0), (0.30, (0.7, 0.4, 0.4), 0.0),
          (0.45, (0.78, 0.42, 0.42), 0.25), (0.68, (0.93, 0.85, 0.78), 0.4),
          (0.80, (0.86, 0.62, 0.48), 0.5), (1.00, (0.88, 0.66, 0.52), 0.7)]
colour = vtk.vtkColorTransferFunction()
opacity = vtk.vtkPiecewiseFunction()
for value, rgb, alpha in points:
    colour.AddRGBPoint(value * window, *rgb)
    opacity.AddPoint(value * window, alpha)
prop = vtk.vtkVolumeProperty()
prop.SetColor(colour)
prop.SetScalarOpacity(opacity)
prop.SetScalarOpacityUnitDistance(1.0)
prop.SetInterpolationTypeToLinear()

mapper = vtk.vtkUnstructuredGridVolumeRayCastMapper()
mapper.SetInputData(grid)
volume = vtk.vtkVolume()
volume.SetMapper(mapper)
volume.SetProperty(prop)
renderer = vtk.vtkRenderer()
renderer.AddVolume(volume)
window_ = vtk.vtkRenderWindow()
window_.SetOffScreenRendering(1)
window_.SetSize(512, 512)
window_.AddRenderer(renderer)
renderer.ResetCamera()
camera = renderer.GetActiveCamera()
camera.Azimuth(35.0)
camera.Elevation(18.0)
renderer.ResetCamera()

window_.Render()  # warm-up (builds the mapper's structures)
times = []
for _ in range(5):
    start = time.perf_counter()
    window_.Render()
    times.append(1e3 * (time.perf_counter() - start))
print(json.dumps({"vtk": vtk.vtkVersion.GetVTKVersion(), "mapper": "vtkUnstructuredGridVolumeRayCastMapper",
                  "brick_voxels": side, "tetrahedra": grid.GetNumberOfCells(), "image": "512x512",
                  "ms_per_frame_median": statistics.median(times)}))
