"""Channel data written by `sonotrace simulate --transmit ... --channels`, read with h5py
alone and beamformed by the guide's NumPy example (scripts/beamform_channels.py): the
layout docs/guide/channel-data.md states, and a wire imaged where the phantom puts it.
Run by ctest (python.channel_file) with SONOTRACE_BINARY and SONOTRACE_SOURCE_DIR set."""
import importlib.util
import json
import os
import subprocess

import h5py
import numpy as np

BINARY = os.environ["SONOTRACE_BINARY"]
SOURCE = os.environ["SONOTRACE_SOURCE_DIR"]

spec = importlib.util.spec_from_file_location(
    "beamform_channels", os.path.join(SOURCE, "scripts", "beamform_channels.py"))
beamform_channels = importlib.util.module_from_spec(spec)
spec.loader.exec_module(beamform_channels)

# One nylon wire at 20 mm in scatter-free water, under the PICMUS probe.
WIRE = {
    "name": "wire", "size": [50, 30, 10], "smoothing": 0.1,
    "background": {"speed_of_sound": 1540, "density": 1000, "attenuation": 0.0,
                   "backscatter": 0, "scatterer_density": 0, "roughness": 0},
    "targets": [{"type": "wire", "at": [27, 20], "diameter": 0.1}],
    "probe": {"preset": "picmus"},
}


def simulate(tmp_path, transmit, probe="picmus"):
    phantom = tmp_path / "wire.json"
    phantom.write_text(json.dumps(WIRE))
    run = subprocess.run([BINARY, "simulate", "-q", "--quality", "interactive", "--phantom",
                          str(phantom), "--probe", probe, "--depth", "28", "--focus", "20",
                          "--transmit", transmit,
                          "--channels", "--out", str(tmp_path)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return tmp_path / "bmode_channels.h5"


def test_the_file_holds_what_beamforming_needs(tmp_path):
    path = simulate(tmp_path, "plane:-5:5:3")
    with h5py.File(path, "r") as f:
        channels = f["channels"]
        assert channels.dtype == np.float32
        assert channels.shape[:2] == (3, 128)
        elements = f["elements_mm"][()]
        assert elements.shape == (128, 2)
        # 0.30 mm pitch, centred on the face.
        assert np.allclose(np.diff(elements[:, 0]), 0.30)
        assert abs(elements[:, 0].mean()) < 1e-9 and np.all(elements[:, 1] == 0)
        assert np.all(f["element_normals"][()] == [0.0, 1.0])
        assert list(f["transmit/kind"][()]) == [0, 0, 0]
        assert np.allclose(np.degrees(f["transmit/angle_rad"][()]), [-5, 0, 5])
        assert np.all(np.isnan(f["transmit/virtual_source_mm"][()]))
        # Each element fires when the plane wave passes it: x sin(a) / c.
        delays = f["transmit/delays_s"][()]
        c = f.attrs["speed_of_sound_m_s"] * 1e3
        expected = elements[:, 0][None, :] * np.sin(f["transmit/angle_rad"][()])[:, None] / c
        assert np.allclose(delays, expected, atol=1e-12)
        assert f.attrs["sampling_frequency_hz"] == 4 * 5.208e6
        assert f.attrs["centre_frequency_hz"] == 5.208e6
        assert f.attrs["start_time_s"] == 0.0
        assert f.attrs["transmit"].decode() == "plane:-5:5:3"  # fixed-length ASCII: bytes
        assert np.isfinite(channels[()]).all() and np.abs(channels[()]).max() > 0


def test_numpy_beamforms_the_wire_where_it_lies(tmp_path):
    """The wire lies 2 mm right of the probe's centre, 20 mm deep: the NumPy image's
    brightest pixel there within 0.2 mm (two of its pixels), for plane and diverging
    waves, and under the convex array's diverging waves."""
    for transmit, probe in (("plane:-5:5:3", "picmus"), ("diverging:30", "picmus"),
                            ("diverging:49.57:-5:5:3", "convex")):
        data = beamform_channels.read(simulate(tmp_path, transmit, probe))
        x = np.arange(-4.0, 4.0 + 1e-9, 0.1)
        z = np.arange(17.0, 23.0 + 1e-9, 0.1)
        image = beamform_channels.beamform(data, x, z)
        j, i = np.unravel_index(np.argmax(image), image.shape)
        assert abs(x[i] - 2.0) <= 0.2 and abs(z[j] - 20.0) <= 0.2, (transmit, probe, x[i], z[j])


def test_a_convex_arrays_elements_lie_on_its_arc(tmp_path):
    """The convex preset: 128 elements 0.508 mm apart along an arc of radius 49.57 mm about
    (0, -49.57), each facing away from that centre; a diverging wave from the centre fires
    every element at once."""
    with h5py.File(simulate(tmp_path, "diverging:49.57", "convex"), "r") as f:
        elements, normals = f["elements_mm"][()], f["element_normals"][()]
        centre = np.array([0.0, -49.57])
        assert np.allclose(np.linalg.norm(elements - centre, axis=1), 49.57)
        assert np.allclose(normals, (elements - centre) / 49.57)
        chords = np.linalg.norm(np.diff(elements, axis=0), axis=1)
        assert np.allclose(chords, 2 * 49.57 * np.sin(0.508 / (2 * 49.57)))
        assert np.allclose(f["transmit/delays_s"][()], 0.0, atol=1e-12)
        assert np.allclose(f["transmit/virtual_source_mm"][()], [centre])
