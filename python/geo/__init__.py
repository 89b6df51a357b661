"""geo: depth, optical flow and camera motion from monocular video (GeoNet with feature refinement).

The C++ library from Python, on the same LibTorch as the installed torch (tensors cross without
copies):

    import geo
    model = geo.Model.load("model.pt")          # a geo_export file, a checkpoint or a run folder
    depth = model.depth(image)                   # image: numpy HxWx3 uint8 or torch 3xHxW -> [H,W]
    motion = model.relative_pose(prev, image)    # [4,4]
    flow = model.flow(prev, image)               # [2,H,W] pixels
    frames = geo.io.Frames("clip.mp4", size=(model.spec.height, model.spec.width))  # read as needed
    out = model.run_sequence(frames, scales=model.sequence_scales(frames, 1.65))  # geo_infer's numbers

    geo.eval.depth_errors(gt, depth)             # Eigen metrics (median scaling) as a dict
    world = geo.synth.world(frames=3)            # the synthetic world with ground truth
    run = geo.train("smoke.yaml", overrides=["data.format=synthetic"], callback=print)

geo.eval, geo.synth, geo.kitti and (built with OpenCV) geo.io hold the protocols, the synthetic world
and KITTI's formats. Failures raise geo.Error (a RuntimeError) with geo's message.
"""
import os as _os
import pathlib as _pathlib
import sys as _sys

# Installed (cmake --install): the shipped configs are <prefix>/share/geo/configs, above this
# package's <prefix>/lib/python3.X/... (GEO_PYTHON_INSTALL_DIR may put it at any depth); the nearest
# folder above that holds them is used, so geo.train("stage1.yaml") finds them. A package copied
# where no such folder is above it still imports (bare config names then mean the build's configs).
if "GEO_CONFIG_DIR" not in _os.environ:
    for _above in _pathlib.Path(__file__).resolve().parents:
        if (_above / "share" / "geo" / "configs").is_dir():
            _os.environ["GEO_CONFIG_DIR"] = str(_above / "share" / "geo" / "configs")
            break
    else:
        _above = None
    del _above

import torch as _torch  # noqa: F401  (registers torch's types before geo's module loads)

from ._geo import (  # noqa: F401
    ConfigError,
    Error,
    FlowParts,
    FrameSource,
    Model,
    ModelSpec,
    chain_poses,
    Networks,
    eval,
    has_opencv,
    image,
    kitti,
    kitti_like_intrinsics,
    resume,
    smooth_road_scales,
    state_dicts,
    synth,
    train,
)

if has_opencv:
    from ._geo import io  # noqa: F401

# `import geo.eval` and friends work as for any package.
for _name in ("eval", "synth", "kitti", "io"):
    if _name in globals():
        _sys.modules[__name__ + "." + _name] = globals()[_name]
del _name

__all__ = ["Model", "ModelSpec", "Networks", "FlowParts", "FrameSource", "Error", "ConfigError", "chain_poses", "smooth_road_scales", "image",
           "kitti_like_intrinsics", "train", "resume", "state_dicts", "eval", "synth", "kitti"] + (["io"] if has_opencv else [])
