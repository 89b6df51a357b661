// The synthetic world's ground truth is exact: flow reproduces the next frame, depth + poses give
// the flow of static points, the LiDAR lands where the depth says; and the KITTI readers read
// everything the writer writes.
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/kitti/sequence_dataset.h"
#include "data/synth/synth_snippets.h"
#include "data/synth/synth_writer.h"
#include "data/text_io.h"
#include "data/kitti/velodyne_depth.h"
#include "geometry/camera.h"
#include "geometry/pose.h"
#include "geometry/warp.h"

#include <gtest/gtest.h>

#include "synth_world.h"

namespace geo {
namespace {

torch::Tensor border_mask(int64_t H, int64_t W, int64_t m) {
  auto mask = torch::zeros({1, 1, H, W});
  mask.slice(2, m, H - m).slice(3, m, W - m).fill_(1);
  return mask;
}

TEST(Synth, SameSeedSameImages) {
  const auto o = test::tiny_options();
  const SynthScene a(7, 20), b(7, 20), c(8, 20);
  EXPECT_TRUE(torch::equal(render_frame(a, 3, o).image, render_frame(b, 3, o).image));
  EXPECT_FALSE(torch::equal(render_frame(a, 3, o).image, render_frame(c, 3, o).image));
}

// turns = 2 doubles the sway's frequency: at every frame the path's lateral speed is twice that
// of turns = 1 at the doubled phase, so tan(heading) doubles at frame 0 (same phase) and the
// forward positions agree. Anything else in the world stays as it is.
TEST(Synth, TurnsScaleTheHeadingAndLeaveTheWorld) {
  const SynthScene gentle(7, 20), winding(7, 20, 2.0);
  const auto a = gentle.camera(0), b = winding.camera(0);
  const double tan_a = a.R[2] / a.R[0], tan_b = b.R[2] / b.R[0];  // R = [c 0 s; 0 1 0; -s 0 c]
  EXPECT_NEAR(tan_b, 2 * tan_a, 1e-12);
  EXPECT_DOUBLE_EQ(gentle.camera(5).c.z, winding.camera(5).c.z);
  ASSERT_EQ(gentle.boxes().size(), winding.boxes().size());
  for (size_t i = 0; i < gentle.boxes().size(); ++i) EXPECT_DOUBLE_EQ(gentle.boxes()[i].lo.z, winding.boxes()[i].lo.z);
  EXPECT_THROW(SynthScene(7, 20, 0.0), std::invalid_argument);
}

// Stop-and-go traffic: the camera stands for stretches (identical poses), the car ahead keeps its
// gap (its depth the same whether the camera moves or stands), a truck passes on the right while the
// camera stands, and every moving object is in the object map. Deterministic from the seed.
TEST(Synth, TrafficStandsStartsAndKeepsTheCarAhead) {
  const auto o = test::tiny_options();
  const SynthScene scene(11, 80, 1.0, true), again(11, 80, 1.0, true);
  int64_t standing = 0, moving = 0, truck_seen = 0;
  int leader = -1;
  for (size_t id = 0; id < scene.boxes().size(); ++id)
    if (scene.boxes()[id].follows_camera) leader = static_cast<int>(id);
  ASSERT_GE(leader, 0);
  EXPECT_TRUE(scene.is_moving(leader));
  // The leader's value in the object map is the one value the world lists as moving with the camera.
  const auto with_camera = synth_with_camera_objects(scene);
  ASSERT_EQ(with_camera.size(), 1u);
  std::vector<double> leader_depth;
  for (int64_t f = 1; f < 80; ++f) {
    const auto a = scene.camera(f - 1), b = scene.camera(f);
    if (!scene.camera_moves(f)) {
      ++standing;
      EXPECT_EQ(a.R, b.R) << f;
      EXPECT_EQ(a.c.z, b.c.z) << f;
      EXPECT_EQ(a.c.x, b.c.x) << f;
    } else {
      ++moving;
      EXPECT_GT(b.c.z - a.c.z, 0.3) << f;
    }
    if (f % 8 != 0) continue;
    const auto frame = render_frame(scene, f, o);
    const auto mask = synth_object_map(scene, frame.object) > 0;
    // The leader's pixels: moving objects all, the same depth at every frame (within the sway).
    const auto on_leader = frame.object == leader;
    EXPECT_TRUE(mask.masked_select(on_leader).all().item<bool>());
    EXPECT_TRUE(torch::equal(synth_object_map(scene, frame.object) == with_camera[0], on_leader)) << f;
    if (on_leader.sum().item<int64_t>() > 50)
      leader_depth.push_back(frame.depth[0].masked_select(on_leader).min().item<double>());
    // A truck beside a standing camera fills much of the image's right half.
    if (!scene.camera_moves(f) && mask.slice(1, o.width / 2).to(torch::kFloat32).mean().item<double>() > 0.3)
      ++truck_seen;
  }
  EXPECT_GT(standing, 15);
  EXPECT_GT(moving, 15);
  EXPECT_GT(truck_seen, 0);
  ASSERT_GE(leader_depth.size(), 5u);
  for (double d : leader_depth) EXPECT_NEAR(d, leader_depth[0], 0.05 * leader_depth[0]);
  EXPECT_TRUE(torch::equal(render_frame(scene, 33, o).image, render_frame(again, 33, o).image));
  // Without traffic the camera never stands.
  const SynthScene plain(11, 80);
  for (int64_t f = 1; f < 80; ++f) EXPECT_TRUE(plain.camera_moves(f));
  EXPECT_TRUE(synth_with_camera_objects(plain).empty());
}

// The exact flow holds for objects that move with the camera as for the others: it warps the next
// frame onto this one in traffic, whether the camera moves or stands.
TEST(Synth, TrafficFlowWarpsNextFrameOntoThisOne) {
  const auto o = test::tiny_options();
  const SynthScene scene(11, 80, 1.0, true);
  int64_t checked_standing = 0;
  for (int64_t f : {10, 20, 30, 40, 50}) {
    checked_standing += !scene.camera_moves(f + 1);
    const auto f0 = render_frame(scene, f, o), f1 = render_frame(scene, f + 1, o);
    const auto gt = render_flow(scene, f, o);
    const auto mask = gt.valid_noc.unsqueeze(0) * border_mask(o.height, o.width, 4);
    ASSERT_GT(mask.sum().item<double>(), 0.5 * o.height * o.width);
    const double warped =
        ((warp(f1.image.unsqueeze(0), gt.flow.unsqueeze(0), OutOfView::kBorder).image - f0.image.unsqueeze(0))
             .abs()
             .mean(1, true) *
         mask)
            .sum()
            .item<double>() /
        mask.sum().item<double>();
    EXPECT_LT(warped, 2.0 / 255) << "frame " << f;
  }
  EXPECT_GT(checked_standing, 0) << "no standing frame among those checked: the test needs another seed";
}

TEST(Synth, GroundTruthFlowWarpsNextFrameOntoThisOne) {
  const auto o = test::tiny_options();
  for (uint64_t seed : {1, 2, 3}) {
    const SynthScene scene(seed, 30);
    const auto f0 = render_frame(scene, 10, o), f1 = render_frame(scene, 11, o);
    const auto gt = render_flow(scene, 10, o);
    const auto mask = gt.valid_noc.unsqueeze(0) * border_mask(o.height, o.width, 4);
    ASSERT_GT(mask.sum().item<double>(), 0.5 * o.height * o.width);
    auto err = [&](const torch::Tensor& img) {
      return ((img - f0.image.unsqueeze(0)).abs().mean(1, true) * mask).sum().item<double>() /
             mask.sum().item<double>();
    };
    const double warped = err(warp(f1.image.unsqueeze(0), gt.flow.unsqueeze(0), OutOfView::kBorder).image);
    const double unwarped = err(f1.image.unsqueeze(0));
    EXPECT_LT(warped, 2.0 / 255) << "seed " << seed;
    EXPECT_GT(unwarped, 3 * warped) << "seed " << seed;
  }
}

TEST(Synth, RigidFlowFromDepthAndPosesMatchesStaticFlow) {
  const auto o = test::tiny_options();
  const SynthScene scene(4, 60);
  bool saw_mover = false;
  for (int64_t f : {5, 20, 35}) {
    const auto f0 = render_frame(scene, f, o);
    const auto gt = render_flow(scene, f, o);
    const auto src_from_tgt = inverse_transform(scene.camera(f + 1).matrix().unsqueeze(0))
                                  .matmul(scene.camera(f).matrix().unsqueeze(0))
                                  .to(torch::kFloat32);
    const auto rigid =
        rigid_flow(f0.depth.unsqueeze(0), src_from_tgt, o.intrinsics.K().to(torch::kFloat32).unsqueeze(0))[0];
    auto moving = torch::zeros({o.height, o.width}, torch::kBool);
    for (size_t id = 0; id < scene.boxes().size(); ++id)
      if (scene.is_moving(static_cast<int>(id))) moving |= f0.object == static_cast<int>(id);
    const auto valid = gt.valid_occ[0] > 0;
    const auto diff = (rigid - gt.flow).pow(2).sum(0).sqrt();
    const auto stat = valid & ~moving;
    EXPECT_LT(diff.masked_select(stat).max().item<double>(), 0.05) << "frame " << f;
    const auto mov = valid & moving;
    if (mov.sum().item<int64_t>() > 20) {
      saw_mover = true;
      EXPECT_GT(diff.masked_select(mov).mean().item<double>(), 0.1) << "frame " << f;
    }
  }
  EXPECT_TRUE(saw_mover) << "no moving car in view: the test needs another seed";
}

TEST(Synth, LidarLandsWhereTheDepthSaysThroughTheCalibration) {
  const auto o = test::tiny_options();
  const SynthScene scene(5, 20);
  const auto frame = render_frame(scene, 8, o);
  const auto pts = render_lidar(scene, 8, o);
  auto P = torch::zeros({3, 4}, torch::kFloat64);
  P.slice(1, 0, 3).copy_(o.intrinsics.K());
  VelodyneDepthOptions exact;
  exact.matlab_offset = false;
  exact.depth_is_velo_x = false;  // camera z, to compare with the rendered depth
  const auto lidar = velodyne_depth(pts, P.matmul(synth_cam_from_velo()), o.height, o.width, exact);
  const auto both = (lidar > 0) & (frame.depth[0] > 0);
  ASSERT_GT(both.sum().item<int64_t>(), 300);
  const auto rel = ((lidar - frame.depth[0]).abs() / frame.depth[0]).masked_select(both);
  EXPECT_LT(rel.median().item<double>(), 0.01);
  EXPECT_GT((rel < 0.05).to(torch::kFloat32).mean().item<double>(), 0.9);
}

TEST(Synth, WrittenWorldReadsBack) {
  const auto o = test::tiny_options();
  const auto root = test::write_small_world("world", 6, 1, 5);
  const SynthScene scene(synth_drive_seed(1, 0, 0), 6);  // drive 1
  const auto f2 = render_frame(scene, 2, o);
  const std::string drive = root + "/raw/" + synth_drive_folder(1);
  EXPECT_LE((read_image(drive + "/image_02/data/0000000002.png") - f2.image).abs().max().item<double>(),
            0.5 / 255 + 1e-6);
  EXPECT_LE(
      (read_depth_png(drive + "/proj_depth/groundtruth/image_02/0000000002.png") - f2.depth).abs().max().item<double>(),
      0.5 / 256 + 1e-6);
  const auto poses = read_poses(drive + "/poses.txt");
  EXPECT_EQ(poses.size(0), 6);
  EXPECT_TRUE(torch::allclose(poses[0], torch::eye(4, torch::kFloat64), 0, 1e-12));
  const auto calib = read_raw_calib(root + "/raw/" + kSynthDate, 2);
  EXPECT_TRUE(torch::allclose(calib.K(), o.intrinsics.K(), 0, 1e-9));
  EXPECT_TRUE(torch::allclose(calib.cam_from_velo, synth_cam_from_velo(), 0, 1e-12));
  EXPECT_EQ(read_velodyne(drive + "/velodyne_points/data/0000000002.bin").size(1), 4);
  const auto odo = read_odometry_calib(root + "/odometry/sequences/09/calib.txt");
  EXPECT_TRUE(torch::allclose(odo.P[2], calib.P_rect, 0, 1e-9));
  EXPECT_EQ(read_poses(root + "/odometry/poses/09.txt").size(0), 5);
  EXPECT_EQ(read_lines(root + "/odometry/sequences/09/times.txt").size(), 5u);
  const auto flow = read_flow_png(root + "/kitti2015/training/flow_occ/000000_10.png");
  EXPECT_EQ(flow.flow.size(2), o.width);
  EXPECT_GE(flow.valid.sum().item<double>(),
            read_flow_png(root + "/kitti2015/training/flow_noc/000000_10.png").valid.sum().item<double>());
  EXPECT_TRUE(read_key_values(root + "/kitti2015/training/calib_cam_to_cam/000000.txt").has("P_rect_02"));
  // Splits: frames 1..4 (those with both neighbours) of the training and of the test drive.
  const auto train = read_split(root + "/raw/splits/eigen_zhou/train_files.txt");
  EXPECT_EQ(train.size(), 4u);
  EXPECT_EQ(read_split(root + "/raw/splits/eigen/test_files.txt").size(), 4u);
  EXPECT_EQ(*read_scene_list(root + "/raw/splits/eigen/test_scenes.txt").begin(), "2011_01_01_drive_0002");
  // The training dataset reads snippets at another size with intrinsics scaled to match.
  SequenceDatasetOptions so;
  so.root = root + "/raw";
  so.height = 32;
  so.width = 104;
  SequenceDataset ds(train, so);
  ASSERT_EQ(ds.size(), 4u);
  const auto s = ds.get(0);
  EXPECT_EQ(s.frames.sizes(), (torch::IntArrayRef{3, 3, 32, 104}));
  EXPECT_NEAR(s.K[0][0].item<double>(), o.intrinsics.fx / 2, 1e-4);
  EXPECT_NEAR(s.K[1][2].item<double>(), o.intrinsics.cy / 2, 1e-4);
  // A missing neighbour drops the entry; a corrupt frame names its file.
  std::filesystem::remove(drive + "/image_02/data/0000000000.png");
  EXPECT_EQ(SequenceDataset(train, so).dropped(), 1u);
  test::write_text(drive + "/image_02/data/0000000003.png", "garbage");
  GEO_EXPECT_THROW_WITH(SequenceDataset(train, so).get(1), "0000000003.png", "cannot decode");
}

// data.format synthetic trains on exactly what geo_synth writes: the same snippets, in the same
// order, with the same pixels (both 8-bit), at the preset's size.
TEST(Synth, InMemorySnippetsEqualTheWrittenWorldsBitForBit) {
  const auto root = test::write_small_world("memory_vs_files", 12, 0, 3);
  const auto list = read_split(root + "/raw/splits/eigen_zhou/train_files.txt");
  SequenceDatasetOptions so;
  so.root = root + "/raw";
  so.height = 64;
  so.width = 208;
  const SequenceDataset files(list, so);
  auto world = synth_world_at("tiny", 64, 208);
  world.train_drives = 1;
  world.frames_per_drive = 12;
  const auto memory = render_synth_snippets(world, 3);
  ASSERT_EQ(memory.train->size(), files.size());
  EXPECT_EQ(memory.val->size(), read_split(root + "/raw/splits/eigen_zhou/val_files.txt").size());
  for (size_t i = 0; i < files.size(); ++i) {
    const auto a = files.get(i), b = memory.train->get(i);
    EXPECT_EQ(a.id, b.id);
    EXPECT_TRUE(torch::equal(a.frames, b.frames)) << a.id << ": " << (a.frames - b.frames).abs().max().item<float>();
    EXPECT_TRUE(torch::allclose(a.K, b.K, 0, 1e-4)) << a.id;
  }
}

}  // namespace
}  // namespace geo
