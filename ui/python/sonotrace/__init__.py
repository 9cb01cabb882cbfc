"""sonotrace: ultrasound frames by particle tracing through tissue maps.

Keyword arguments are the frame's parameters, the options of `sonotrace simulate` that are
not about its files (`sonotrace simulate --help` gives units and defaults), with '_' for
'-', and threads; errors are sonotrace.InputError naming the option or file and field.

    frame = sonotrace.simulate(phantom="phantoms/cyst_and_stone.json", seed=3, labels=True)
    scene = sonotrace.Scene(phantom="phantoms/abdomen_meshes.json", quality="interactive")
    frame = scene.frame(pose="at=80,0,30 beam=0,1,0", seed=2)

sonotrace.torch.FrameDataset(spec) yields a dataset spec's frames to a PyTorch DataLoader
(PyTorch is needed only there).
"""
from ._sonotrace import *  # noqa: F401,F403  (the extension's classes and functions)
from ._sonotrace import __version__  # noqa: F401
