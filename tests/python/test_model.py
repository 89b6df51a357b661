"""geo.Model from Python: the same results as the C++ tools, numpy and torch inputs without copies,
errors as geo.Error, and one Model called from several threads."""
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import threading

import numpy as np
import pytest
import torch

import geo
from conftest import run_app


@pytest.fixture(scope="module")
def frames():
    return geo.synth.world(frames=3, seed=7)["images"]  # [3,3,64,208] uint8


def test_spec_is_the_trained_architecture(model, model_file):
    spec = model.spec
    assert (spec.height, spec.width, spec.seq_length, spec.encoder_depth) == (64, 208, 3, 18)
    assert spec.feature_refinement and spec.has_flow and not spec.learns_intrinsics
    assert spec.source == str(model_file)
    assert model.device == torch.device("cpu")


def test_created_models_follow_the_seed_and_only_checkpoints_carry_training_configs(trained, model, frames):
    yaml = "model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n"
    torch.manual_seed(3)
    a = geo.Model.create(yaml)
    torch.manual_seed(3)
    b = geo.Model.create(yaml)
    assert (a.spec.source, a.spec.encoder_depth, a.spec.width) == ("untrained", 18, 208)
    assert torch.equal(a.depth(frames[0]), b.depth(frames[0]))
    assert a.training_configs == [] and model.training_configs == []  # created, geo_export file
    configs = geo.Model.load(str(trained[0])).training_configs
    assert len(configs) == 1 and "encoder_depth: 18" in configs[0]
    with pytest.raises(geo.Error, match="encoder_dept"):
        geo.Model.create("model: {encoder_dept: 18}")
    # Created in int8 for inference only, as load: the float kernels go, the depth is the kept model's.
    torch.manual_seed(3)
    kept = geo.Model.create(yaml, precision="int8", calibration=list(frames))
    torch.manual_seed(3)
    lean = geo.Model.create(yaml, precision="int8", calibration=list(frames), keep_float_weights=False)
    assert lean.float_weights_released and not kept.float_weights_released
    assert torch.equal(lean.depth(frames[0]), kept.depth(frames[0]))


def test_numpy_images_are_viewed_channels_last_without_a_copy(frames):
    hwc = np.ascontiguousarray(frames[0].permute(1, 2, 0).numpy())
    seen = geo.image(hwc)
    assert seen.shape == (3, 64, 208) and seen.data_ptr() == hwc.ctypes.data
    assert torch.equal(seen, frames[0])
    batch = np.ascontiguousarray(frames.permute(0, 2, 3, 1).numpy())
    assert geo.image(batch).data_ptr() == batch.ctypes.data and torch.equal(geo.image(batch), frames)
    # A torch tensor is geo's [3,H,W] as it is: the same tensor, no copy.
    assert geo.image(frames[1]).data_ptr() == frames[1].data_ptr()
    # Read-only arrays (PIL's np.asarray) are shared too; reversed channels (BGR[..., ::-1]) are copied.
    hwc.flags.writeable = False
    assert geo.image(hwc).data_ptr() == hwc.ctypes.data
    bgr = np.ascontiguousarray(hwc[..., ::-1])
    assert torch.equal(geo.image(bgr[..., ::-1]), frames[0])


def test_numpy_and_torch_inputs_give_the_same_outputs(model, frames):
    hwc = [f.permute(1, 2, 0).numpy() for f in frames]
    depth = model.depth(hwc[1])
    assert depth.shape == (64, 208) and depth.dtype == torch.float32 and bool((depth > 0).all())
    assert torch.equal(depth, model.depth(frames[1]))
    # A batch is one forward pass (its convolutions may sum in another order): equal to rounding.
    assert torch.allclose(model.depth(frames), torch.stack([model.depth(f) for f in frames]), rtol=1e-5, atol=0)
    assert torch.equal(model.flow(hwc[0], hwc[1]), model.flow(frames[0], frames[1]))
    assert torch.equal(model.relative_pose(hwc[0], hwc[1]), model.relative_pose(frames[0], frames[1]))


def test_outputs_have_the_documented_shapes(model, frames):
    a, b, c = frames
    pose = model.relative_pose(a, b)
    assert pose.shape == (4, 4) and torch.equal(pose[3], torch.tensor([0, 0, 0, 1], dtype=pose.dtype))
    assert model.pose([a, b, c]).shape == (2, 4, 4)
    full, rigid = model.flow_parts(b, c, previous=a)
    assert full.shape == rigid.shape == (2, 64, 208)
    assert torch.equal(full, model.flow(b, c, previous=a))
    parts = model.flow_parts(b, c, previous=a)  # the depth and motion it was made of, as their own calls give them
    assert torch.equal(parts.depth, model.depth(b)) and torch.equal(parts.motion, model.pose([a, b, c])[1])
    assert torch.equal(model.flow_parts(b, c).motion, model.relative_pose(b, c))
    K = geo.kitti_like_intrinsics(64, 208)
    assert torch.allclose(K, torch.tensor([[0.58 * 208, 0, 104], [0, 1.92 * 64, 32], [0, 0, 1]], dtype=torch.float64))
    assert torch.equal(model.depth(b), model.depth(b))  # no state between calls
    assert torch.equal(model.flow(b, c, K.numpy()), model.flow(b, c, K))


def test_a_frame_folder_through_the_library_gives_geo_infers_files(model, model_file, frames, tmp_path):
    if not geo.has_opencv:
        pytest.skip("geo_infer and geo.io need OpenCV")
    inputs = tmp_path / "frames"
    inputs.mkdir()
    for i, f in enumerate(frames):
        geo.io.write_image(str(inputs / f"{i:06d}.png"), f)
    out = tmp_path / "geo_infer"
    run_app("geo_infer", "--checkpoint", model_file, "--input", inputs, "--output", out)
    # The library reads the folder as geo_infer does and runs the same sequence: no geo_infer here.
    source = geo.io.Frames(str(inputs), size=(model.spec.height, model.spec.width))
    seen = []
    result = model.run_sequence(source)
    assert source.names == ["000000", "000001", "000002"]
    assert result["depth"].shape == (3, 64, 208) and result["flow"].shape == (2, 2, 64, 208)
    assert result["motion"].shape == (2, 4, 4) and result["poses"].shape == (3, 4, 4)
    for i, name in enumerate(source.names):
        mine = tmp_path / f"{name}-depth.png"
        geo.io.write_depth_png(str(mine), result["depth"][i])
        assert mine.read_bytes() == (out / f"{name}-depth.png").read_bytes()
    written = geo.kitti.read_poses(str(out / "trajectory.txt"))
    assert torch.allclose(result["poses"], written, rtol=0, atol=1e-6)  # the file's decimals
    assert torch.equal(result["poses"], geo.chain_poses(list(result["motion"])))
    # Frame by frame through a callback (nothing held): the same numbers; a list of images: the same.
    streamed = model.run_sequence(source, seen.append)
    assert set(streamed) == {"poses"} and torch.equal(streamed["poses"], result["poses"])
    assert [f["index"] for f in seen] == [0, 1, 2] and seen[2]["flow"] is None and seen[2]["motion"] is None
    assert all(torch.equal(f["depth"], result["depth"][f["index"]]) for f in seen)
    in_memory = model.run_sequence([f["image"] for f in seen])
    assert torch.equal(in_memory["depth"], result["depth"]) and torch.equal(in_memory["poses"], result["poses"])
    # Scales multiply each frame's depth and each step of the trajectory.
    scaled = model.run_sequence(source, scales=[2.0, 3.0, 4.0])
    assert torch.allclose(scaled["depth"][1], 3 * result["depth"][1], rtol=1e-6, atol=0)
    assert torch.allclose(scaled["poses"][1, :3, 3], 2 * result["poses"][1, :3, 3], rtol=1e-6, atol=1e-9)
    with pytest.raises(geo.Error, match="2 scales for a sequence of more frames"):
        model.run_sequence(source, scales=[1.0, 1.0])
    with pytest.raises(geo.Error, match="no frame"):
        model.run_sequence([])
    with pytest.raises(geo.Error, match="geo.io.Frames"):
        model.run_sequence(str(inputs))
    with pytest.raises(RuntimeError, match="missing"):
        geo.io.Frames(str(tmp_path / "missing"))


def test_bad_inputs_raise_geo_errors_naming_them(model, frames, tmp_path):
    with pytest.raises(geo.Error, match="image: an image array must be HxWx3 or BxHxWx3 RGB.*got 64x208"):
        model.depth(np.zeros((64, 208), np.uint8))
    with pytest.raises(geo.Error, match="image: not a numeric array"):
        model.depth(np.array([["a"]]))
    with pytest.raises(geo.Error, match="intrinsics"):
        model.flow(frames[0], frames[1], torch.eye(4))
    with pytest.raises(geo.Error, match=str(tmp_path / "missing.pt")):
        geo.Model.load(str(tmp_path / "missing.pt"))
    not_a_model = tmp_path / "junk.pt"
    not_a_model.write_bytes(b"not a zip file")
    with pytest.raises(geo.Error, match="junk.pt"):
        geo.Model.load(str(not_a_model))
    with pytest.raises(geo.Error, match="learn"):
        model.intrinsics(frames[0], frames[1])  # this model assumes KITTI's proportions
    with pytest.raises(geo.Error):
        geo.Model.load(str(tmp_path / "missing.pt"), device="gpu")
    assert issubclass(geo.Error, RuntimeError) and issubclass(geo.ConfigError, geo.Error)
    # torch's own errors stay torch's.
    with pytest.raises(RuntimeError) as raised:
        torch.zeros(2) @ torch.zeros(3)
    assert not isinstance(raised.value, geo.Error)


def test_two_threads_share_one_model(model, frames):
    expected = [model.depth(f) for f in frames]
    results, errors = {}, []

    def work(index):
        try:
            results[index] = [model.depth(frames[(index + k) % 3]) for k in range(6)]
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    for index, outs in results.items():
        for k, out in enumerate(outs):
            assert torch.equal(out, expected[(index + k) % 3])


def test_save_and_load_round_trip(model, frames, tmp_path):
    path = tmp_path / "again.pt"
    model.save(str(path))
    again = geo.Model.load(str(path))
    assert torch.equal(again.depth(frames[0]), model.depth(frames[0]))
    half = tmp_path / "half.pt"
    model.save(str(half), half=True)
    assert half.stat().st_size < path.stat().st_size * 0.6


def test_save_never_replaces_a_training_checkpoint_or_its_own_file(trained, model_file, tmp_path):
    run = trained[0]
    checkpoint = sorted((run / "checkpoints").glob("stage*-*.pt"))[0]
    before = checkpoint.read_bytes()
    model = geo.Model.load(str(run))
    with pytest.raises(geo.Error, match="is not a geo_export model file .a training checkpoint"):
        model.save(str(checkpoint))
    assert checkpoint.read_bytes() == before
    with pytest.raises(geo.Error, match="is the checkpoint being exported"):
        geo.Model.load(str(model_file)).save(str(model_file), half=True)
    # Over an earlier model file, or anything with force=True.
    other = tmp_path / "other.pt"
    other.write_bytes(b"mine")
    with pytest.raises(geo.Error, match="exists and is not a geo_export model file"):
        model.save(str(other))
    model.save(str(other), force=True)
    model.save(str(other))
    assert geo.Model.load(str(other)).spec.height == model.spec.height


def test_trajectories_chain_motions_at_their_scales(model, frames):
    forward = torch.eye(4, dtype=torch.float64)
    forward[2, 3] = -1  # the camera moves 1 unit along its z: points come 1 unit closer
    poses = geo.chain_poses([forward, forward])
    assert torch.equal(poses[:, 2, 3], torch.tensor([0.0, 1.0, 2.0], dtype=torch.float64))
    assert torch.equal(geo.chain_poses([forward, forward], [2.0, 3.0])[:, 2, 3], torch.tensor([0.0, 2.0, 5.0], dtype=torch.float64))
    with pytest.raises(geo.Error, match="2 motions and 1 scales"):
        geo.chain_poses([forward, forward], [1.0])
    with pytest.raises(geo.Error, match=r"motion 1 must be \[4,4\]"):
        geo.chain_poses([forward, torch.eye(3)])
    # A two-step model sees no road: the error names the frame and the default camera.
    with pytest.raises(geo.Error, match="no road plane in any frame near frame 0 of 3 .with the default KITTI-like camera"):
        model.sequence_scales(list(frames))
    # Frame by frame (a sequence too long to hold): each frame's own factor, then the smoothing:
    # 0 where no road; the median of the road frames within 5 (2 and 4: 3), else the nearest's.
    assert [model.road_scale(f) for f in frames] == [0.0, 0.0, 0.0]
    assert geo.smooth_road_scales([2.0, 0.0, 4.0]) == [3.0, 3.0, 3.0]
    assert geo.smooth_road_scales([2.0] + [0.0] * 12 + [8.0]) == [2.0] * 7 + [8.0] * 7
    with pytest.raises(geo.Error, match="no road plane in any frame near frame 0 of 3"):
        geo.smooth_road_scales([0.0, 0.0, 0.0])


def test_int8_is_calibrated_on_frames_and_follows_fp32(model_file, frames, tmp_path):
    fp32 = geo.Model.load(str(model_file))
    assert not fp32.has_int8_calibration
    with pytest.raises(geo.Error, match="calibration frames"):
        geo.Model.load(str(model_file), precision="int8")
    int8 = geo.Model.load(str(model_file), precision="int8", calibration=[frames[0], frames[1], frames[2]])
    assert int8.spec.precision == "int8"
    d32, d8 = fp32.depth(frames), int8.depth(frames)
    assert d8.shape == d32.shape and d8.dtype == torch.float32
    assert ((d8 - d32).abs() / d32).mean() < 0.05
    with pytest.raises(geo.Error, match="int8 already"):
        int8.quantize_int8(list(frames))
    # The same frames through quantize_int8: the same calibration, the same int8 model.
    later = geo.Model.load(str(model_file))
    later.quantize_int8(list(frames))
    assert torch.equal(later.depth(frames), d8)
    with pytest.raises(geo.Error, match="at least 2"):
        geo.Model.load(str(model_file)).quantize_int8([frames[0]])
    # A file saved in int8 keeps its calibration: loaded in fp32, quantize_int8() needs no frames.
    int8.save(str(tmp_path / "int8.pt"))
    kept = geo.Model.load(str(tmp_path / "int8.pt"))
    assert kept.has_int8_calibration
    kept.quantize_int8()
    assert kept.spec.precision == "int8" and torch.equal(kept.depth(frames), d8)
    # For inference only: the float kernels go, the int8 depth is the same; saved, it is an int8
    # model file (its int8 kernels), which opens in int8 only.
    assert not kept.float_weights_released
    lean = geo.Model.load(str(tmp_path / "int8.pt"), precision="int8", keep_float_weights=False)
    assert lean.float_weights_released and torch.equal(lean.depth(frames), d8)
    lean.save(str(tmp_path / "lean.pt"))
    assert (tmp_path / "lean.pt").stat().st_size * 2 < (tmp_path / "int8.pt").stat().st_size
    assert torch.equal(geo.Model.load(str(tmp_path / "lean.pt"), precision="int8").depth(frames), d8)
    with pytest.raises(geo.Error, match="an int8 model file"):
        geo.Model.load(str(tmp_path / "lean.pt"))
    from_frames = geo.Model.load(str(model_file))
    from_frames.quantize_int8(list(frames), keep_float_weights=False)
    assert from_frames.float_weights_released and torch.equal(from_frames.depth(frames), d8)


def test_the_package_imports_from_wherever_it_is_copied():
    # A package folder copied (or installed with GEO_PYTHON_INSTALL_DIR) two levels below the root,
    # where no <prefix>/share/geo/configs lies above it: it imports, and bare config names keep
    # meaning the shipped configs. Then the same folder with a share/geo/configs above it uses those.
    package = pathlib.Path(geo.__file__).resolve().parent
    shallow = pathlib.Path(tempfile.mkdtemp(prefix="geo-py-", dir="/tmp"))
    try:
        shutil.copytree(package, shallow / "geo")
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GEO_CONFIG_DIR")}
        env["PYTHONPATH"] = str(shallow)
        probe = "import geo, os; print(geo.__file__); print(os.environ.get('GEO_CONFIG_DIR', ''))"
        out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        where, configs = out.stdout.splitlines()
        assert where == str(shallow / "geo" / "__init__.py") and configs == ""
        prefix = shallow / "lib" / "python3" / "site-packages"
        prefix.mkdir(parents=True)
        shutil.move(str(shallow / "geo"), str(prefix / "geo"))
        (shallow / "share" / "geo" / "configs").mkdir(parents=True)
        env["PYTHONPATH"] = str(prefix)
        out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        assert out.stdout.splitlines()[1] == str(shallow / "share" / "geo" / "configs")
    finally:
        shutil.rmtree(shallow)
