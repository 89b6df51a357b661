// The learning check on real driving video: geo_train's video path (configs/video.yaml: frame folders,
// the camera in pixels of the frames, per-pixel minimum reprojection and auto-masking) trains on the
// first 36 frames of two real KITTI odometry runs (tests/data/kitti_real: nearly straight driving and
// a right turn) and is scored on what it never saw:
//   - camera motion: 5-frame snippet ATE against the ground-truth poses on the last frames of each
//     run (snippets centred on frames 39..48, every frame of them after the training frames), against
//     no motion at all;
//   - depth: median-scaled AbsRel against the Velodyne of ten frames of another drive (KITTI raw,
//     2011_09_26, Eigen protocol), against the untrained network and the best constant depth.
// The same training with the photometric term off (loss weight 0: only the smoothness term trains)
// must fail: what passes is learnt from the images, not from the schedule or the smoothness prior.
// That control runs 100 of the 400 iterations: with no photometric gradient the PoseNet learns
// nothing and the depth only smooths, and its scores after 100, 200, 300 and 400 iterations were the
// same to the fourth digit in AbsRel and failed the check at each (docs/measured/ci-times.md).
// And int8 (calibrated on 8 training frames) keeps the trained model's scores within 2% / 5%.
#include "core/config.h"
#include "core/files.h"
#include "data/image_io.h"
#include "data/kitti/calib.h"
#include "eval/predictor.h"
#include "eval/protocols.h"
#include "eval/sources.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>

#include "eval_result.h"
#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

const std::string kData = GEO_TEST_DATA_DIR "/kitti_real";
const std::vector<std::string> kRuns = {"forward", "turn"};
constexpr int kTrainFrames = 36;  // frames 0..35 train; snippets centred on 39..48 are scored

using test::metric_of;

struct Scores {
  double abs_rel = 0;
  std::vector<double> ate;  // one per run of kRuns
};

class RealVideo : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = test::fresh_dir("real_video");
    // The training clips: frame folders of the first frames of each run.
    std::vector<std::string> clips;
    for (const auto& run : kRuns) {
      const std::string clip = root_ + "/clips/" + run;
      fs::create_directories(clip);
      for (int f = 0; f < kTrainFrames; ++f) {
        const std::string name = zero_padded(f, 6) + ".png";
        fs::copy_file(kData + "/odometry_" + run + "/frames/" + name, clip + "/" + name);
      }
      clips.push_back(clip);
    }
    // The camera of the frames: P0 of the committed calib.txt (both runs: one sequence).
    const auto P0 = read_key_values(kData + "/odometry_forward/calib.txt").projection("P0");
    const std::string P = format_numbers(P0);
    const std::string intrinsics = "[" + format_numbers(P0[0][0]) + "," + format_numbers(P0[1][1]) + "," +
                                   format_numbers(P0[0][2]) + "," + format_numbers(P0[1][2]) + "]";
    // The scoring root: KITTI raw (eigen) as committed, and each run as a KITTI odometry sequence.
    // The odometry protocol reads image_2/ with P2 of calib.txt; these frames are the grey left
    // camera's (P0), whose matrix stands in for all four.
    fs::create_directories(root_ + "/eval/odometry/poses");
    fs::create_directory_symlink(kData + "/raw", root_ + "/eval/raw");
    for (size_t i = 0; i < kRuns.size(); ++i) {
      const std::string seq = root_ + "/eval/odometry/sequences/" + sequence(i);
      fs::create_directories(seq);
      fs::create_directory_symlink(kData + "/odometry_" + kRuns[i] + "/frames", seq + "/image_2");
      test::write_text(seq + "/calib.txt",
                       "P0: " + P + "\nP1: " + P + "\nP2: " + P + "\nP3: " + P + "\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
      fs::copy_file(kData + "/odometry_" + kRuns[i] + "/poses.txt",
                    root_ + "/eval/odometry/poses/" + sequence(i) + ".txt");
      std::string centres;
      for (int c = kTrainFrames + 3; c <= 48; ++c) centres += sequence(i) + " " + std::to_string(c) + " l\n";
      test::write_text(root_ + "/eval/heldout_" + sequence(i) + ".txt", centres);
    }
    std::string depth_frames;
    for (int f = 0; f < 10; ++f) depth_frames += "2011_09_26/2011_09_26_drive_0000_sync " + std::to_string(f) + " l\n";
    test::write_text(root_ + "/eval/depth_frames.txt", depth_frames);

    // configs/video.yaml as a user runs it on these frames, at a size and length CI affords.
    std::string videos = "data.videos=[";
    for (size_t i = 0; i < clips.size(); ++i) videos += (i ? "," : "") + clips[i];
    videos += "]";
    const std::vector<std::string> common = {videos,
                                             "data.camera.intrinsics=" + intrinsics,
                                             "data.video.val_fraction=0",
                                             "data.height=64",
                                             "data.width=208",
                                             "data.num_workers=1",
                                             "model.encoder_depth=18",
                                             "model.bn_momentum=0.1",
                                             "stages.0.iterations=400",
                                             "stages.0.learning_rate=5.0e-4",
                                             "logging.interval=100",
                                             "logging.summary_interval=0",
                                             "logging.checkpoint_interval=400",
                                             "logging.val_interval=0",
                                             "run.seed=1",
                                             "run.threads=2"};
    config_ = load_config(resolve_config_path("video.yaml"), common);
    auto without_photometric = common;
    without_photometric.push_back("stages.0.weights.rigid=0");
    without_photometric.push_back("stages.0.iterations=100");
    const Config blind = load_config(resolve_config_path("video.yaml"), without_photometric);
    TrainOptions t;
    t.run_dir = root_ + "/run";
    trained_ok_ = train(config_, t) == 0;
    t.run_dir = root_ + "/run_without_photometric";
    blind_ok_ = train(blind, t) == 0;
  }
  void SetUp() override {
    ASSERT_TRUE(trained_ok_) << "the real-video training failed";
    ASSERT_TRUE(blind_ok_) << "the training without the photometric term failed";
  }

  static std::string sequence(size_t i) { return "0" + std::to_string(i + 1); }

  // Depth and per-run ATE of a model (null: the trivial baseline: constant depth, no motion).
  static Scores score(Predictor* p) {
    auto run = [&](EvalOptions e) { return p ? evaluate(e, *p) : evaluate(e, *trivial_source()); };
    Scores s;
    EvalOptions depth;
    depth.split = "eigen";
    depth.data_root = root_ + "/eval";
    depth.split_file = root_ + "/eval/depth_frames.txt";
    s.abs_rel = metric_of(run(depth), "abs_rel");
    for (size_t i = 0; i < kRuns.size(); ++i) {
      EvalOptions odometry;
      odometry.split = "odometry";
      odometry.data_root = root_ + "/eval";
      odometry.sequence = sequence(i);
      odometry.split_file = root_ + "/eval/heldout_" + sequence(i) + ".txt";
      s.ate.push_back(metric_of(run(odometry), "ate_mean"));
    }
    return s;
  }

  // The trained run's scores: computed once, read by the tests that need them.
  static const Scores& trained_scores() {
    static const Scores scores = [] {
      Predictor trained(root_ + "/run", "cpu");
      return score(&trained);
    }();
    return scores;
  }

  static void print(const char* what, const Scores& s) {
    std::printf("real-video check %-26s abs_rel %.4f  ate forward %.4f  ate turn %.4f\n", what, s.abs_rel, s.ate[0],
                s.ate[1]);
  }

  static std::string root_;
  static Config config_;
  static bool trained_ok_, blind_ok_;
};
std::string RealVideo::root_;
Config RealVideo::config_;
bool RealVideo::trained_ok_ = false, RealVideo::blind_ok_ = false;

// Margins, from what this schedule gave (2026-11-26, LibTorch 1.13; checkpoints of one longer run
// after 400, 500, 600 and 700 iterations): depth AbsRel 0.334-0.343 against 0.376 for the best
// constant (0.89-0.91x); ATE of the unseen end of the straight run 0.02-0.04 m against 0.93 m for no
// motion, of the turn 0.44-0.51 m against 1.10 m (0.40-0.47x). Depth must be 5% below the better
// baseline (ten frames of one drive: a smaller gain would be within what another seed moves), motion
// below 0.6x no motion on each run (the turn's rotation is what a short run learns last).
constexpr double kDepthMargin = 0.95, kMotionMargin = 0.6;

bool passes(const Scores& s, const Scores& untrained, const Scores& trivial) {
  bool ok = s.abs_rel < kDepthMargin * std::min(untrained.abs_rel, trivial.abs_rel);
  for (size_t i = 0; i < s.ate.size(); ++i) ok = ok && s.ate[i] < kMotionMargin * trivial.ate[i];
  return ok;
}

TEST_F(RealVideo, DepthAndMotionOfUnseenFramesBeatTheBaselines) {
  Predictor untrained(config_, "cpu");
  const Scores& t = trained_scores();
  const Scores u = score(&untrained), v = score(nullptr);
  print("trained", t);
  print("untrained", u);
  print("constant depth, no motion", v);
  EXPECT_LT(t.abs_rel, kDepthMargin * std::min(u.abs_rel, v.abs_rel)) << "depth of unseen frames";
  for (size_t i = 0; i < kRuns.size(); ++i)
    EXPECT_LT(t.ate[i], kMotionMargin * v.ate[i]) << "camera motion of the unseen end of " << kRuns[i];
  EXPECT_TRUE(passes(t, u, v));
}

// Forward driving is footage that teaches: training says nothing of a clip unlikely to teach depth
// (neither the frame selection's warning nor the auto-masked share's: 62% over the first 50 steps
// from random weights, falling from there).
TEST_F(RealVideo, ForwardDrivingIsNotCalledHardFootage) {
  const std::string log = test::read_file(root_ + "/run/train.log");
  EXPECT_EQ(log.find("unlikely to teach depth"), std::string::npos) << log;
  EXPECT_NE(log.find("of pixels auto-masked"), std::string::npos) << "the progress lines carry the share";
}

// int8 (geo::Model::quantize_int8) on real frames: calibrated on the first 8 training frames of the
// straight run, the trained model keeps its accuracy on the unseen frames: AbsRel within 2%
// (relative) and each run's ATE within 5% of fp32's.
TEST_F(RealVideo, Int8KeepsTheAccuracyOfFp32) {
  std::vector<torch::Tensor> frames;
  for (int f = 0; f < 8; ++f) frames.push_back(read_image(root_ + "/clips/forward/" + zero_padded(f, 6) + ".png"));
  Predictor int8(root_ + "/run", "cpu");
  int8.quantize_int8(frames);
  const Scores& a = trained_scores();
  const Scores b = score(&int8);
  print("fp32", a);
  print("int8", b);
  EXPECT_LE(b.abs_rel, 1.02 * a.abs_rel) << "AbsRel: int8 " << b.abs_rel << ", fp32 " << a.abs_rel;
  for (size_t i = 0; i < kRuns.size(); ++i)
    EXPECT_LE(b.ate[i], 1.05 * a.ate[i]) << "ATE of " << kRuns[i] << ": int8 " << b.ate[i] << ", fp32 " << a.ate[i];
}

TEST_F(RealVideo, WithoutThePhotometricTermTheCheckFails) {
  Predictor blind(root_ + "/run_without_photometric", "cpu"), untrained(config_, "cpu");
  const Scores b = score(&blind), u = score(&untrained), v = score(nullptr);
  print("without photometric term", b);
  EXPECT_FALSE(passes(b, u, v)) << "the check passes without the photometric term: it does not measure learning";
}

}  // namespace
}  // namespace geo
