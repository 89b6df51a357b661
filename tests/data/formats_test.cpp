// Calibration, split lists, pose files, Velodyne scans and the Eigen-protocol ground truth:
// hand-made inputs with known answers, malformed inputs with the messages they must give, and the
// real KITTI excerpts when ../shared/kitti_samples is present.
#include "core/config.h"
#include "core/files.h"
#include "data/kitti/calib.h"
#include "data/kitti/splits.h"
#include "data/text_io.h"
#include "data/kitti/velodyne_depth.h"

#include <gtest/gtest.h>

#include <cmath>

#include <limits>
#include <set>

#include "test_util.h"

namespace geo {
namespace {

TEST(Calib, ParsesKeyValuesAndSkipsCalibTime) {
  const auto kv = parse_key_values(
      "calib_time: 09-Jan-2012 13:57:47\nP_rect_02: 1 2 3 4 5 6 7 8 9 10 11 12\nS_rect_02: 1242 375\n", "x.txt");
  EXPECT_FALSE(kv.has("calib_time"));
  const auto P = kv.matrix("P_rect_02", 3, 4);
  EXPECT_EQ(P[1][2].item<double>(), 7.0);
  EXPECT_EQ(kv.get("S_rect_02", 2)[0], 1242.0);
}

TEST(Calib, MalformedInputsNameFileLineAndKey) {
  GEO_EXPECT_THROW_WITH(parse_key_values("P0: 1 2 x 4\n", "calib.txt"), "calib.txt line 1", "'P0'",
                        "'x' is not a number");
  const auto kv = parse_key_values("R: 1 2 3\n", "velo.txt");
  GEO_EXPECT_THROW_WITH(kv.get("T", 3), "velo.txt", "missing calibration entry 'T'");
  GEO_EXPECT_THROW_WITH(kv.matrix("R", 3, 3), "velo.txt", "'R' has 3 numbers, expected 9");
  GEO_EXPECT_THROW_WITH(read_key_values("/nonexistent/calib.txt"), "/nonexistent/calib.txt", "cannot open");
}

TEST(Calib, RawAndOdometryFiles) {
  const auto dir = test::fresh_dir("calib");
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   "calib_time: now\nR_rect_00: 1 0 0 0 1 0 0 0 1\nP_rect_02: 100 0 50 10 0 100 20 0 0 0 1 0\n");
  test::write_text(dir + "/calib_velo_to_cam.txt", "calib_time: now\nR: 0 -1 0 0 0 -1 1 0 0\nT: 1 2 3\n");
  const auto c = read_raw_calib(dir, 2);
  EXPECT_EQ(c.K()[0][0].item<double>(), 100.0);
  // A point 10 m ahead of the scanner: camera (y, z, x) = (-0, -0, 10) + T = (1, 2, 13).
  const auto x = c.img_from_velo().matmul(torch::tensor({10.0, 0.0, 0.0, 1.0}, torch::kFloat64));
  EXPECT_NEAR(x[0].item<double>(), 100 * 1 + 50 * 13 + 10, 1e-9);
  EXPECT_NEAR(x[2].item<double>(), 13.0, 1e-9);
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 3), "calib_cam_to_cam.txt", "'P_rect_03'");
  test::write_text(dir + "/calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nP1: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_odometry_calib(dir + "/calib.txt"), "calib.txt", "'P2'");
}

TEST(Calib, NonFiniteOrImplausibleFocalLengthsAreRejectedNamingFileAndKey) {
  const auto dir = test::fresh_dir("calib_nan");
  test::write_text(dir + "/calib_velo_to_cam.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
  const std::string rect = "R_rect_00: 1 0 0 0 1 0 0 0 1\n";
  test::write_text(dir + "/calib_cam_to_cam.txt", rect + "P_rect_02: nan 0 50 0 0 100 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt", "'P_rect_02'", "non-finite");
  test::write_text(dir + "/calib_cam_to_cam.txt", rect + "P_rect_02: -7 0 50 0 0 100 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt", "'P_rect_02'", "fx = -7", "not plausible");
  test::write_text(dir + "/calib_cam_to_cam.txt", rect + "P_rect_02: 100 0 50 0 0 1e9 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "'P_rect_02'", "not plausible");
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   rect + "P_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\nR_rect_02: inf 0 0 0 1 0 0 0 1\n");
  EXPECT_NO_THROW(read_raw_calib(dir, 2));  // entries that are not used are not checked
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   "R_rect_00: 1 0 0 0 1 0 0 0 inf\nP_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "'R_rect_00'", "non-finite");
  // An image size that is not one (found by the fuzzer: 1e20 did not fit an integer).
  for (const std::string size : {"1e20 375", "1242 0", "1242.5 375", "nan 375", "-1242 375"}) {
    test::write_text(dir + "/calib_cam_to_cam.txt",
                     rect + "P_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\nS_rect_02: " + size + "\n");
    GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt", "'S_rect_02'", "not an image size");
  }
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   rect + "P_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\nS_rect_02: 1.242000e+03 3.750000e+02\n");
  EXPECT_EQ(read_raw_calib(dir, 2).width, 1242);
  EXPECT_EQ(read_raw_calib(dir, 2).height, 375);
  // A key given twice: which one is meant cannot be told.
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   rect + "P_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\nP_rect_02: 7 0 50 0 0 7 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt line 3 ('P_rect_02')",
                        "given twice (lines 2 and 3)");
  // Finite but absurd: a principal point at 1e30, a zero or a mirroring "rotation".
  test::write_text(dir + "/calib_cam_to_cam.txt", rect + "P_rect_02: 100 0 1e30 0 0 100 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt", "'P_rect_02'", "principal point",
                        "not plausible");
  test::write_text(dir + "/calib_cam_to_cam.txt",
                   "R_rect_00: 0 0 0 0 0 0 0 0 0\nP_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_cam_to_cam.txt", "'R_rect_00' is not a rotation");
  test::write_text(dir + "/calib_cam_to_cam.txt", rect + "P_rect_02: 100 0 50 0 0 100 20 0 0 0 1 0\n");
  test::write_text(dir + "/calib_velo_to_cam.txt", "R: -1 0 0 0 1 0 0 0 1\nT: 0 0 0\n");
  GEO_EXPECT_THROW_WITH(read_raw_calib(dir, 2), "calib_velo_to_cam.txt", "'R' is not a rotation", "det -1");
}

TEST(Splits, ReadsBothFormatsAndRejectsOthers) {
  const auto a = parse_split_line("2011_09_26/2011_09_26_drive_0022_sync 473 r", "f");
  EXPECT_EQ(a.folder, "2011_09_26/2011_09_26_drive_0022_sync");
  EXPECT_EQ(a.frame, 473);
  EXPECT_EQ(a.camera(), 3);
  EXPECT_EQ(a.image_path("/k", -1), "/k/2011_09_26/2011_09_26_drive_0022_sync/image_03/data/0000000472.png");
  const auto b = parse_split_line("2011_09_26/2011_09_26_drive_0002_sync/image_02/data/0000000069.png", "f");
  EXPECT_EQ(b.folder, "2011_09_26/2011_09_26_drive_0002_sync");
  EXPECT_EQ(b.frame, 69);
  EXPECT_EQ(b.side, 'l');
  EXPECT_EQ(b.date(), "2011_09_26");
  EXPECT_EQ(b.drive(), "2011_09_26_drive_0002_sync");
  GEO_EXPECT_THROW_WITH(parse_split_line("2011_09_26 x l", "list.txt line 4"), "list.txt line 4", "'2011_09_26 x l'");
  GEO_EXPECT_THROW_WITH(parse_split_line("a 1 q", "list.txt line 2"), "list.txt line 2");
}

TEST(Splits, ExcludesTestScenesAndStaticFrames) {
  std::vector<SplitEntry> e = {parse_split_line("d/2011_09_26_drive_0117_sync 5 l", ""),
                               parse_split_line("d/2011_09_26_drive_0009_sync 386 l", ""),
                               parse_split_line("d/2011_09_26_drive_0009_sync 387 r", ""),
                               parse_split_line("d/2011_09_26_drive_0001_sync 3 l", "")};
  const auto dir = test::fresh_dir("splits");
  test::write_text(dir + "/static.txt", "2011_09_26 2011_09_26_drive_0009_sync 0000000386\n");
  EXPECT_EQ(exclude_entries(e, {"2011_09_26_drive_0117"}, read_static_frames(dir + "/static.txt")), 2u);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].frame, 387);
  EXPECT_EQ(e[1].frame, 3);
}

TEST(Splits, ShippedListsParse) {
  const std::string dir = shipped_config_dir() + "/splits";
  EXPECT_EQ(read_split(dir + "/eigen/test_files.txt").size(), 697u);
  EXPECT_EQ(read_split(dir + "/eigen_zhou/train_files.txt").size(), 39810u);
  EXPECT_EQ(read_split(dir + "/eigen_zhou/val_files.txt").size(), 4424u);
  EXPECT_EQ(read_scene_list(dir + "/eigen/test_scenes.txt").size(), 28u);
}

TEST(TextFormats, PoseFileRoundTripAndErrors) {
  const auto dir = test::fresh_dir("poses");
  auto poses = torch::eye(4, torch::kFloat64).repeat({3, 1, 1});
  poses[1][0][3] = 1.5;
  poses[2][1][2] = -0.25;
  write_poses(dir + "/p.txt", poses);
  EXPECT_TRUE(torch::allclose(read_poses(dir + "/p.txt"), poses, 0, 1e-9));
  test::write_text(dir + "/bad.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n");
  GEO_EXPECT_THROW_WITH(read_poses(dir + "/bad.txt"), "bad.txt line 2", "expected 12 numbers");
  // An all-zero pose (a failed prediction) cannot be inverted: rejected by line, not by linalg.inv.
  test::write_text(dir + "/zero.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n0 0 0 0 0 0 0 0 0 0 0 0\n");
  GEO_EXPECT_THROW_WITH(read_poses(dir + "/zero.txt"), "zero.txt line 2", "determinant 0.000000");
  test::write_text(dir + "/scaled.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n");
  GEO_EXPECT_THROW_WITH(read_poses(dir + "/scaled.txt"), "scaled.txt line 1", "determinant 8.000000");
  test::write_text(dir + "/nan.txt", "1 0 0 nan 0 1 0 0 0 0 1 0\n");
  GEO_EXPECT_THROW_WITH(read_poses(dir + "/nan.txt"), "nan.txt line 1", "NaN or infinity");
}

TEST(TextFormats, VelodyneRoundTripAndTruncation) {
  const auto dir = test::fresh_dir("velo");
  const auto pts = torch::arange(12, torch::kFloat32).reshape({3, 4});
  write_velodyne(dir + "/a.bin", pts);
  EXPECT_TRUE(torch::equal(read_velodyne(dir + "/a.bin"), pts));
  test::write_text(dir + "/b.bin", std::string(20, '\0'));
  GEO_EXPECT_THROW_WITH(read_velodyne(dir + "/b.bin"), "b.bin", "not a multiple of 16");
}

TEST(VelodyneDepth, EigenProtocolByHand) {
  // Identity-like projection: image = (f*y/x + c, ..., x) with the scanner looking along x.
  const auto P =
      torch::tensor({0.0, 10.0, 0.0, 0.0, 0.0, 0.0, 10.0, 0.0, 1.0, 0.0, 0.0, 0.0}, torch::kFloat64).view({3, 4});
  // Points at x = 5 (u = 10*y/5), two on one pixel (nearest kept), one behind, one off the image.
  const auto pts = torch::tensor({5.0f, 1.0f, 1.0f, 0.f,   // u = 2, v = 2 -> pixel (1,1) with -1
                                  4.0f, 0.8f, 0.8f, 0.f,   // same pixel, nearer
                                  -5.0f, 1.0f, 1.0f, 0.f,  // behind
                                  5.0f, 50.f, 1.0f, 0.f})  // u = 100: outside
                       .view({4, 4});
  const auto d = velodyne_depth(pts, P, 4, 5);
  EXPECT_EQ(d[1][1].item<float>(), 4.0f);
  EXPECT_EQ((d > 0).sum().item<int64_t>(), 1);
  VelodyneDepthOptions exact;
  exact.matlab_offset = false;
  EXPECT_EQ(velodyne_depth(pts, P, 4, 5, exact)[2][2].item<float>(), 4.0f);
}

TEST(VelodyneDepth, NonFiniteAndFarOffPointsAreLeftOutAndCounted) {
  const auto P =
      torch::tensor({0.0, 10.0, 0.0, 0.0, 0.0, 0.0, 10.0, 0.0, 1.0, 0.0, 0.0, 0.0}, torch::kFloat64).view({3, 4});
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  const auto pts = torch::tensor({5.0f,   1.0f,  1.0f,  0.f,   // pixel (1,1), depth 5
                                  nan,    1.0f,  1.0f,  0.f,   // NaN x
                                  5.0f,   inf,   1.0f,  0.f,   // infinite y
                                  5.0f,   1.0f,  1.0f,  nan,   // NaN reflectance: a usable point
                                  1e-30f, 1e30f, 1e30f, 0.f})  // projects beyond int64: ignored, no UB
                       .view({5, 4});
  EXPECT_EQ(count_non_finite_points(pts), 2);
  const auto d = velodyne_depth(pts, P, 4, 5);
  EXPECT_EQ(d[1][1].item<float>(), 5.0f);
  EXPECT_EQ((d > 0).sum().item<int64_t>(), 1);
}

// GeoNet's kitti_raw_stereo frames: every drive on disk but the test scenes, both cameras, the static
// frames removed from the list before snippets are formed (a neighbour is the next moving frame).
TEST(Splits, RawDriveSnippetsAreGeoNetsFrameListsWithoutStaticFrames) {
  const auto root = test::fresh_dir("raw_drives");
  auto frames = [&](const std::string& drive, const char* camera, int n) {
    const std::string dir = root + "/2011_09_26/" + drive + "/" + camera + "/data";
    std::filesystem::create_directories(dir);
    for (int f = 0; f < n; ++f) test::write_text(dir + "/" + zero_padded(f, 10) + ".png", "");
  };
  frames("2011_09_26_drive_0001_sync", "image_02", 6);
  frames("2011_09_26_drive_0001_sync", "image_03", 6);
  frames("2011_09_26_drive_0002_sync", "image_02", 6);                              // a test scene
  frames("2011_09_26_drive_0003_sync", "image_02", 2);                              // shorter than a snippet
  std::filesystem::create_directories(root + "/calibration/x_sync/image_02/data");  // not a date folder
  const std::set<std::string> statics = {static_key("2011_09_26_drive_0001_sync", 2),
                                         static_key("2011_09_26_drive_0001_sync", 3)};
  const std::set<std::string> tests = {"2011_09_26_drive_0002"};
  const auto e = raw_drive_snippets(root, tests, statics, 3);
  ASSERT_EQ(e.size(), 4u);  // frames 0 1 4 5 left in each camera: targets 1 and 4
  EXPECT_EQ(e[0].snippet, (std::vector<int64_t>{0, 1, 4}));
  EXPECT_EQ(e[0].frame, 1);
  EXPECT_EQ(e[1].snippet, (std::vector<int64_t>{1, 4, 5}));
  EXPECT_EQ(e[1].frame, 4);
  EXPECT_EQ(e[0].side, 'l');
  EXPECT_EQ(e[2].side, 'r');
  EXPECT_EQ(e[2].line, "2011_09_26/2011_09_26_drive_0001_sync 1 r");
  const std::string drive = root + "/2011_09_26/2011_09_26_drive_0001_sync";
  EXPECT_EQ(e[1].image_path(root, -1), drive + "/image_02/data/0000000001.png");
  EXPECT_EQ(e[1].image_path(root, 1), drive + "/image_02/data/0000000005.png");
  EXPECT_EQ(e[0].image_path(root, 1), drive + "/image_02/data/0000000004.png");  // 2 and 3 do not move
  EXPECT_EQ(e[3].image_path(root, 0), drive + "/image_03/data/0000000004.png");
  // Without static frames: frame - 1 .. frame + 1, targets 1..4 in both cameras.
  const auto all = raw_drive_snippets(root, tests, {}, 3);
  ASSERT_EQ(all.size(), 8u);
  EXPECT_EQ(all[2].snippet, (std::vector<int64_t>{2, 3, 4}));
  EXPECT_EQ(raw_drive_snippets(root, tests, {}, 5).size(), 4u);  // targets 2 and 3
  EXPECT_EQ(raw_drives_on_disk(root, tests), (std::set<std::string>{"2011_09_26_drive_0001", "2011_09_26_drive_0003"}));
  // A list entry keeps frame - L/2 .. frame + L/2.
  EXPECT_EQ(parse_split_line("2011_09_26/2011_09_26_drive_0001_sync 3 l", "x").image_path(root, 1),
            drive + "/image_02/data/0000000004.png");
}

// ---- real KITTI excerpts (skipped when ../shared/kitti_samples is absent) ----

TEST(KittiSamples, CalibrationAndVelodyneGroundTruth) {
  const auto root = test::kitti_samples();
  if (root.empty()) GTEST_SKIP() << "../shared/kitti_samples not present";
  const auto calib = read_raw_calib(root + "/raw/2011_09_26", 2);
  EXPECT_NEAR(calib.K()[0][0].item<double>(), 721.5377, 1e-4);
  const auto pts =
      read_velodyne(root + "/raw/2011_09_26/2011_09_26_drive_0000_sync/velodyne_points/data/0000000000.bin");
  const auto depth = velodyne_depth(pts, calib.img_from_velo(), 375, 1242);
  // The reference (monodepth2's generate_depth_map, as the Eigen protocol computes it) written out
  // from the files' own matrices: P_rect_02 R_rect_00 [R|T]velo_to_cam, points ahead of the scanner,
  // pixel = round(projection) - 1 (MATLAB), depth = the scanner's x, the nearest point per pixel.
  const auto cam = read_key_values(root + "/raw/2011_09_26/calib_cam_to_cam.txt");
  const auto velo = read_key_values(root + "/raw/2011_09_26/calib_velo_to_cam.txt");
  auto Rt = torch::eye(4, torch::kFloat64), R0 = torch::eye(4, torch::kFloat64);
  Rt.slice(0, 0, 3).slice(1, 0, 3).copy_(velo.matrix("R", 3, 3));
  Rt.slice(0, 0, 3).select(1, 3).copy_(velo.matrix("T", 3, 1).view({3}));
  R0.slice(0, 0, 3).slice(1, 0, 3).copy_(cam.matrix("R_rect_00", 3, 3));
  const auto P = cam.matrix("P_rect_02", 3, 4).matmul(R0).matmul(Rt);
  auto reference = torch::zeros({375, 1242}, torch::kFloat32);
  auto r = reference.accessor<float, 2>();
  const auto p = pts.to(torch::kFloat64);
  const auto a = p.accessor<double, 2>();
  const auto m = P.accessor<double, 2>();
  int64_t projected = 0;
  for (int64_t i = 0; i < p.size(0); ++i) {
    if (a[i][0] < 0) continue;
    double x[3];
    for (int k = 0; k < 3; ++k) x[k] = m[k][0] * a[i][0] + m[k][1] * a[i][1] + m[k][2] * a[i][2] + m[k][3];
    if (x[2] <= 0) continue;
    const double u = std::round(x[0] / x[2]) - 1, v = std::round(x[1] / x[2]) - 1;
    if (u < 0 || v < 0 || u >= 1242 || v >= 375) continue;
    ++projected;
    float& cell = r[static_cast<int64_t>(v)][static_cast<int64_t>(u)];
    const auto d = static_cast<float>(a[i][0]);
    if (cell == 0 || d < cell) cell = d;
  }
  EXPECT_GT(projected, 10000);  // a scan, not an empty file
  EXPECT_TRUE(torch::equal(depth, reference))
      << (depth != reference).sum().item<int64_t>() << " pixels differ of " << (reference > 0).sum().item<int64_t>();
}

TEST(KittiSamples, OdometryPoses) {
  const auto root = test::kitti_samples();
  if (root.empty()) GTEST_SKIP() << "../shared/kitti_samples not present";
  const auto poses = read_poses(root + "/odometry/poses/09.txt");
  EXPECT_EQ(poses.size(0), 1591);
  EXPECT_TRUE(torch::allclose(poses[0], torch::eye(4, torch::kFloat64), 0, 1e-9));
  EXPECT_EQ(read_poses(root + "/odometry/poses/10.txt").size(0), 1201);
}

// The .npy header is a Python dict: read whatever its spacing, so that a Fortran-order array
// written without spaces is refused, never read as C order.
TEST(Npy, TheHeaderIsReadWhateverItsSpacing) {
  const auto dir = test::fresh_dir("npy_header");
  const float values[6] = {1, 2, 3, 4, 5, 6};
  const std::string data(reinterpret_cast<const char*>(values), sizeof values);
  test::write_text(dir + "/c.npy", test::npy_bytes("{'descr':'<f4','fortran_order':False,'shape':(2,3)}", data));
  const auto t = read_npy(dir + "/c.npy");
  EXPECT_EQ(t.sizes(), (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(t[1][0].item<float>(), 4.0f);
  test::write_text(dir + "/f.npy", test::npy_bytes("{'descr':'<f4','fortran_order':True,'shape':(2,3)}", data));
  GEO_EXPECT_THROW_WITH(read_npy(dir + "/f.npy"), "f.npy: Fortran-order arrays are not supported");
  test::write_text(dir + "/b.npy",
                   test::npy_bytes("{'descr': '>f4', 'fortran_order': False, 'shape': (2, 3), }", data));
  GEO_EXPECT_THROW_WITH(read_npy(dir + "/b.npy"), "'descr' is '>f4'", "little-endian");
  test::write_text(dir + "/o.npy", test::npy_bytes("{'descr': '<f4', 'fortran_order': 0, 'shape': (2, 3), }", data));
  GEO_EXPECT_THROW_WITH(read_npy(dir + "/o.npy"), "'fortran_order' is '0'");
  test::write_text(dir + "/s.npy", test::npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': 6, }", data));
  GEO_EXPECT_THROW_WITH(read_npy(dir + "/s.npy"), "'shape' is '6', not a tuple");
}

}  // namespace
}  // namespace geo
