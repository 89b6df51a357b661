#include "core/config.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include <sys/stat.h>
#include <filesystem>
#include <fstream>
#include <tuple>
#include <vector>

#include "test_util.h"

namespace {

using geo::Config;
using geo::ConfigError;

// Runs `fn` and returns the ConfigError message (fails the test if nothing is thrown).
template <class Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const ConfigError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a ConfigError";
  return "";
}

TEST(Config, DefaultsAreThePapersSettings) {
  const Config c = geo::parse_config("");
  EXPECT_EQ(c.model.encoder_depth, 50);
  EXPECT_TRUE(c.model.use_fr);
  EXPECT_EQ(c.model.fr_ratio, 16);
  EXPECT_EQ(c.data.height, 128);
  EXPECT_EQ(c.data.width, 416);
  EXPECT_DOUBLE_EQ(c.loss.ssim_alpha, 0.85);
  EXPECT_DOUBLE_EQ(c.loss.occ_alpha1, 0.01);
  EXPECT_DOUBLE_EQ(c.loss.occ_alpha2, 0.5);
  EXPECT_DOUBLE_EQ(c.loss.consistency_a, 3.0);
  EXPECT_DOUBLE_EQ(c.loss.consistency_b, 0.05);
  ASSERT_EQ(c.stages.size(), 1u);
  EXPECT_EQ(c.stages[0].iterations, 350000);
  EXPECT_DOUBLE_EQ(c.stages[0].learning_rate, 2e-4);
  EXPECT_EQ(c.stages[0].batch_size, 4);
  EXPECT_DOUBLE_EQ(c.stages[0].weights.disp_smooth, 0.5);
  EXPECT_DOUBLE_EQ(c.stages[0].weights.flow_smooth, 0.2);
  EXPECT_DOUBLE_EQ(c.optimizer.beta1, 0.9);
  EXPECT_DOUBLE_EQ(c.optimizer.beta2, 0.999);
  // GeoNet's where the paper is silent: [-1,1] loss images, zero-padding sampler, slim BatchNorm.
  EXPECT_EQ(c.loss.image_range, (std::vector<double>{-1.0, 1.0}));
  EXPECT_EQ(c.loss.sampler, geo::Sampler::kZeros);
  EXPECT_EQ(c.loss.flow_mask, geo::FlowMask::kOcclusion);  // the paper's eq. 13
  EXPECT_DOUBLE_EQ(c.model.bn_eps, 1e-3);
  EXPECT_DOUBLE_EQ(c.model.bn_momentum, 1e-3);
  EXPECT_FALSE(c.model.bn_scale);
}

TEST(Config, GeoNetSwitchesParseRoundTripAndAreValidated) {
  const Config c = geo::parse_config(
      "loss: {image_range: [0, 1], sampler: border, flow_mask: consistency}\n"
      "model: {bn_eps: 1.0e-5, bn_momentum: 0.1, bn_scale: true}\n");
  EXPECT_EQ(c.loss.image_range, (std::vector<double>{0.0, 1.0}));
  EXPECT_EQ(c.loss.sampler, geo::Sampler::kBorder);
  EXPECT_EQ(c.loss.flow_mask, geo::FlowMask::kConsistency);
  const Config back = geo::parse_config(geo::to_yaml(c));
  EXPECT_EQ(back.loss.image_range, c.loss.image_range);
  EXPECT_EQ(back.loss.sampler, geo::Sampler::kBorder);
  EXPECT_DOUBLE_EQ(back.model.bn_momentum, 0.1);
  EXPECT_TRUE(back.model.bn_scale);
  const std::string msg =
      error_of([] { geo::parse_config("loss: {image_range: [0, 255]}\nmodel: {bn_momentum: 0}\n"); });
  for (const char* want : {"'loss.image_range' = [0, 255] (line 1): must be [-1, 1] (GeoNet) or [0, 1]",
                           "'model.bn_momentum' = 0 (line 2)"})
    EXPECT_NE(msg.find(want), std::string::npos) << want << "\n" << msg;
  // Enumerations are checked while parsing, naming the valid names.
  EXPECT_EQ(error_of([] { geo::parse_config("loss: {sampler: reflect}\n", "x.yaml"); }),
            "x.yaml line 1: key 'loss.sampler' must be one of zeros, border, got 'reflect'");
  EXPECT_EQ(error_of([] { geo::parse_config("stages: [{train: [depth, flwo]}]\n", "x.yaml"); }),
            "x.yaml line 1: key 'stages[0].train[1]' must be one of depth, pose, flow, got 'flwo'");
}

TEST(Config, ValidConfigRoundTrips) {
  const std::string text = R"(
model: {encoder_depth: 18, use_fr: false, fr_ratio: 8}
data: {root: /data/kitti, height: 64, width: 208, augment: {scale_max: 1.3}}
loss: {ssim_alpha: 0.8, automask: true}
stages:
  - {name: a, iterations: 10, train: [depth, pose], learning_rate: 1.0e-3, batch_size: 2}
  - name: b
    iterations: 20
    train: [flow]
    learning_rate: 3.3e-5
    weights: {flow: 1, flow_smooth: 0.2, flow_consistency: 0.1}
run: {seed: 7, device: cpu}
)";
  const Config a = geo::parse_config(text);
  EXPECT_EQ(a.model.encoder_depth, 18);
  EXPECT_FALSE(a.model.use_fr);
  EXPECT_EQ(a.data.root, "/data/kitti");
  EXPECT_DOUBLE_EQ(a.data.augment.scale_max, 1.3);
  ASSERT_EQ(a.stages.size(), 2u);
  EXPECT_EQ(a.stages[1].train.names(), std::vector<std::string>{"flow"});
  EXPECT_DOUBLE_EQ(a.stages[1].learning_rate, 3.3e-5);
  EXPECT_TRUE(a.stages[1].uses_flow());
  EXPECT_FALSE(a.stages[0].uses_flow());
  const std::string emitted = geo::to_yaml(a);
  const Config b = geo::parse_config(emitted);
  EXPECT_EQ(geo::to_yaml(b), emitted);
  EXPECT_DOUBLE_EQ(b.stages[1].learning_rate, 3.3e-5);
  EXPECT_DOUBLE_EQ(b.loss.ssim_alpha, 0.8);
  EXPECT_TRUE(b.loss.automask);
  EXPECT_EQ(b.run.seed, 7);
}

TEST(Config, UnknownKeyNamesFullPathAndLine) {
  const std::string msg =
      error_of([] { geo::parse_config("model:\n  encoder_depth: 50\n  use_frr: true\n", "x.yaml"); });
  EXPECT_NE(msg.find("unknown key 'model.use_frr'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("x.yaml line 3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("use_fr"), std::string::npos) << msg;  // lists the valid keys
}

TEST(Config, UnknownKeyInsideAStage) {
  const std::string msg = error_of([] { geo::parse_config("stages:\n  - name: s\n    iters: 5\n", "x.yaml"); });
  EXPECT_NE(msg.find("unknown key 'stages[0].iters'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line 3"), std::string::npos) << msg;
}

TEST(Config, WrongTypeNamesKeyValueAndLine) {
  const std::string msg = error_of([] { geo::parse_config("data:\n  height: tall\n", "x.yaml"); });
  EXPECT_NE(msg.find("'data.height'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("an integer"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'tall'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("x.yaml line 2"), std::string::npos) << msg;
}

TEST(Config, NegativeLearningRateNamesKeyValueAndLine) {
  const std::string msg =
      error_of([] { geo::parse_config("stages:\n  - name: s\n    learning_rate: -0.001\n", "x.yaml"); });
  EXPECT_NE(msg.find("'stages[0].learning_rate' = -0.001 (line 3): must be in (0, 1]"), std::string::npos) << msg;
}

// stages[].hold_masked is a share of pixels, measured by the auto-mask: outside [0, 1] or without
// loss.automask it is refused by key and line. A held stage trains what it trains besides depth,
// without the anchor.
TEST(Config, HoldMaskedIsAShareOfTheAutoMaskAndHoldsOnlyDepth) {
  const std::string range = error_of(
      [] { geo::parse_config("loss: {automask: true}\nstages:\n  - name: s\n    hold_masked: 1.5\n", "x.yaml"); });
  EXPECT_NE(range.find("'stages[0].hold_masked' = 1.5 (line 4): must be in [0, 1]"), std::string::npos) << range;
  const std::string unmasked =
      error_of([] { geo::parse_config("stages:\n  - name: s\n    hold_masked: 0.5\n", "x.yaml"); });
  EXPECT_NE(unmasked.find("'stages[0].hold_masked' = 0.5 (line 3): needs loss.automask: true"), std::string::npos)
      << unmasked;
  const Config video =
      geo::load_config(geo::resolve_config_path("video.yaml"), {"data.videos=[a.mp4]", "data.camera.fov_deg=90"});
  EXPECT_DOUBLE_EQ(video.stages[0].hold_masked, 0.65);
  EXPECT_DOUBLE_EQ(Config{}.stages[0].hold_masked, 0.0);  // the paper's recipe never holds

  geo::StageConfig s;
  s.train = {true, true, false};
  s.weights.anchor = 2;
  const geo::StageConfig held = s.held_depth();
  EXPECT_EQ(held.train, (geo::NetworkSet{false, true, false}));
  EXPECT_FALSE(held.freeze_batch_norm);
  EXPECT_EQ(held.weights.anchor, 0);
  EXPECT_EQ(held.learning_rate, s.learning_rate);
  EXPECT_EQ(held.name, s.name);
  s.train = {true, false, false};  // nothing else to train: the stage as it is
  EXPECT_EQ(s.held_depth().train, s.train);
  EXPECT_EQ(s.held_depth().weights.anchor, 2);
}

// A value left empty is an error, not the default; integers are decimal (YAML's 010 is octal 8).
TEST(Config, EmptyValuesAndNonDecimalIntegersAreRefused) {
  for (const auto& [text, why] : std::vector<std::pair<std::string, std::string>>{
           {"stages: [{name: s, iterations: ~}]", "key 'stages[0].iterations' has no value"},
           {"stages:\n  - name: s\n    iterations:\n", "key 'stages[0].iterations' has no value"},
           {"model: {use_fr: null}", "key 'model.use_fr' has no value"},
           {"stages: [{name: s, iterations: 010}]", "written in decimal without leading zeros, got '010'"},
           {"stages: [{name: s, iterations: 0x10}]", "got '0x10'"},
           {"data: {height: 1e3}", "got '1e3'"}}) {
    const std::string msg = error_of([&, &text = text] { geo::parse_config(text + "\n", "x.yaml"); });
    EXPECT_NE(msg.find(why), std::string::npos) << msg;
  }
  EXPECT_EQ(geo::parse_config("stages: [{name: s, iterations: 10}]\n").stages[0].iterations, 10);
  EXPECT_EQ(geo::parse_config("stages: [{name: s, iterations: +5}]\n").stages[0].iterations, 5);
  EXPECT_EQ(geo::parse_config("model:\nrun: {seed: -0}\n").model.use_fr,
            geo::Config().model.use_fr);  // an empty section
}

// Sizes are bounded where they are read, naming the key: never a 22 GB allocation, a LibTorch
// backtrace or a float overflow later.
TEST(Config, SizesAreBoundedWhereRead) {
  for (const auto& [text, key, why] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"data: {height: 1048576}", "'data.height' = 1048576 (line 1)", "in 16..4096"},
           {"data: {width: 8192}", "'data.width' = 8192 (line 1)", "in 16..4096"},
           {"data: {augment: {scale_max: 1e300}}", "'data.augment.scale_max'", "must be in [1, 2]"},
           {"stages: [{name: s, learning_rate: 1e300}]", "'stages[0].learning_rate'", "must be in (0, 1]"}}) {
    const std::string msg = error_of([&, &text = text] { geo::parse_config(text + "\n", "x.yaml"); });
    EXPECT_NE(msg.find(key), std::string::npos) << msg;
    EXPECT_NE(msg.find(why), std::string::npos) << msg;
  }
}

TEST(Config, StageNamesArePlainAndThreadsBounded) {
  for (const char* bad : {"../../evil", "a/b", "..", "''"}) {
    const std::string msg = error_of([&] { geo::parse_config("", "x.yaml", {std::string("stages[0].name=") + bad}); });
    EXPECT_NE(msg.find("'stages[0].name'"), std::string::npos) << bad << ": " << msg;
  }
  EXPECT_NO_THROW(geo::parse_config("stages: [{name: stage-2.b_1}]\n"));
  EXPECT_NE(error_of([] { geo::parse_config("stages: [{name: s-00000001}]\n"); }).find("eight digits"),
            std::string::npos);
  EXPECT_NE(error_of([] { geo::parse_config("run: {threads: 100000}\n"); }).find("'run.threads' = 100000"),
            std::string::npos);
}

// Every count is bounded where it is read: int64's limit (or anything near it) is an error naming the
// key, not an overflow in the sums and products of counts later.
TEST(Config, CountsAreBoundedWhereTheyAreRead) {
  for (const char* key : {"stages.0.iterations", "stages.0.lr_step", "logging.interval", "logging.summary_interval",
                          "logging.checkpoint_interval", "logging.val_interval", "run.distributed.verify_interval"}) {
    const std::string set = std::string(key) + "=9223372036854775807";
    const std::string msg = error_of([&] { geo::parse_config("", "x.yaml", {set}); });
    EXPECT_NE(msg.find("9223372036854775807"), std::string::npos) << key << ": " << msg;
    EXPECT_NE(msg.find("1000000000000"), std::string::npos) << key << ": " << msg;
    EXPECT_NO_THROW(geo::parse_config("", "x.yaml", {std::string(key) + "=1000000000000"})) << key;
  }
  for (const char* set : {"stages.0.batch_size=65537", "logging.keep_last=1000001", "model.fr_ratio=4097"})
    EXPECT_NE(error_of([&] { geo::parse_config("", "x.yaml", {set}); }).find("must be in 1.."), std::string::npos)
        << set;
}

TEST(Config, ReportsEveryInvalidValue) {
  const std::string msg =
      error_of([] { geo::parse_config("model: {encoder_depth: 101}\nrun: {device: tpu}\n", "x.yaml"); });
  EXPECT_NE(msg.find("'model.encoder_depth' = 101 (line 1)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'run.device' = 'tpu' (line 2)"), std::string::npos) << msg;
}

TEST(Config, MissingFileNamesPath) {
  const std::string msg = error_of([] { geo::load_config("/nonexistent/dir/cfg.yaml"); });
  EXPECT_NE(msg.find("/nonexistent/dir/cfg.yaml"), std::string::npos) << msg;
}

TEST(Config, MalformedYamlNamesLine) {
  const std::string msg = error_of([] { geo::parse_config("model:\n  a: [1, 2\n", "bad.yaml"); });
  EXPECT_NE(msg.find("bad.yaml line"), std::string::npos) << msg;
  EXPECT_NE(msg.find("malformed YAML"), std::string::npos) << msg;
}

// A config that is not a map, with or without --set, names the file; an empty config file is refused
// (it would silently start the paper's 350k-iteration run with every default).
TEST(Config, NonMapAndEmptyConfigsNameTheFile) {
  for (const char* text : {"just a string\n", "- a\n- b\n", "42\n"}) {
    for (const std::vector<std::string>& sets : {std::vector<std::string>{}, {"loss.ssim_alpha=0.5"}}) {
      const std::string msg = error_of([&] { geo::parse_config(text, "odd.yaml", sets); });
      EXPECT_NE(msg.find("odd.yaml line 1: a config is a map of sections"), std::string::npos) << text << msg;
    }
  }
  const auto dir = geo::test::fresh_dir("config_empty");
  for (const char* text : {"", "# only a comment\n", "---\n"}) {
    geo::test::write_text(dir + "/empty.yaml", text);
    const std::string msg = error_of([&] { geo::load_config(dir + "/empty.yaml"); });
    EXPECT_NE(msg.find(dir + "/empty.yaml: the config is empty"), std::string::npos) << msg;
  }
  geo::test::write_text(dir + "/one.yaml", "run: {seed: 3}\n");
  EXPECT_EQ(geo::load_config(dir + "/one.yaml").run.seed, 3);
}

TEST(Config, OverridesApplyAndAreValidated) {
  const Config c = geo::parse_config(
      "", "<s>", {"loss.ssim_alpha=0.8", "stages[0].learning_rate=1e-3", "data.root=/tmp/k", "stages.0.train=[depth]"});
  EXPECT_DOUBLE_EQ(c.loss.ssim_alpha, 0.8);
  EXPECT_DOUBLE_EQ(c.stages[0].learning_rate, 1e-3);
  EXPECT_EQ(c.data.root, "/tmp/k");
  EXPECT_EQ(c.stages[0].train.names(), std::vector<std::string>{"depth"});

  std::string msg = error_of([] { geo::parse_config("", "<s>", {"loss.ssim_alpha=2"}); });
  EXPECT_NE(msg.find("'loss.ssim_alpha' = 2 (from --set)"), std::string::npos) << msg;
  msg = error_of([] { geo::parse_config("", "<s>", {"loss.ssim_weight=0.8"}); });
  EXPECT_NE(msg.find("unknown key 'loss.ssim_weight'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("--set"), std::string::npos) << msg;
  msg = error_of([] { geo::parse_config("", "<s>", {"stages[3].iterations=5"}); });
  EXPECT_NE(msg.find("stages[3]"), std::string::npos) << msg;
  msg = error_of([] { geo::parse_config("", "<s>", {"no_equals_sign"}); });
  EXPECT_NE(msg.find("expected key.path=value"), std::string::npos) << msg;
  // Malformed keys and empty values are errors naming the key (not a default, not "stoul").
  const std::pair<const char*, const char*> bad[] = {{"stages[-1].iterations=3", "'[-1]' is not a list index"},
                                                     {"stages[abc].iterations=3", "'[abc]' is not a list index"},
                                                     {"stages[0.iterations=3", "unclosed '['"},
                                                     {"stages[99999999999999].iterations=3", "is not a list index"},
                                                     {"loss.ssim_alpha=", "empty value"},
                                                     {"loss..ssim_alpha=1", "is not a key name"}};
  for (const auto& [set, want] : bad) {
    msg = error_of([&, &set = set] { geo::parse_config("", "<s>", {set}); });
    EXPECT_NE(msg.find(want), std::string::npos) << set << ": " << msg;
  }
  EXPECT_EQ(geo::parse_config("", "<s>", {"data.root=''"}).data.root, "");
  // A key given twice in a file is an error, not "the first one wins".
  msg = error_of([] { geo::parse_config("loss: {ssim_alpha: 0.5}\nloss: {ssim_alpha: 0.9}\n", "d.yaml"); });
  EXPECT_NE(msg.find("key 'loss' is given twice (lines 1 and 2)"), std::string::npos) << msg;
}

TEST(Config, ShippedConfigsParseWithThePapersSchedule) {
  const Config s1 = geo::load_config(geo::resolve_config_path("stage1.yaml"));
  ASSERT_EQ(s1.stages.size(), 1u);
  EXPECT_EQ(s1.stages[0].iterations, 350000);
  EXPECT_FALSE(s1.stages[0].uses_flow());
  const Config s2 = geo::load_config(geo::resolve_config_path("stage2"));
  ASSERT_EQ(s2.stages.size(), 1u);
  EXPECT_EQ(s2.stages[0].iterations, 1500000);
  EXPECT_TRUE(s2.stages[0].uses_flow());
  EXPECT_DOUBLE_EQ(s2.stages[0].weights.flow_consistency, 0.2);
  const Config smoke = geo::load_config(geo::resolve_config_path("smoke.yaml"));
  EXPECT_EQ(smoke.stages.size(), 2u);
  // The per-task data of GeoNet: pose on odometry 00-08 with 5 frames, flow alone on raw minus
  // the KITTI 2015 scenes with GeoNet's L_fr mask.
  const Config pose = geo::load_config(geo::resolve_config_path("pose_odometry.yaml"));
  EXPECT_EQ(pose.data.split, "odometry");
  EXPECT_EQ(pose.data.seq_length, 5);
  EXPECT_EQ(pose.data.sequences, (std::vector<std::string>{"00", "01", "02", "03", "04", "05", "06", "07", "08"}));
  const Config flow = geo::load_config(geo::resolve_config_path("flow_geonet"));
  EXPECT_EQ(flow.data.split, "kitti_raw_stereo");
  EXPECT_EQ(flow.data.val_split, "geonet");  // the list's validation frames lie in the drives it trains on
  EXPECT_EQ(geo::load_config(geo::resolve_config_path("rigid_geonet")).data.val_split, "geonet");
  EXPECT_EQ(flow.stages[0].train.names(), std::vector<std::string>{"flow"});
  EXPECT_EQ(flow.loss.flow_mask, geo::FlowMask::kConsistency);
}

TEST(Config, VideoConfigNeedsClipsAndTakesOneCamera) {
  const auto path = geo::resolve_config_path("video.yaml");
  std::string msg;
  try {
    geo::load_config(path);
  } catch (const ConfigError& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("key 'data.videos' = [] (line"), std::string::npos) << msg;
  EXPECT_NE(msg.find("must name at least one video file or frame folder"), std::string::npos) << msg;
  const Config v = geo::load_config(path, {"data.videos=[drive.mp4, frames/]", "data.camera.fov_deg=90"});
  EXPECT_EQ(v.data.format, geo::DataFormat::kVideo);
  EXPECT_EQ(v.data.videos, (std::vector<std::string>{"drive.mp4", "frames/"}));
  EXPECT_DOUBLE_EQ(v.data.camera.fov_deg, 90);
  EXPECT_TRUE(v.loss.min_reprojection);
  EXPECT_TRUE(v.loss.automask);
  // Round trip of the new sections.
  EXPECT_EQ(geo::to_yaml(geo::parse_config(geo::to_yaml(v))), geo::to_yaml(v));
  // Two cameras, an absurd one, bad video settings: each names its key and value.
  msg.clear();
  try {
    geo::load_config(path, {"data.videos=[a.mp4]", "data.camera.fov_deg=90", "data.camera.intrinsics=[0,700,640,360]",
                            "data.video.static_threshold=1.5", "data.video.crop_y=-1"});
  } catch (const ConfigError& e) {
    msg = e.what();
  }
  for (const char* want : {"key 'data.camera.intrinsics' = [0, 700, 640, 360] (from --set): give one of",
                           "key 'data.camera.intrinsics' = [0, 700, 640, 360] (from --set): focal lengths fx = 0, fy = "
                           "700 are not plausible",
                           "key 'data.video.static_threshold' = 1.5 (from --set): must be in [0, 1)",
                           "key 'data.video.crop_y' = -1 (from --set): must be in [0, 1]"})
    EXPECT_NE(msg.find(want), std::string::npos) << want << "\n" << msg;
}

TEST(Config, ClipSettingsForOtherDataAreRefusedByKey) {
  // data.videos with another format, data.camera and data.video with KITTI data or the in-memory
  // world: they would go unused, so each is refused by its key.
  auto error_of = [](const std::vector<std::string>& sets) {
    try {
      geo::load_config(geo::resolve_config_path("stage1.yaml"), sets);
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const auto kitti = error_of({"data.format=kitti_raw", "data.videos=[a.mp4]"});
  EXPECT_NE(kitti.find("key 'data.videos' = [a.mp4] (from --set): data.format is 'kitti_raw', which trains on "
                       "data.root, not on clips"),
            std::string::npos)
      << kitti;
  const auto camera = error_of({"data.camera.fov_deg=90"});
  EXPECT_NE(camera.find("key 'data.camera.fov_deg' = 90 (from --set): applies to data.videos only (data.format 'auto' "
                        "without clips reads data.root"),
            std::string::npos)
      << camera;
  const auto video = error_of({"data.format=synthetic", "data.video.fps=5", "data.video.crop=false"});
  for (const char* want : {"key 'data.video.fps' = 5 (from --set): applies to data.videos only (data.format "
                           "'synthetic' reads the in-memory world",
                           "key 'data.video.crop' = false (from --set): applies to data.videos only"})
    EXPECT_NE(video.find(want), std::string::npos) << want << "\n" << video;
  // With clips they are used; a resolved config (every key, defaults included) loads as before.
  EXPECT_EQ(error_of({"data.videos=[a.mp4]", "data.camera.fov_deg=90", "data.video.fps=5"}), "");
  const auto resolved = geo::to_yaml(geo::load_config(geo::resolve_config_path("stage1.yaml"), {}));
  EXPECT_NO_THROW(geo::parse_config(resolved));
}

TEST(Config, ResolveNamesEveryPlaceTried) {
  std::string msg;
  try {
    geo::resolve_config_path("nope.yaml");
  } catch (const ConfigError& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("config 'nope.yaml' not found"), std::string::npos) << msg;
  EXPECT_NE(msg.find("configs/nope.yaml"), std::string::npos) << msg;
  EXPECT_EQ(error_of([] { geo::resolve_config_path(geo::shipped_config_dir()); }),
            "config '" + geo::shipped_config_dir() + "' is a folder, not a file (a YAML file is needed)");
  // Devices and FIFOs are named as such (a FIFO would block the reader, /dev/zero never end).
  EXPECT_EQ(error_of([] { geo::resolve_config_path("/dev/zero"); }),
            "config '/dev/zero' is a device, not a file (a YAML file is needed)");
  const std::string fifo = geo::test::fresh_dir("config_fifo") + "/c.yaml";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(error_of([&] { geo::resolve_config_path(fifo); }),
            "config '" + fifo + "' is a FIFO (named pipe), not a file (a YAML file is needed)");
}

// A mistyped path is an error, never the shipped config of the same file name; bare names (with or
// without .yaml) are the shipped ones.
TEST(Config, OnlyBareNamesMeanShippedConfigs) {
  const auto msg = error_of([] { geo::resolve_config_path("no_such_folder/stage1.yaml"); });
  EXPECT_NE(msg.find("config 'no_such_folder/stage1.yaml' not found (a path with a folder is used as given"),
            std::string::npos)
      << msg;
  EXPECT_EQ(geo::resolve_config_path("stage1"), geo::shipped_config_dir() + "/stage1.yaml");
  EXPECT_EQ(geo::resolve_config_path("stage1.yaml"), geo::shipped_config_dir() + "/stage1.yaml");
  const auto dir = geo::test::fresh_dir("config_here");
  geo::test::write_text(dir + "/stage1.yaml", "stages: [{name: mine, iterations: 3}]\n");
  EXPECT_EQ(geo::resolve_config_path(dir + "/stage1.yaml"), dir + "/stage1.yaml");  // a file that exists: as given
}

}  // namespace

namespace geo {
namespace {

// The keys two resolved configs differ in, by dotted path (stages by index), with the ignored ones
// (a whole section by its prefix) left out.
TEST(Config, DifferencesAreNamedByKey) {
  Config a = parse_config("stages: [{name: s1}, {name: s2, batch_size: 4}]\n");
  Config b = a;
  EXPECT_TRUE(config_differences(to_yaml(a), to_yaml(b)).empty());
  b.stages[1].batch_size = 8;
  b.model.use_fr = !a.model.use_fr;
  b.run.threads = 3;
  b.run.distributed.timeout_s = 5;
  b.data.augment.scale_max = 1.3;
  EXPECT_EQ(config_differences(to_yaml(a), to_yaml(b), {"run", "data.augment"}),
            (std::vector<std::string>{"model.use_fr: true vs false", "stages[1].batch_size: 4 vs 8"}));
  EXPECT_EQ(
      config_differences(to_yaml(a), to_yaml(b), {"run.threads", "run.distributed", "data", "model", "stages[1]"}),
      std::vector<std::string>{});
  b.stages.pop_back();
  EXPECT_EQ(config_differences(to_yaml(a), to_yaml(b), {"run", "data", "model"}).front().rfind("stages[1].", 0), 0u);
}

}  // namespace
}  // namespace geo
