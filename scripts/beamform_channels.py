#!/usr/bin/env python3
"""Delay-and-sum of a sonotrace channel-data file with NumPy and h5py alone.

The example of docs/guide/channel-data.md: everything it needs is in the file (element
positions and normals, each transmit's kind, angle and virtual source, the sampling rate,
the start time, the speed of sound, the centre frequency). Flat and convex arrays alike.

    python3 scripts/beamform_channels.py bmode_channels.h5 image.npy [--f-number 1.75]

writes the compounded envelope (rows = depth, columns = lateral, 0.1 mm pixels over the
array's width) as a NumPy array, and prints where its brightest pixel lies.
Coordinates: x lateral, z depth from the face's centre (a convex array's apex), mm.
"""
import argparse

import h5py
import numpy as np


def read(path):
    """The channels [transmit, element, sample] and what beamforming them needs."""
    with h5py.File(path, "r") as f:
        return {
            "channels": f["channels"][()],
            "elements_mm": f["elements_mm"][()],
            "normals": f["element_normals"][()],
            "kind": f["transmit/kind"][()],
            "angle": f["transmit/angle_rad"][()],
            "source_mm": f["transmit/virtual_source_mm"][()],
            "fs": float(f.attrs["sampling_frequency_hz"]),
            "t0": float(f.attrs["start_time_s"]),
            "c": float(f.attrs["speed_of_sound_m_s"]) * 1e3,  # mm/s
            "f0": float(f.attrs["centre_frequency_hz"]),
        }


def transmit_delay(data, k, x, z):
    """When transmit k's wave reaches (x, z) mm, from the file's time zero (s)."""
    if data["kind"][k] == 0:  # plane wave
        a = data["angle"][k]
        return (x * np.sin(a) + z * np.cos(a)) / data["c"]
    vx, vz = data["source_mm"][k]  # diverging: from the virtual source behind the face
    return (np.hypot(x - vx, z - vz) - np.hypot(vx, vz)) / data["c"]


def beamform(data, x, z, f_number=1.75):
    """|delay-and-sum| on the grid x (columns) by z (rows), mm, all transmits compounded."""
    X, Z = np.meshgrid(x, z)
    channels = data["channels"]
    n = channels.shape[-1]
    # Analytic signal of every channel: the negative frequencies removed.
    spectrum = np.fft.fft(channels, axis=-1)
    h = np.zeros(n)
    h[0] = 1.0
    h[1:(n + 1) // 2] = 2.0
    if n % 2 == 0:
        h[n // 2] = 1.0
    analytic = np.fft.ifft(spectrum * h, axis=-1)
    image = np.zeros(X.shape, complex)
    samples = np.arange(n)
    for k in range(channels.shape[0]):
        tx = transmit_delay(data, k, X, Z)
        for e, ((xe, ze), (nx, nz)) in enumerate(zip(data["elements_mm"], data["normals"])):
            # The receive aperture: the pixels an element sees within the F-number's cone,
            # in its own frame (across and along its normal).
            across = (X - xe) * nz - (Z - ze) * nx
            along = (X - xe) * nx + (Z - ze) * nz
            inside = (along > 0) & (np.abs(across) <= along / (2.0 * f_number))
            delay = tx + np.hypot(X - xe, Z - ze) / data["c"]
            position = (delay - data["t0"]) * data["fs"]
            # Interpolate the signal at baseband, then restore the carrier at the delay.
            baseband = analytic[k, e] * np.exp(-2j * np.pi * data["f0"] * (data["t0"] + samples / data["fs"]))
            value = np.interp(position, samples, baseband.real, 0, 0) + 1j * np.interp(
                position, samples, baseband.imag, 0, 0)
            image += inside * value * np.exp(2j * np.pi * data["f0"] * delay)
    return np.abs(image)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("channels", help="a sonotrace NAME_channels.h5")
    parser.add_argument("out", help="the envelope image (.npy)")
    parser.add_argument("--f-number", type=float, default=1.75, help="receive F-number")
    parser.add_argument("--depth", type=float, nargs=2, default=(5.0, 45.0), metavar=("FROM", "TO"),
                        help="depth range (mm)")
    args = parser.parse_args()
    data = read(args.channels)
    half = np.abs(data["elements_mm"][:, 0]).max()
    x = np.arange(-half, half + 1e-9, 0.1)
    z = np.arange(args.depth[0], args.depth[1] + 1e-9, 0.1)
    image = beamform(data, x, z, args.f_number)
    np.save(args.out, image)
    j, i = np.unravel_index(np.argmax(image), image.shape)
    print(f"brightest pixel at x = {x[i]:.2f} mm, z = {z[j]:.2f} mm")


if __name__ == "__main__":
    main()
