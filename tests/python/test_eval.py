"""geo.eval, geo.kitti, geo.synth and geo.io: the protocols' numbers by hand and equal to geo_eval's
JSON byte for byte; the synthetic world's ground truth consistent with itself."""
import math

import numpy as np
import pytest
import torch

import geo
from conftest import run_app


def test_depth_errors_by_hand():
    gt = torch.tensor([[2.0, 4.0]])
    pred = torch.tensor([[1.0, 2.0]])
    e = geo.eval.depth_errors(gt, pred, scaling="none", garg_crop=False)
    assert e["pixels"] == 2 and e["scale"] == 1
    assert e["abs_rel"] == pytest.approx(0.5) and e["sq_rel"] == pytest.approx(0.75)
    assert e["rmse"] == pytest.approx(math.sqrt(2.5)) and e["rmse_log"] == pytest.approx(math.log(2))
    assert (e["a1"], e["a2"], e["a3"]) == (0, 0, 0)
    median = geo.eval.depth_errors(gt.numpy(), pred.numpy(), garg_crop=False)  # median scaling: x2, exact
    assert median["abs_rel"] == 0 and median["scale"] == 2 and median["a1"] == 1
    assert geo.eval.depth_errors(gt, pred, scaling=2.0, garg_crop=False)["rmse"] == 0
    with pytest.raises(geo.Error, match="scaling must be"):
        geo.eval.depth_errors(gt, pred, scaling="mean")


def test_flow_errors_by_hand():
    gt = torch.zeros(2, 2, 2)
    pred = torch.zeros(2, 2, 2)
    pred[:, 0, 0] = torch.tensor([3.0, 4.0])  # EPE 5 at one pixel of four
    e = geo.eval.flow_errors(gt, np.ones((2, 2), bool), pred)
    assert e == {"epe": 1.25, "fl": 0.25, "pixels": 4}
    valid = torch.ones(2, 2)
    valid[0, 0] = 0
    assert geo.eval.flow_errors(gt, valid, pred) == {"epe": 0.0, "fl": 0.0, "pixels": 3}


def test_trajectory_errors_by_hand():
    gt = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    assert geo.eval.snippet_ate(gt, 2 * gt) == 0  # one scale aligns them
    assert geo.eval.trajectory_rmse(gt, 3 * gt + 1) == pytest.approx(0, abs=1e-9)  # Sim(3)
    poses = torch.eye(4, dtype=torch.float64).repeat(30, 1, 1)
    poses[:, 2, 3] = torch.arange(30) * 10.0  # 10 m a frame along z
    e = geo.eval.odometry_errors(poses, poses, lengths=[100], step=1)
    assert e["segments"] == 19 and e["t_err"] == 0 and e["r_err"] == 0
    drift = poses.clone()
    drift[:, 0, 3] = torch.arange(30) * 0.1  # 1 cm of sideways drift per metre
    e = geo.eval.odometry_errors(poses, drift, lengths=[100], step=1, align_scale=False)
    assert e["t_err"] == pytest.approx(math.hypot(100, 1) / 100 - 1 + 0, abs=0.011)
    assert e["t_err_percent"] == pytest.approx(e["t_err"] * 100)


def test_the_synthetic_world_reprojects_onto_its_flow():
    w = geo.synth.world(frames=2, seed=3)
    assert w["images"].dtype == torch.uint8 and w["images"].shape == (2, 3, 64, 208)
    again = geo.synth.world(frames=2, seed=3)
    assert all(torch.equal(w[k], again[k]) for k in ("images", "depths", "poses", "flow"))
    K = w["intrinsics"]
    depth, flow = w["depths"][0].double(), w["flow"][0].double()
    # Static road pixels seen in both frames: back-project with depth, move by the poses, project.
    mask = (w["objects"][0] == -1) & w["flow_noc"][0]
    v, u = torch.nonzero(mask, as_tuple=True)
    assert len(u) > 500
    z = depth[v, u]
    points = torch.linalg.inv(K) @ torch.stack([u.double() * z, v.double() * z, z])
    world = w["poses"][0] @ torch.cat([points, torch.ones(1, len(u), dtype=torch.float64)])
    seen = K @ (torch.linalg.inv(w["poses"][1]) @ world)[:3]
    u1, v1 = seen[0] / seen[2], seen[1] / seen[2]
    assert torch.allclose(u1, u + flow[0, v, u], atol=1e-3) and torch.allclose(v1, v + flow[1, v, u], atol=1e-3)
    lidar = geo.synth.world(frames=1, lidar=True, flow=False)
    assert lidar["lidar"][0].shape[1] == 4 and "flow" not in lidar
    # Stop-and-go traffic: somewhere the camera stands (two equal poses), and the car ahead, which
    # keeps its gap, is among the moving objects.
    t = geo.synth.world(frames=30, seed=5, traffic=True, flow=False)
    assert any(torch.equal(t["poses"][i], t["poses"][i + 1]) for i in range(29))
    assert t["moving"].dtype == torch.bool and t["moving"][:, 36:44, 98:106].float().mean() > 0.5
    assert not w["moving"].any() or w["moving"].float().mean() < 0.5


def test_kitti_formats(tmp_path):
    calib = tmp_path / "calib.txt"
    calib.write_text("calib_time: 09-Jan-2012 13:57:47\nP0: 700 0 600 0 0 700 180 0 0 0 1 0\nTr: 1 2 3\n")
    values = geo.kitti.read_calib(str(calib))
    assert set(values) == {"P0", "Tr"} and values["P0"].dtype == torch.float64
    assert values["P0"].tolist() == [700, 0, 600, 0, 0, 700, 180, 0, 0, 0, 1, 0]
    calib.write_text("P0: 700 0 x\n")
    with pytest.raises(geo.Error, match="calib.txt"):
        geo.kitti.read_calib(str(calib))
    poses = torch.eye(4, dtype=torch.float64).repeat(3, 1, 1)
    poses[:, 0, 3] = torch.tensor([0.0, 1.5, -2.25])
    geo.kitti.write_poses(str(tmp_path / "poses.txt"), poses)
    assert torch.equal(geo.kitti.read_poses(str(tmp_path / "poses.txt")), poses)
    # One point 10 m ahead (Velodyne x) seen by a camera looking along x: pixel round(u) - 1.
    img_from_velo = torch.tensor([[50.0, -100, 0, 0], [20, 0, -100, 0], [1, 0, 0, 0]], dtype=torch.float64)
    points = torch.tensor([[10.0, 0.2, 0.1, 0.5]])  # u = (500 - 20) / 10 = 48, v = (200 - 10) / 10 = 19
    depth = geo.kitti.velodyne_depth(points, img_from_velo, 30, 60)
    assert depth[18, 47] == 10 and int((depth > 0).sum()) == 1
    assert geo.kitti.velodyne_depth(points, img_from_velo, 30, 60, exact_pixels=True)[19, 48] == 10


def test_flow_and_depth_png_round_trips(tmp_path):
    if not geo.has_opencv:
        pytest.skip("geo.io needs OpenCV")
    flow = torch.tensor([[[1.5, -2.25]], [[0.015625, 100.0]]])  # [2,1,2], multiples of 1/64
    valid = torch.tensor([[True, False]])
    geo.io.write_flow_png(str(tmp_path / "f.png"), flow, valid)
    back, back_valid = geo.io.read_flow_png(str(tmp_path / "f.png"))
    assert torch.equal(back_valid, valid) and torch.equal(back[:, 0, 0], flow[:, 0, 0])
    depth = torch.tensor([[1.0, 2.5], [0.0, 80.0]])
    geo.io.write_depth_png(str(tmp_path / "d.png"), depth)
    assert torch.equal(geo.io.read_depth_png(str(tmp_path / "d.png")), depth)


@pytest.mark.parametrize("split,source", [("eigen", "model"), ("kitti2015", "model"), ("odometry", "trivial"),
                                          ("odometry", "int8")])
def test_evaluate_equals_geo_eval_byte_for_byte(split, source, model_file, world_dir, tmp_path):
    if not geo.has_opencv:
        pytest.skip("geo.eval.evaluate needs OpenCV")
    # int8: the model calibrated on the first 4 frames of a drive of the world, the same in both.
    frames = str(next((world_dir / "raw").glob("*/*_sync/image_02/data")))
    args = {"model": ["--checkpoint", model_file], "trivial": ["--trivial"],
            "int8": ["--checkpoint", model_file, "--precision", "int8", "--calibration", frames, "--calibration-frames", "4"]}
    run_app("geo_eval", "--split", split, "--data-root", world_dir, "--device", "cpu", "--output", tmp_path / "cpp.json",
            *args[source])
    kwargs = {"model": {"checkpoint": str(model_file)}, "trivial": {"trivial": True},
              "int8": {"checkpoint": str(model_file), "precision": "int8", "calibration": frames, "calibration_frames": 4}}[source]
    result = geo.eval.evaluate(split, data_root=str(world_dir), device="cpu", output=str(tmp_path / "py.json"), **kwargs)
    assert (tmp_path / "py.json").read_bytes() == (tmp_path / "cpp.json").read_bytes()
    assert result["split"] == split and result["metrics"]
    with pytest.raises(geo.Error, match="camera-height is for --split eigen and odometry"):
        geo.eval.evaluate("kitti2015", data_root=str(world_dir), trivial=True, scaling="camera-height")
    with pytest.raises(geo.Error, match="one source of predictions"):
        geo.eval.evaluate(split, data_root=str(world_dir))
    # The split file it reads is never its output.
    split_file = tmp_path / "split.txt"
    split_file.write_text("keep\n")
    with pytest.raises(geo.Error, match="which this command reads"):
        geo.eval.evaluate(split, data_root=str(world_dir), trivial=True, split_file=str(split_file), output=str(split_file))
    assert split_file.read_text() == "keep\n"
    if source == "int8":
        with pytest.raises(geo.Error, match="keeps no int8 calibration: give --calibration FRAMES"):
            geo.eval.evaluate(split, data_root=str(world_dir), checkpoint=str(model_file), precision="int8")
        # The same calibration exported as an int8 model file: evaluated with its own, the same figures.
        int8_file = tmp_path / "int8.pt"
        run_app("geo_export", "--checkpoint", model_file, "--out", int8_file, "--int8", "--calibration", frames,
                "--calibration-frames", "4")
        from_file = geo.eval.evaluate(split, data_root=str(world_dir), device="cpu", checkpoint=str(int8_file),
                                      precision="int8")
        assert from_file["metrics"] == result["metrics"]
        with pytest.raises(geo.Error, match="an int8 model file"):
            geo.eval.evaluate(split, data_root=str(world_dir), checkpoint=str(int8_file))
        with pytest.raises(geo.Error, match="is a model's"):
            geo.eval.evaluate(split, data_root=str(world_dir), trivial=True, precision="int8", calibration=frames)
