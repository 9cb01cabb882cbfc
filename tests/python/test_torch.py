"""sonotrace.torch.FrameDataset against `sonotrace dataset`: with two DataLoader workers it
yields, in index order, exactly the frames the command writes for the same spec (the
arrays byte for byte, the draws to the bit). Run by ctest (python.torch); needs Debian's
python3-torch, which `scripts/setup.sh test` installs."""
import json
import os
import subprocess
import sys

import h5py
import numpy as np
import torch
from torch.utils.data import DataLoader

sys.path.insert(0, os.environ["SONOTRACE_PYTHON_DIR"])
from sonotrace.torch import FrameDataset  # noqa: E402

BINARY = os.environ["SONOTRACE_BINARY"]
SOURCE = os.environ["SONOTRACE_SOURCE_DIR"]


def test_two_workers_yield_the_shards_frames(tmp_path):
    spec = {
        "frames": 6, "frames_per_shard": 3, "seed": 4,
        "image": {"width": 48, "height": 40},
        "sources": [{"phantom": SOURCE + "/phantoms/cyst_and_stone.json", "weight": 2},
                    {"phantom": SOURCE + "/phantoms/point_grid.json"}],
        "transducer": {"depth": [18, 24], "focus": 15, "f-number": [1.5, 2.5]},
        "gain_db": [36, 48], "pose": {"lateral_mm": 3, "rotation_deg": 4},
        "tgc": {"slope": [0.4, 0.8], "sliders": 3, "slider_db": 2}, "noise_snr_db": [15, 30],
        "tissues": {"liver": {"backscatter": {"spread": 0.3}}},
        "quality": "interactive",
        "write": ["bmode", "labels", "depth", "instances", "envelope"],
    }
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    subprocess.run([BINARY, "dataset", str(path), "--out", str(tmp_path / "out"), "-q"],
                   check=True)
    shards = []
    for k in range(2):
        with h5py.File(tmp_path / "out" / ("shard_%05d.h5" % k), "r") as f:
            shards.append({name: f[name][:] for name in ("bmode", "labels", "depth", "instances",
                                                         "frames")}
                          | {"envelope": {int(i): f["envelope"][i][:] for i in f["envelope"]}})
    loader = DataLoader(FrameDataset(path), num_workers=2, batch_size=None)
    samples = list(loader)
    assert [int(s["index"]) for s in samples] == list(range(6))
    for sample in samples:
        i = int(sample["index"])
        shard, row = shards[i // 3], i % 3
        for name in ("bmode", "labels", "depth"):
            assert sample[name].dtype == torch.from_numpy(shard[name][row]).dtype, name
            assert np.array_equal(sample[name].numpy(), shard[name][row]), (name, i)
        assert np.array_equal(sample["instances"].numpy(), shard["instances"][row].astype(np.int32))
        assert np.array_equal(sample["envelope"].numpy(), shard["envelope"][i])
        table = shard["frames"][row]
        assert int(sample["seed"]) == table["seed"] and int(sample["source"]) == table["source"]
        assert sample["probe"].encode() == table["probe"]
        assert set(sample["drawn"]) == {n for n in table.dtype.names if "." in n or n == "noise_snr_db"}
        for name, value in sample["drawn"].items():
            assert value == table[name], name  # to the bit


def test_frames_split_among_workers_by_index(tmp_path):
    """A range of frames, three workers: each frame once, in order."""
    spec = {"frames": 5, "seed": 2, "image": {"width": 32, "height": 32},
            "sources": [{"phantom": SOURCE + "/phantoms/cyst_and_stone.json"}],
            "quality": "interactive", "write": ["bmode"]}
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    loader = DataLoader(FrameDataset(path, first=1, stop=5), num_workers=3, batch_size=None)
    assert [int(s["index"]) for s in loader] == [1, 2, 3, 4]
