"""geo.nn: geo's networks written independently in plain torch.nn, loaded from geo.state_dicts(),
compute what the C++ networks compute (FR on and off), and export to ONNX."""
import importlib.util

import pytest
import torch

import geo
import geo.nn
from conftest import TINY_RUN, remove_folder


def check_same(tag, mine, theirs, tol=1e-5):
    assert len(mine) == len(theirs), tag
    for s, (a, b) in enumerate(zip(mine, theirs)):
        assert a.shape == b.shape, f"{tag} scale {s}: {tuple(a.shape)} vs {tuple(b.shape)}"
        assert torch.allclose(a, b, rtol=tol, atol=tol), f"{tag} scale {s}: max difference {(a - b).abs().max()}"


@pytest.fixture(scope="module")
def no_fr_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nofr")
    run = folder / "run"
    geo.train("smoke.yaml", run_dir=str(run), overrides=TINY_RUN + ["model.use_fr=false"])
    yield run
    remove_folder(folder)


@pytest.mark.parametrize("which", ["fr", "no_fr"])
def test_pytorch_modules_compute_what_geo_computes(which, trained, no_fr_run):
    run = trained[0] if which == "fr" else no_fr_run
    theirs = geo.Networks.load(str(run))
    mine = geo.nn.from_checkpoint(str(run))
    spec = geo.state_dicts(str(run))["spec"]["model"]
    assert spec["use_fr"] == (which == "fr")
    assert any("refined" in k for k in mine["depth"].state_dict()) == (which == "fr")
    frames = geo.synth.world(frames=3, seed=11)["images"].float() / 255
    with torch.no_grad():
        check_same("depth", mine["depth"](frames), theirs.depth_net(frames))
        tgt, srcs = frames[1:2], [frames[0:1], frames[2:3]]
        check_same("pose", [mine["pose"](tgt, srcs)], [theirs.pose_net(tgt, srcs)])
        flow_input = torch.cat([frames[:2] * 2 - 1, frames[1:] * 2 - 1, frames[:2] * 2 - 1,
                                torch.randn(2, 3, 64, 208, generator=torch.Generator().manual_seed(1))], 1)
        check_same("flow", mine["flow"](flow_input), theirs.flow_net(flow_input))
    # An odd size: the decoder's nearest resizing at every scale.
    odd = torch.rand(1, 3, 45, 70, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        check_same("depth 45x70", mine["depth"](odd), theirs.depth_net(odd))
    # The modules are the weights: a changed weight changes the output.
    with torch.no_grad():
        mine["depth"].net.pred1.bias += 1
        assert not torch.allclose(mine["depth"](frames)[0], theirs.depth_net(frames)[0], atol=1e-3)


def test_the_depth_net_exports_to_onnx(trained, tmp_path):
    if importlib.util.find_spec("onnx") is None:
        pytest.skip("no onnx module (Debian: python3-onnx)")
    import onnx

    depth = geo.nn.from_checkpoint(str(trained[0]))["depth"]
    path = tmp_path / "depth.onnx"
    torch.onnx.export(depth, torch.rand(1, 3, 64, 208), str(path), input_names=["image"],
                      output_names=["disp0", "disp1", "disp2", "disp3"], opset_version=13)
    model = onnx.load(str(path))
    onnx.checker.check_model(model)
    assert [o.name for o in model.graph.output] == ["disp0", "disp1", "disp2", "disp3"]
    assert [d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim] == [1, 3, 64, 208]
