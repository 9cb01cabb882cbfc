"""`sonotrace dataset` read back with h5py alone, as a training pipeline would: shapes,
dtypes, the frame table, labels within the manifest's legend, and bad specs refused with
exit status 1 and nothing written. Run by ctest (python.dataset_shards) with
SONOTRACE_BINARY and SONOTRACE_SOURCE_DIR set."""
import json
import os
import subprocess

import h5py
import numpy as np
import pytest

BINARY = os.environ["SONOTRACE_BINARY"]
SOURCE = os.environ["SONOTRACE_SOURCE_DIR"]


def make(tmp_path, spec, *args):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    out = tmp_path / "out"
    run = subprocess.run([BINARY, "dataset", str(path), "--out", str(out), "-q", *args],
                         capture_output=True, text=True)
    return run, out


def spec(**changes):
    s = {
        "frames": 3, "frames_per_shard": 2, "seed": 11,
        "image": {"width": 40, "height": 32},
        "sources": [{"phantom": SOURCE + "/phantoms/cyst_and_stone.json"}],
        "transducer": {"depth": [18, 22], "focus": 15}, "quality": "interactive",
        "write": ["bmode", "labels", "rf"],
    }
    s.update(changes)
    return s


def test_echo_labels_are_the_labels_where_the_echoes_show_them(tmp_path):
    """write "labels_echo": the labels moved to where the frame shows the anatomy. Under
    cyst_and_stone's probe the water cyst (slower than the liver around it) and the plaque
    (2500 m/s) move what lies below them, so the two maps differ, though only near
    boundaries (at most 15 % of the scanned pixels), and both keep to the legend."""
    run, out = make(tmp_path, spec(frames=2, write=["bmode", "labels", "labels_echo"]))
    assert run.returncode == 0, run.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    legend = set(int(k) for k in manifest["labels"])
    with h5py.File(out / manifest["shards"][0], "r") as f:
        labels, moved = f["labels"][:], f["labels_echo"][:]
        assert moved.shape == labels.shape and moved.dtype == np.uint8
        assert set(np.unique(moved)) <= legend
        scanned = labels > 0
        differ = (moved != labels) & scanned
        assert differ.any()
        assert differ.sum() <= 0.15 * scanned.sum()


def test_shards_read_back_with_h5py(tmp_path):
    run, out = make(tmp_path, spec())
    assert run.returncode == 0, run.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["shards"] == ["shard_00000.h5", "shard_00001.h5"]
    indices = []
    for name, count in zip(manifest["shards"], [2, 1]):
        with h5py.File(out / name, "r") as f:
            assert f["bmode"].shape == (count, 32, 40) and f["bmode"].dtype == np.uint8
            assert f["labels"].shape == (count, 32, 40) and f["labels"].dtype == np.uint8
            rows = f["frames"][:]
            assert len(rows) == count
            indices += list(rows["index"])
            # The scanned grid fits the image; its pixels are square and positive.
            assert np.all(rows["valid_width"] <= 40) and np.all(rows["valid_height"] <= 32)
            assert np.all(rows["pixel_mm"] > 0)
            assert np.all((rows["depth_mm"] >= 18) & (rows["depth_mm"] <= 22))
            assert np.all(rows["focus_mm"] == 15)
            assert all(p == b"linear" for p in rows["probe"])
            # Unit axes, lateral x axial = elevation (probe/pose.h).
            for r in rows:
                assert np.allclose(np.cross(r["lateral"], r["axial"]), r["elevation"])
            legend = set(int(k) for k in manifest["labels"])
            assert set(np.unique(f["labels"][:])) <= legend
            assert f.attrs["frame_count"] == count
            assert json.loads(f.attrs["spec"]) == manifest["spec"]
            for row in rows:
                rf = f["rf"]["%08d" % row["index"]]
                assert rf.dtype == np.float32 and rf.ndim == 2 and rf.shape[0] > 0
            # Pixels outside the scanned grid are 0, inside not all the same.
            b = f["bmode"][0]
            assert np.all(b[rows["valid_height"][0]:, :] == 0)
            assert b[: rows["valid_height"][0], : rows["valid_width"][0]].std() > 1
    assert indices == [0, 1, 2]


def test_the_frame_table_has_a_column_for_every_drawn_value(tmp_path):
    """Domain randomisation as a user reads it back: one column per drawn value, each in
    its range, the transducer's drawn depth the one the frame was made at."""
    run, out = make(tmp_path, spec(
        transducer={"depth": [18, 22], "focus": 15, "f-number": [1.5, 2.5]},
        tgc={"slope": [0.3, 0.9], "sliders": 3, "slider_db": 2}, noise_snr_db=[10, 40],
        tissues={"liver": {"speed_of_sound": [1550, 1600], "attenuation": {"spread": 0.2}}}))
    assert run.returncode == 0, run.stderr
    with h5py.File(out / "shard_00000.h5", "r") as f:
        rows = f["frames"][:]
    ranges = {"transducer.depth": (18, 22), "transducer.f-number": (1.5, 2.5),
              "transducer.focus": (15, 15), "tgc.slope": (0.3, 0.9), "tgc.slider0": (-2, 2),
              "tgc.slider1": (-2, 2), "tgc.slider2": (-2, 2), "noise_snr_db": (10, 40),
              "tissues.liver.speed_of_sound": (1550, 1600),
              "tissues.liver.attenuation": (0.4, 0.6)}  # liver 0.5 dB/(cm MHz) +-20 %
    names = set(rows.dtype.names)
    assert set(ranges) <= names, names
    for name, (low, high) in ranges.items():
        assert np.all((rows[name] >= low) & (rows[name] <= high)), (name, rows[name])
    assert np.array_equal(rows["transducer.depth"], rows["depth_mm"])
    assert len(set(rows["noise_snr_db"])) == len(rows)  # drawn per frame


def test_truth_maps_in_shards(tmp_path):
    run, out = make(tmp_path, spec(write=["bmode", "labels", "depth", "echogenicity",
                                          "instances"]))
    assert run.returncode == 0, run.stderr
    with h5py.File(out / "shard_00000.h5", "r") as f:
        assert f["depth"].dtype == np.float32 and f["depth"].shape == (2, 32, 40)
        assert f["echogenicity"].dtype == np.float32
        assert f["instances"].dtype == np.uint16
        labels, instances = f["labels"][:], f["instances"][:]
        assert set(np.unique(instances)) <= {0, 1, 2}
        assert np.all(labels[instances == 1] == 1)  # the cyst: water
        # Where the liver shows (label 5), its backscatter: the table's 0.5.
        echo = f["echogenicity"][:]
        assert np.median(echo[labels == 5]) == pytest.approx(0.5, abs=0.01)


@pytest.mark.parametrize("change,field", [
    ({"frames": 0}, "frames"),
    ({"write": ["bmode", "video"]}, "write[1]"),
    ({"sources": [{"phantom": "missing.json"}]}, "sources[0].phantom"),
    ({"transducer": {"depth": [18, 22], "focus": 30}}, "focus"),
    ({"extra": 1}, "extra"),
])
def test_bad_specs_exit_1_naming_the_field_and_write_nothing(tmp_path, change, field):
    run, out = make(tmp_path, spec(**change))
    assert run.returncode == 1, run.stderr
    assert "spec.json" in run.stderr and field in run.stderr, run.stderr
    assert not out.exists() or not any(out.iterdir())


def test_channel_data_in_shards(tmp_path):
    """"transmit" and write "channels": each frame's channel data, [transmits, elements,
    samples] float32, with its sampling and geometry as attributes; the frames' images as
    without them. Asking for channels of focused frames is refused."""
    s = spec(sources=[{"phantom": SOURCE + "/phantoms/picmus.json"}],
             transducer={"depth": [28, 34]}, transmit="plane:-4:4:3", frames=2,
             write=["bmode", "channels"])
    run, out = make(tmp_path, s)
    assert run.returncode == 0, run.stderr
    with h5py.File(out / "shard_00000.h5", "r") as f:
        assert sorted(f["channels"].keys()) == ["00000000", "00000001"]
        for name, d in f["channels"].items():
            assert d.dtype == np.float32 and d.shape[:2] == (3, 128)
            assert d.attrs["pitch_mm"] == 0.30
            assert d.attrs["sampling_frequency_hz"] == 4 * 5.208e6
            assert d.attrs["speed_of_sound_m_s"] == 1540.0
            # Samples enough for the frame's depth and back from every element.
            depth = f["frames"][int(name)]["depth_mm"]
            reach = (depth + np.hypot(depth, 38.4)) / 1540e3 * d.attrs["sampling_frequency_hz"]
            assert d.shape[2] > reach
            assert np.abs(d[()]).max() > 0
            # The PICMUS probe's elements: 0.30 mm apart on z = 0, facing +z.
            elements = f["channel_elements"][name][()]
            assert elements.shape == (128, 4)
            assert np.allclose(np.diff(elements[:, 0]), 0.30) and np.all(elements[:, 1] == 0)
            assert np.all(elements[:, 2:] == [0.0, 1.0])
    (tmp_path / "bad").mkdir()
    bad, out = make(tmp_path / "bad", spec(write=["bmode", "channels"]))
    assert bad.returncode == 1 and "needs unfocused transmits" in bad.stderr
    assert not out.exists()
