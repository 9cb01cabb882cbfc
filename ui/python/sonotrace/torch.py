"""PyTorch's view of a dataset spec: frames made as a training loop asks for them.

    from torch.utils.data import DataLoader
    from sonotrace.torch import FrameDataset
    loader = DataLoader(FrameDataset("phantoms/datasets/example.json"), num_workers=2,
                        batch_size=None)
    for sample in loader:  # frame 0, 1, 2, ... of the spec
        sample["bmode"], sample["labels"], sample["drawn"], sample["index"]

Frame i is the frame `sonotrace dataset SPEC` writes as frame i, byte for byte: the same
draws, the same pixels (tests/python/test_torch.py). The DataLoader's workers split the
indices (worker k of n makes frames k, k + n, ...), and DataLoader takes one from each in
turn, so the frames come in index order. Each worker loads the spec's scenes once, when it
starts, and uses cpu_count / num_workers threads unless threads= says otherwise.
"""
import os

import torch
import torch.utils.data

from ._sonotrace import DatasetFrames

__all__ = ["FrameDataset"]


class FrameDataset(torch.utils.data.IterableDataset):
    """The frames of a dataset spec (`sonotrace dataset`'s JSON), in index order.

    Each sample is a dict: the arrays the spec writes (`bmode`, `labels`, `labels_echo`,
    `depth`, `echogenicity`, `instances` (int32), `envelope`, `rf`) as tensors, and `index`,
    `seed`, `source`, `probe` and `drawn` (the values drawn for the frame, named as the
    shard's frame-table columns).

    spec: path of the spec. first, stop: the frames [first, stop) (default: all).
    threads: cores per worker (0: the machine's divided among the workers).
    """

    def __init__(self, spec, first=0, stop=None, threads=0):
        super().__init__()
        self.spec = os.fspath(spec)
        self.first, self.stop, self.threads = int(first), stop, int(threads)

    def _frames(self, threads):
        return DatasetFrames(self.spec, threads)

    def __iter__(self):
        info = torch.utils.data.get_worker_info()
        worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
        threads = self.threads or max(1, (os.cpu_count() or 1) // workers)
        frames = self._frames(threads)
        stop = len(frames) if self.stop is None else min(int(self.stop), len(frames))
        for index in range(self.first + worker, stop, workers):
            sample = frames.frame(index)
            for name, value in list(sample.items()):
                if hasattr(value, "dtype"):
                    # A tensor of its own (the frame's memory goes when the sample does);
                    # PyTorch has no uint16, so instances come as int32.
                    if value.dtype == "uint16":
                        value = value.astype("int32")
                    sample[name] = torch.from_numpy(value.copy())
            yield sample
