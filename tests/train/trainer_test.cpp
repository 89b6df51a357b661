// Whole-loop behaviour on a tiny synthetic world: a run SIGKILLed (in a child process) and resumed
// logs exactly the losses of an uninterrupted run; bad configs stop before training naming the key;
// NaN steps never reach a checkpoint; each stage keeps its own best checkpoint, chosen by what the
// stage trains, and a run folder resolves to the best of its last stage; the TensorBoard file
// holds the losses of metrics.csv.
#include "core/files.h"
#include "data/packed/packed.h"
#include "data/kitti/splits.h"
#include "data/synth/synth_writer.h"
#include "pipeline/checkpoint.h"
#include "train/checkpoints.h"
#include "data/training_data.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include "log_capture.h"

#include <csignal>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "synth_world.h"
#include "tensorboard_reader.h"
#include "train/training_helpers.h"

namespace geo {
namespace {

// One tiny world for the whole suite.
const std::string& world() {
  static const std::string root = test::write_small_world("trainer_world", 10, 0, 5) + "/raw";
  return root;
}

Config tiny_config(const std::string& extra = "") {
  return parse_config(R"(
model: {encoder_depth: 18}
data: {height: 64, width: 208, num_workers: 1, augment: {enabled: true}}
stages:
  - {name: s1, iterations: 3, train: [depth, pose], batch_size: 1}
  - {name: s2, iterations: 3, train: [depth, pose, flow], batch_size: 1}
logging: {interval: 1, summary_interval: 0, checkpoint_interval: 2, val_interval: 0, keep_last: 5}
run: {threads: 2, seed: 3}
)" + extra,
                      "tiny.yaml", {"data.root=" + world()});
}

using test::metrics;

TrainState state_of(const std::string& checkpoint) { return CheckpointFile(checkpoint).train_state(); }

// val.csv rows of one stage: iteration -> score.
std::map<int64_t, double> val_scores(const std::string& dir, const std::string& stage) {
  std::ifstream in(dir + "/val.csv");
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "stage_index,stage,iteration,photometric,flow,score");
  std::map<int64_t, double> out;
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    if (f.size() == 6 && f[1] == stage) out[std::stoll(f[2])] = std::stod(f[5]);
  }
  return out;
}

// metrics.csv's column `name`, one entry per row ("" where the step had no such term).
std::vector<std::string> metrics_column(const std::string& csv, const std::string& name) {
  std::istringstream rows(csv);
  std::vector<std::vector<std::string>> table;
  for (std::string row; std::getline(rows, row);) {
    table.emplace_back();
    std::stringstream ss(row + ",");
    for (std::string x; std::getline(ss, x, ',');) table.back().push_back(x);
  }
  const auto& header = table.at(0);
  const size_t col = std::find(header.begin(), header.end(), name) - header.begin();
  EXPECT_LT(col, header.size()) << name;
  std::vector<std::string> out;
  for (size_t i = 1; i < table.size(); ++i) out.push_back(col < table[i].size() ? table[i][col] : "?");
  return out;
}

TEST(Trainer, KilledAndResumedRunLogsTheSameLosses) {
  // s1: 3 steps (checkpoints 2, 3), s2: 2 steps (checkpoint 2), killed during the 6th step.
  // weights.anchor on both: s1 starts from random weights (nothing to hold, no term), s2 holds
  // depth to s1's result, kept as anchor-s2.pt, which the resumed run reads.
  auto cfg = tiny_config();
  for (auto& s : cfg.stages) s.weights.anchor = 1;
  const auto r = test::killed_and_resumed(cfg, test::fresh_dir("resume"), 6);
  EXPECT_EQ(r.latest_when_killed, "s2-00000002.pt\n");
  const auto& whole = r.whole;
  EXPECT_EQ(std::count(whole.begin(), whole.end(), '\n'), 7);  // header + 6 iterations
  EXPECT_EQ(whole, r.resumed);
  const auto anchor = metrics_column(whole, "anchor");
  ASSERT_EQ(anchor.size(), 6u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(anchor[i], "") << i;
  for (int i = 3; i < 6; ++i) EXPECT_GT(std::stod(anchor[i]), 0.0) << i;
  for (const auto& dir : {r.whole_dir, r.killed_dir}) {
    EXPECT_FALSE(std::filesystem::exists(dir + "/anchor-s1.pt"));
    EXPECT_TRUE(std::filesystem::exists(dir + "/anchor-s2.pt"));
  }

  // The TensorBoard file of the uninterrupted run: a loss value per iteration, steps 1..6 over both
  // stages, equal to metrics.csv's (as float32).
  const auto events = test::read_tensorboard_dir(r.whole_dir + "/tb");
  std::map<int64_t, float> rigid;
  for (const auto& e : events)
    for (const auto& v : e.values)
      if (v.tag == "loss/rigid") rigid[e.step] = v.simple_value;
  ASSERT_EQ(rigid.size(), 6u);
  std::istringstream rows(whole);
  std::string row;
  std::getline(rows, row);  // header: stage_index,stage,iteration,total,rigid,...
  for (int64_t step = 1; std::getline(rows, row); ++step) {
    std::vector<std::string> f;
    std::stringstream ss(row);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    ASSERT_TRUE(rigid.count(step)) << step;
    EXPECT_EQ(rigid[step], static_cast<float>(std::stod(f[4]))) << "step " << step;
  }
}

TEST(Trainer, FlowOnlyStageKeepsItsOwnBestChosenByTheFlowLoss) {
  // GeoNet's schedule: depth and pose first, then the FlowNet alone (depth and pose frozen, so the
  // rigid validation loss is constant there and cannot select a FlowNet).
  auto cfg = tiny_config();
  cfg.logging.checkpoint_interval = 1;
  cfg.logging.val_interval = 1;
  cfg.logging.keep_last = 2;
  cfg.stages[0].iterations = 2;
  cfg.stages[1].iterations = 4;
  cfg.stages[1].train = NetworkSet{false, false, true};
  cfg.stages[1].learning_rate = 1e-3;
  TrainOptions o;
  o.run_dir = test::fresh_dir("flowbest") + "/run";
  ASSERT_EQ(train(cfg, o), 0);
  const auto s1 = val_scores(o.run_dir, "s1"), s2 = val_scores(o.run_dir, "s2");
  ASSERT_EQ(s1.size(), 2u);
  ASSERT_EQ(s2.size(), 4u);
  auto argmin = [](const std::map<int64_t, double>& m) {
    return std::min_element(m.begin(), m.end(), [](auto& a, auto& b) { return a.second < b.second; })->first;
  };
  // Each stage's best file is that stage's checkpoint with the lowest score (ties: the first).
  const std::string ck = o.run_dir + "/checkpoints";
  const auto b1 = state_of(ck + "/best-s1.pt"), b2 = state_of(ck + "/best-s2.pt");
  EXPECT_EQ(b1.stage, 0);
  EXPECT_EQ(b1.iteration, argmin(s1));
  EXPECT_EQ(b2.stage, 1);
  EXPECT_EQ(b2.iteration, argmin(s2));
  EXPECT_NEAR(b2.best_score, s2.at(argmin(s2)), 1e-7);  // val.csv holds 9 digits
  // The flow stage's scores are L_fr: they change while the FlowNet trains.
  EXPECT_NE(s2.begin()->second, s2.rbegin()->second);
  // keep_last 2 rotated the others away, the best files stay; the run resolves to the last stage's.
  EXPECT_EQ(resolve_checkpoint(o.run_dir), ck + "/best-s2.pt");
  EXPECT_FALSE(std::filesystem::exists(ck + "/s1-00000001.pt"));
}

TEST(Trainer, BestHoldsTheValidatedWeightsWhenTheIntervalsDiffer) {
  // Validation every 3 iterations, checkpoints every 4: a new best is checkpointed when it is
  // validated, so best-<stage>.pt is the checkpoint of the iteration with the lowest val.csv score
  // (not the next regular checkpoint, whose weights were never validated).
  auto cfg = tiny_config();
  cfg.stages.resize(1);
  cfg.stages[0].iterations = 9;
  cfg.stages[0].learning_rate = 1e-3;
  cfg.logging.val_interval = 3;
  cfg.logging.checkpoint_interval = 4;
  cfg.logging.keep_last = 10;
  TrainOptions o;
  o.run_dir = test::fresh_dir("bestintervals") + "/run";
  ASSERT_EQ(train(cfg, o), 0);
  const auto scores = val_scores(o.run_dir, "s1");
  ASSERT_EQ(scores.size(), 3u);  // iterations 3, 6, 9
  const auto best =
      std::min_element(scores.begin(), scores.end(), [](auto& a, auto& b) { return a.second < b.second; });
  const auto b = state_of(o.run_dir + "/checkpoints/best-s1.pt");
  EXPECT_EQ(b.iteration, best->first);
  EXPECT_NEAR(b.best_score, best->second, 1e-7);
  // The regular checkpoints are still written (4, 8) beside the validated ones (3 and any later best).
  EXPECT_TRUE(std::filesystem::exists(o.run_dir + "/checkpoints/s1-00000004.pt"));
  EXPECT_TRUE(std::filesystem::exists(o.run_dir + "/checkpoints/s1-00000003.pt"));
}

TEST(Trainer, TwoStageRunResolvesToTheLastStagesBest) {
  auto cfg = tiny_config();
  cfg.logging.checkpoint_interval = 1;
  cfg.logging.val_interval = 1;
  cfg.logging.summary_interval = 2;  // summaries (PNG files and TensorBoard images) too
  cfg.stages[0].iterations = 2;
  cfg.stages[1].iterations = 2;
  TrainOptions o;
  o.run_dir = test::fresh_dir("twostage") + "/run";
  ASSERT_EQ(train(cfg, o), 0);
  const std::string best = resolve_checkpoint(o.run_dir);
  EXPECT_EQ(best, o.run_dir + "/checkpoints/best-s2.pt");
  EXPECT_EQ(state_of(best).stage, 1);  // never a stage-1 checkpoint without a trained FlowNet
  torch::serialize::InputArchive a, flow;
  a.load_from(best);
  EXPECT_TRUE(a.try_read("flow", flow));
  // The summary images reached TensorBoard as PNGs, tagged by stage, at the global step.
  std::map<std::string, int64_t> images;
  for (const auto& e : test::read_tensorboard_dir(o.run_dir + "/tb"))
    for (const auto& v : e.values)
      if (v.has_image) {
        images[v.tag] = e.step;
        EXPECT_EQ(v.png.substr(1, 3), "PNG") << v.tag;
        EXPECT_EQ(v.height, 64);
        EXPECT_EQ(v.width, 208);
      }
  EXPECT_EQ(images["s1/disp"], 2);
  EXPECT_EQ(images["s2/flow"], 4);
  EXPECT_EQ(images.size(), 3u + 5u);  // stage 1: target, disp, warped; stage 2 adds flow, visible
  EXPECT_TRUE(std::filesystem::exists(o.run_dir + "/summaries/s2-2-visible.png"));
}

// A folder holding a run killed before its first checkpoint: a fresh start is refused (it would
// append its rows to the earlier run's metrics.csv), and the earlier files stay as they were.
TEST(Trainer, AFreshStartInAFolderWithAPartialRunIsRefused) {
  TrainOptions o;
  o.run_dir = test::fresh_dir("partial") + "/run";
  test::write_text(o.run_dir + "/metrics.csv", "iteration,stage\n1,stage1\n");
  GEO_EXPECT_THROW_WITH(train(tiny_config(), o), "run folder '" + o.run_dir + "'", "metrics.csv",
                        "stopped before its first checkpoint");
  EXPECT_EQ(test::read_file(o.run_dir + "/metrics.csv"), "iteration,stage\n1,stage1\n");
  EXPECT_FALSE(std::filesystem::exists(o.run_dir + "/config.yaml"));
}

TEST(Trainer, BadConfigStopsBeforeTrainingNamingTheKey) {
  auto cfg = tiny_config();
  cfg.data.root = "/nonexistent/kitti";
  TrainOptions o;
  o.run_dir = test::fresh_dir("badroot") + "/run";
  GEO_EXPECT_THROW_WITH(train(cfg, o), "data.root", "/nonexistent/kitti");
  EXPECT_FALSE(std::filesystem::exists(o.run_dir));  // a run that could not start leaves no folder
  GEO_EXPECT_THROW_WITH(tiny_config("optimizer: {beta3: 1}\n"), "optimizer.beta3");
}

TEST(TrainingData, AGeoSynthOutFolderReadsItsRawFolder) {
  DataConfig d = tiny_config().data;
  d.root = std::filesystem::path(world()).parent_path().string();  // holds raw/, kitti2015/, odometry/
  const auto data = open_training_data(d);
  EXPECT_EQ(data.root, world());
  EXPECT_EQ(data.train->size(), 7u);
}

// A damaged or partial packed cache in data.root is an error naming it, never a silent fall-back to
// the raw KITTI lists beside it (here a readable raw world).
TEST(TrainingData, ADamagedPackedCacheIsNamedNotSkipped) {
  DataConfig d = tiny_config().data;
  ASSERT_EQ(open_training_data(d).format, "kitti_raw");
  const std::string cache = world() + "/train";
  test::write_text(cache + "/frames.bin.tmp", "interrupted");
  GEO_EXPECT_THROW_WITH(open_training_data(d), "packed cache " + cache + " is incomplete", "re-run geo_prepare");
  test::write_text(cache + "/index.txt", "garbage\n");
  GEO_EXPECT_THROW_WITH(open_training_data(d), cache + "/index.txt", "not a geo packed cache");
  remove_tree(cache);
  EXPECT_EQ(open_training_data(d).format, "kitti_raw");
}

// A packed cache's val/ must come from the geo_prepare run that wrote train/, at the config's size:
// a val/ left by an earlier run would validate, and choose best-<stage>.pt, on stale frames.
TEST(TrainingData, AStaleValidationCacheIsRefused) {
  DataConfig d = tiny_config().data;
  d.root = test::fresh_dir("stale_val");
  const auto write = [&](const std::string& part, const std::string& pack, int64_t height) {
    PackedWriter w(d.root + "/" + part, height, d.width, d.seq_length, pack);
    Snippet s;
    s.frames = torch::rand({d.seq_length, 3, height, d.width});
    s.K = torch::eye(3);
    s.id = part;
    w.add(s);
    w.finish();
  };
  write("train", "run-2", d.height);
  write("val", "run-1", d.height);
  GEO_EXPECT_THROW_WITH(open_training_data(d), "'" + d.root + "': val/ was written by another geo_prepare run",
                        "pack 'run-1', train/ 'run-2'", "remove " + d.root + "/val");
  write("val", "run-2", d.height * 2);
  GEO_EXPECT_THROW_WITH(open_training_data(d), d.root + "/val' holds", "ask for");
  write("val", "run-2", d.height);
  const auto data = open_training_data(d);
  ASSERT_TRUE(data.val);
  EXPECT_EQ(data.val->id(0), "val");
  // A version-1 cache (no pack line) still reads.
  for (const char* part : {"/train/index.txt", "/val/index.txt"}) {
    std::string index = test::read_file(d.root + part);
    index.replace(0, 12, "geo-packed 1");
    index.erase(index.find("pack run-2\n"), 11);
    test::write_text(d.root + part, index);
  }
  EXPECT_TRUE(open_training_data(d).val);
}

// data.val_split geonet: GeoNet's prepare_train_data holds out each frame with probability 0.1;
// geo by a fixed hash, the same on every machine, the held-out snippets never trained on.
TEST(TrainingData, GeoNetsValidationSplitHoldsOutATenthOfTheTrainingSnippets) {
  int64_t held = 0;
  for (int64_t f = 0; f < 4000; ++f) {
    SplitEntry e;
    e.folder = "2011_09_26/2011_09_26_drive_0001_sync";
    e.frame = f;
    e.side = f % 2 ? 'l' : 'r';
    held += in_geonet_validation(e);
    EXPECT_EQ(in_geonet_validation(e), in_geonet_validation(e));
  }
  EXPECT_GT(held, 340);  // 400 expected; a binomial's 3 sigma is 57
  EXPECT_LT(held, 460);
  DataConfig d = tiny_config().data;
  const auto listed = open_training_data(d);
  d.val_split = "geonet";
  const auto geonet = open_training_data(d);
  std::set<std::string> train_ids, val_ids;
  for (size_t i = 0; i < geonet.train->size(); ++i) train_ids.insert(geonet.train->id(i));
  if (geonet.val)
    for (size_t i = 0; i < geonet.val->size(); ++i) val_ids.insert(geonet.val->id(i));
  EXPECT_EQ(train_ids.size() + val_ids.size(), listed.train->size());
  for (const auto& id : val_ids) EXPECT_EQ(train_ids.count(id), 0u) << id;
  EXPECT_NE(geonet.val_list.find("GeoNet's 10% of"), std::string::npos) << geonet.val_list;
}

TEST(TrainingData, PerTaskSplits) {
  // odometry (GeoNet's pose data): every frame of the sequences with L/2 neighbours each side.
  DataConfig d = tiny_config().data;
  d.root = std::filesystem::path(world()).parent_path().string();  // its odometry/ is found
  d.split = "odometry";
  d.sequences = {"09"};  // the small world has 5 frames of sequence 09
  d.seq_length = 5;
  auto odo = open_training_data(d);
  EXPECT_EQ(odo.format, "kitti_odometry");
  ASSERT_EQ(odo.train->size(), 1u);
  const auto s = odo.train->get(0);
  EXPECT_EQ(s.frames.sizes(), (torch::IntArrayRef{5, 3, 64, 208}));
  EXPECT_EQ(s.id, "odometry 09 2");
  d.seq_length = 3;
  EXPECT_EQ(open_training_data(d).train->size(), 3u);
  d.sequences = {"00"};
  GEO_EXPECT_THROW_WITH(open_training_data(d), "sequence 00 not found", "sequences/00/image_2");

  // raw_minus_kitti2015 (GeoNet's flow data): eigen_zhou without the KITTI 2015 scenes. The
  // shipped list names real KITTI drives, none of this world's; a world's own list is used first.
  DataConfig r = tiny_config().data;
  r.split = "raw_minus_kitti2015";
  const auto shipped = open_training_data(r);
  EXPECT_EQ(shipped.train->size(), 7u);
  EXPECT_TRUE(std::any_of(shipped.exclusions.begin(), shipped.exclusions.end(), [](const std::string& f) {
    return f.find("stereo/test_scenes_stereo.txt") != std::string::npos;
  }));
  // kitti_raw_stereo (GeoNet's flow data): every drive on disk but the KITTI 2015 scenes (the Eigen
  // test drive included), both cameras: each camera's frames but the two ends.
  DataConfig k = tiny_config().data;
  k.split = "kitti_raw_stereo";
  size_t expected = 0;
  std::string drives;
  for (const auto& drive : std::filesystem::directory_iterator(world() + "/2011_01_01")) {
    if (!drive.is_directory()) continue;  // the calibration files
    drives += drive.path().filename().string().substr(0, drive.path().filename().string().size() - 5) + "\n";
    for (const char* camera : {"image_02", "image_03"}) {
      const auto dir = drive.path() / camera / "data";
      if (std::filesystem::is_directory(dir))
        expected += static_cast<size_t>(std::distance(std::filesystem::directory_iterator(dir), {})) - 2;
    }
  }
  EXPECT_EQ(std::count(drives.begin(), drives.end(), '\n'), 2);  // the training and the Eigen test drive
  // Validation from a list whose frames lie in the drives trained on is warned about; GeoNet's 10%
  // held out (val_split geonet, as the shipped kitti_raw_stereo configs set) is not.
  size_t trained_with_list = 0;
  const auto warned = test::captured_log("%l %v", [&] { trained_with_list = open_training_data(k).train->size(); });
  EXPECT_EQ(trained_with_list, expected);
  EXPECT_NE(warned.find("warning data.split kitti_raw_stereo with data.val_split list"), std::string::npos) << warned;
  DataConfig held = k;
  held.val_split = "geonet";
  const auto quiet = test::captured_log("%l %v", [&] { EXPECT_LT(open_training_data(held).train->size(), expected); });
  EXPECT_EQ(quiet.find("val_split list"), std::string::npos) << quiet;
  test::write_text(world() + "/splits/stereo/test_scenes_stereo.txt", "2011_01_01_drive_0001\n");
  GEO_EXPECT_THROW_WITH(open_training_data(r), "all 7 entries", "are excluded", "test_scenes_stereo.txt");
  EXPECT_LT(open_training_data(k).train->size(), expected);
  test::write_text(world() + "/splits/stereo/test_scenes_stereo.txt", drives);
  GEO_EXPECT_THROW_WITH(open_training_data(k), "kitti_raw_stereo: no 3-frame snippet", "test_scenes_stereo.txt");
  remove_tree(world() + "/splits/stereo");
}

TEST(TrainingData, AMissingNeighbourIsNamed) {
  DataConfig d = tiny_config().data;
  d.train_list = test::fresh_dir("neighbour") + "/list.txt";
  test::write_text(d.train_list, "2011_01_01/2011_01_01_drive_0001_sync 9 l\n");  // the drive's last frame
  GEO_EXPECT_THROW_WITH(open_training_data(d), "has all its 3 frames on disk", "image_02/data/0000000010.png");
}

TEST(Trainer, ValidationHonoursOnBadSampleSkip) {
  // Validation on two snippets of the test drive, whose frames training never reads; the second
  // snippet's last frame is corrupt.
  const auto root = test::write_small_world("badval_world", 10, 0, 5) + "/raw";
  const std::string drive = synth_drive_folder(2);
  const std::string list = root + "/val_list.txt", bad = root + "/" + drive + "/image_02/data/0000000007.png";
  test::write_text(list, drive + " 3 l\n" + drive + " 6 l\n");
  test::write_text(bad, "not a png");
  auto cfg = tiny_config();
  cfg.data.root = root;
  cfg.data.val_list = list;
  cfg.stages.resize(1);
  cfg.stages[0].iterations = 2;
  cfg.logging.val_interval = 1;
  TrainOptions o;
  o.run_dir = test::fresh_dir("badval") + "/stop";
  // stop (the default): the run ends naming the corrupt file.
  GEO_EXPECT_THROW_WITH(train(cfg, o), bad, "cannot decode");
  cfg.data.on_bad_sample = BadSample::kSkip;
  o.run_dir = test::fresh_dir("badval") + "/skip";
  ASSERT_EQ(train(cfg, o), 0);
  EXPECT_EQ(val_scores(o.run_dir, "s1").size(), 2u);  // both validations ran, on the readable snippet
}

// Makes the checkpoints folder unwritable after `step` steps. A read-only folder does not stop
// root (CI runs as root), so the folder is replaced by a plain file: the same failed write.
struct BreakCheckpointsAtStep : MetricsSink {
  BreakCheckpointsAtStep(std::string dir, int64_t n) : ck(std::move(dir) + "/checkpoints"), left(n) {}
  void on_step(const StepRecord&) override {
    if (--left != 0) return;
    std::filesystem::rename(ck, ck + ".moved");
    test::write_text(ck, "");
  }
  std::string ck;
  int64_t left;
};

TEST(Trainer, AFailedCheckpointWriteNamesThePathAndResumeContinues) {
  auto cfg = tiny_config();
  cfg.stages.resize(1);
  TrainOptions o;
  o.run_dir = test::fresh_dir("ckfail") + "/run";
  o.sinks.push_back(std::make_shared<BreakCheckpointsAtStep>(o.run_dir, 3));
  GEO_EXPECT_THROW_WITH(train(cfg, o), o.run_dir + "/checkpoints/s1-00000003.pt", "Not a directory");
  const std::string ck = o.run_dir + "/checkpoints";
  std::filesystem::remove(ck);
  std::filesystem::rename(ck + ".moved", ck);
  EXPECT_EQ(state_of(resolve_checkpoint(o.run_dir)).iteration, 2);  // the earlier checkpoint is intact
  ASSERT_EQ(resume(o.run_dir, {}), 0);
  EXPECT_EQ(state_of(resolve_checkpoint(o.run_dir)).iteration, 3);
}

// A run on a frame folder (data.videos) records what the clip gave (clips.txt); resuming after the
// clip changed (frames deleted) is refused before anything is written, naming the clip, also for a
// run that had finished; the unchanged clip resumes.
TEST(Trainer, ResumeRefusesAClipThatChanged) {
  const auto dir = test::fresh_dir("clip_resume");
  const std::string clip = dir + "/clip";
  std::filesystem::create_directories(clip);
  for (const auto& e :
       std::filesystem::directory_iterator(world() + "/2011_01_01/2011_01_01_drive_0001_sync/image_02/data"))
    std::filesystem::copy_file(e.path(), clip + "/" + e.path().filename().string());
  auto cfg = tiny_config();
  cfg.stages.resize(1);
  cfg.stages[0].iterations = 2;
  cfg.data.root.clear();
  cfg.data.format = DataFormat::kVideo;
  cfg.data.videos = {clip};
  cfg.data.camera.intrinsics = {120.8, 123.1, 102.1, 29.5};
  cfg.data.video.static_threshold = 0;
  cfg.data.video.standing_parallax = 0;
  cfg.data.augment.enabled = false;
  TrainOptions o;
  o.run_dir = dir + "/run";
  ASSERT_EQ(train(cfg, o), 0);
  const auto record = test::read_file(o.run_dir + "/clips.txt");
  EXPECT_EQ(record.rfind("clip '" + clip + "': 10 frames, 10 kept, digest ", 0), 0u) << record;
  ASSERT_EQ(resume(o.run_dir, {}), 0);  // unchanged: the finished run says so
  std::filesystem::remove(clip + "/0000000009.png");
  const auto csv = test::read_file(o.run_dir + "/metrics.csv");
  GEO_EXPECT_THROW_WITH(resume(o.run_dir, {}),
                        "a clip changed since the run started: then " + record.substr(0, record.size() - 1),
                        "; now clip '" + clip + "': 9 frames, 9 kept, digest ", "geo_train --init " + o.run_dir);
  EXPECT_EQ(test::read_file(o.run_dir + "/metrics.csv"), csv);
}

// One stage of one iteration with its checkpoint: a run folder to initialise others from.
Config one_step_config() {
  auto cfg = tiny_config();
  cfg.stages.resize(1);
  cfg.stages[0].iterations = 1;
  cfg.logging.checkpoint_interval = 1;
  return cfg;
}

TEST(Trainer, InitFromAnotherArchitectureOrABrokenFileIsOneClearLine) {
  const auto cfg = one_step_config();
  const auto base = test::fresh_dir("initarch");
  TrainOptions o;
  o.run_dir = base + "/r18";
  ASSERT_EQ(train(cfg, o), 0);
  const std::string ck = resolve_checkpoint(o.run_dir);
  TrainOptions i;
  i.init = o.run_dir;
  i.run_dir = base + "/other";
  auto other = cfg;
  other.model.encoder_depth = 34;
  other.model.use_fr = false;
  GEO_EXPECT_THROW_WITH(train(other, i), ck + ": its networks were trained with model.encoder_depth 18 (wanted 34), "
                                              "model.use_fr true (wanted false); set those keys");
  EXPECT_FALSE(std::filesystem::exists(i.run_dir));  // a run that could not start leaves no folder
  // A truncated file given to --init: named, no LibTorch stack trace.
  std::filesystem::copy_file(ck, base + "/cut.pt");
  std::filesystem::resize_file(base + "/cut.pt", 1000);
  i.init = base + "/cut.pt";
  GEO_EXPECT_THROW_WITH(train(cfg, i), base + "/cut.pt: not a readable geo/LibTorch file");
}

// Sends this process SIGTERM (as a cluster scheduler would) after `n` steps: just before validation.
struct TermAtStep : MetricsSink {
  explicit TermAtStep(int64_t n) : left(n) {}
  void on_step(const StepRecord&) override {
    if (--left == 0) std::raise(SIGTERM);
  }
  int64_t left;
};

// Every parameter and buffer (BatchNorm's statistics) of `a` equal to `b`'s.
bool same_state(const torch::nn::Module& a, const torch::nn::Module& b) {
  const auto pa = a.named_parameters(), pb = b.named_parameters();
  const auto ba = a.named_buffers(), bb = b.named_buffers();
  if (pa.size() != pb.size() || ba.size() != bb.size()) return false;
  for (const auto& p : pa)
    if (!torch::equal(p.value(), pb[p.key()])) return false;
  for (const auto& x : ba)
    if (!torch::equal(x.value(), bb[x.key()])) return false;
  return true;
}

// stages[].hold_masked: a stage that starts from trained weights and finds at least that share of
// the pixels auto-masked holds depth (the DepthNet and its statistics leave it exactly as they came,
// the PoseNet trains), says so, and records it in its checkpoints, so that a resumed run stays held;
// below it depth trains; a stage from random weights measures nothing.
TEST(Trainer, AStageFromTrainedWeightsHoldsDepthWhereMostPixelsAreAutoMasked) {
  const auto base = test::fresh_dir("hold");
  auto cfg = one_step_config();
  TrainOptions a;
  a.run_dir = base + "/a";
  ASSERT_EQ(train(cfg, a), 0);
  Networks start = CheckpointFile(resolve_checkpoint(a.run_dir)).networks();
  cfg.loss.automask = true;
  struct Result {
    std::string log;
    Networks nets;
    bool held;
  };
  // `stop_after` > 0: stopped by a SIGTERM after that many steps, then resumed.
  const auto run = [&](double hold_masked, const std::string& name, const std::string& init, int64_t stop_after = 0) {
    cfg.stages[0].hold_masked = hold_masked;
    cfg.stages[0].iterations = stop_after + 1;
    TrainOptions o;
    o.run_dir = base + "/" + name;
    o.init = init;
    Result r;
    if (stop_after > 0) {
      o.sinks.push_back(std::make_shared<TermAtStep>(stop_after));
      EXPECT_EQ(train(cfg, o), 130);
      EXPECT_EQ(resume(o.run_dir, {}), 0);
    } else {
      EXPECT_EQ(train(cfg, o), 0);
    }
    r.log = test::read_file(o.run_dir + "/train.log");
    const std::string ck = resolve_checkpoint(o.run_dir);
    r.nets = CheckpointFile(ck).networks();
    r.held = state_of(ck).depth_held;
    return r;
  };
  // Any auto-masked pixel holds; stopped after the first step and resumed, the stage stays held.
  const Result held = run(1e-9, "held", a.run_dir, 1);
  EXPECT_TRUE(held.held);
  EXPECT_TRUE(same_state(*held.nets.depth, *start.depth));
  EXPECT_FALSE(same_state(*held.nets.pose, *start.pose));
  EXPECT_NE(held.log.find("[warning] stage s1: the weights it starts from leave "), std::string::npos) << held.log;
  EXPECT_NE(held.log.find("pixels of 7 training snippets auto-masked"), std::string::npos) << held.log;
  EXPECT_NE(held.log.find("Depth is held: the DepthNet stays as it starts (its BatchNorm statistics too) and the stage "
                          "trains [pose]. To train depth all the same: --set stages.0.hold_masked=0"),
            std::string::npos)
      << held.log;

  const Result trains = run(1.0, "trains", a.run_dir);  // only a wholly masked clip would hold
  EXPECT_FALSE(trains.held);
  EXPECT_FALSE(same_state(*trains.nets.depth, *start.depth));
  EXPECT_NE(trains.log.find("below stages[0].hold_masked 1: depth trains"), std::string::npos) << trains.log;

  const Result fresh = run(1e-9, "fresh", "");  // random weights: nothing to hold, nothing measured
  EXPECT_FALSE(fresh.held);
  EXPECT_EQ(fresh.log.find("the weights it starts from"), std::string::npos) << fresh.log;
}

// Every checkpoint of a run records what its initial weights were trained on, nearest first, and a
// run initialised from it inherits the chain (geo_eval's training-drive check follows it).
TEST(Trainer, CheckpointsRecordTheirInitChain) {
  const auto cfg = one_step_config();
  const auto base = test::fresh_dir("initchain");
  TrainOptions a;
  a.run_dir = base + "/a";
  ASSERT_EQ(train(cfg, a), 0);
  EXPECT_TRUE(CheckpointFile(resolve_checkpoint(a.run_dir)).init_configs().empty());
  auto second = cfg;
  second.data.split = "eigen_zhou";
  second.run.seed = 7;
  TrainOptions b;
  b.run_dir = base + "/b";
  b.init = a.run_dir;
  ASSERT_EQ(train(second, b), 0);
  const auto chain_b = CheckpointFile(resolve_checkpoint(b.run_dir)).init_configs();
  ASSERT_EQ(chain_b.size(), 1u);
  EXPECT_EQ(parse_config(chain_b[0]).run.seed, cfg.run.seed);  // a's config
  TrainOptions c;
  c.run_dir = base + "/c";
  c.init = b.run_dir;
  ASSERT_EQ(train(cfg, c), 0);
  const auto chain_c = CheckpointFile(resolve_checkpoint(c.run_dir)).init_configs();
  ASSERT_EQ(chain_c.size(), 2u);
  EXPECT_EQ(parse_config(chain_c[0]).run.seed, 7);  // b's, then a's
  EXPECT_EQ(parse_config(chain_c[1]).run.seed, cfg.run.seed);
  ASSERT_EQ(resume(c.run_dir, {}), 0);  // a resumed run keeps it
  EXPECT_EQ(CheckpointFile(resolve_checkpoint(c.run_dir)).init_configs(), chain_c);
}

TEST(Trainer, ASigtermDuringValidationEndsItCheckpointsAndTheResumeValidatesFirst) {
  auto cfg = tiny_config();
  cfg.stages.resize(1);
  cfg.stages[0].iterations = 5;
  cfg.logging.val_interval = 1;
  cfg.logging.checkpoint_interval = 100;
  TrainOptions o;
  o.run_dir = test::fresh_dir("termval") + "/run";
  o.sinks.push_back(std::make_shared<TermAtStep>(2));
  EXPECT_EQ(train(cfg, o), 130);
  // Iteration 1 was validated; iteration 2's validation stopped at its first batch, unrecorded.
  const auto scores = val_scores(o.run_dir, "s1");
  EXPECT_EQ(scores.size(), 1u);
  EXPECT_EQ(scores.count(1), 1u);
  // The signal's checkpoint is the latest; the best is iteration 1's, written when it was validated.
  const std::string ck = o.run_dir + "/checkpoints";
  EXPECT_EQ(state_of(ck + "/" + latest_checkpoint_name(ck)).iteration, 2);
  EXPECT_EQ(state_of(resolve_checkpoint(o.run_dir)).iteration, 1);
  EXPECT_TRUE(state_of(ck + "/" + latest_checkpoint_name(ck)).validation_pending);
  // Resumed, the run validates iteration 2 first: val.csv and the best checkpoint are exactly those
  // of the uninterrupted run.
  ASSERT_EQ(resume(o.run_dir, {}), 0);
  TrainOptions whole;
  whole.run_dir = test::fresh_dir("termval_whole") + "/run";
  ASSERT_EQ(train(cfg, whole), 0);
  EXPECT_EQ(val_scores(o.run_dir, "s1"), val_scores(whole.run_dir, "s1"));
  EXPECT_EQ(val_scores(o.run_dir, "s1").size(), 5u);
  EXPECT_EQ(state_of(resolve_checkpoint(o.run_dir)).iteration, state_of(resolve_checkpoint(whole.run_dir)).iteration);
}

TEST(Trainer, ASecondWriterOnARunFolderIsRefused) {
  const auto dir = test::fresh_dir("locked") + "/run";
  std::filesystem::create_directories(dir);
  test::write_text(dir + "/config.yaml", to_yaml(tiny_config()));
  const FolderLock running(dir);  // as if a geo_train were training in it
  GEO_EXPECT_THROW_WITH(resume(dir, {}), dir, "is in use by process");
  // A new run into it is told the folder is in use (before its first checkpoint a live run has only
  // logs), never advised to remove it.
  test::write_text(dir + "/train.log", "training\n");
  TrainOptions o;
  o.run_dir = dir;
  std::string msg;
  try {
    train(tiny_config(), o);
  } catch (const std::exception& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find(dir + " is in use by process"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("remove the folder"), std::string::npos) << msg;
  EXPECT_EQ(test::read_file(dir + "/train.log"), "training\n");
}

TEST(Trainer, ExplicitCudaWithoutCudaIsAnError) {
  if (torch::cuda::is_available()) GTEST_SKIP() << "CUDA is available here";
  TrainOptions o;
  o.run_dir = test::fresh_dir("nocuda") + "/run";
  o.device = "cuda";
  GEO_EXPECT_THROW_WITH(train(tiny_config(), o), "device 'cuda'", "CUDA is not available");
}

TEST(Trainer, NonFiniteStepsAreSkippedAndStopTheRun) {
  // An absurd learning rate breaks the weights after the first update; later losses are NaN/Inf.
  auto cfg = tiny_config("optimizer: {eps: 1.0e-30}\n");
  cfg.stages.resize(1);
  cfg.stages[0].learning_rate = 1e30;
  cfg.stages[0].iterations = 50;
  cfg.logging.checkpoint_interval = 1;
  cfg.logging.max_bad_steps = 2;
  TrainOptions o;
  o.run_dir = test::fresh_dir("nan") + "/run";
  GEO_EXPECT_THROW_WITH(train(cfg, o), "NaN/Inf steps in a row", "logging.max_bad_steps",
                        "the last good checkpoint is untouched: " + o.run_dir + "/checkpoints/s1-");
  {  // Before any checkpoint: said so, not an empty path.
    auto early = cfg;
    early.logging.checkpoint_interval = 1000;
    TrainOptions e;
    e.run_dir = test::fresh_dir("nan_early") + "/run";
    GEO_EXPECT_THROW_WITH(train(early, e), "NaN/Inf steps in a row", "no checkpoint was written before it");
  }
  // Every checkpoint written holds finite weights (and there is at least the one named above).
  int64_t checked = 0;
  for (const auto& e : std::filesystem::directory_iterator(o.run_dir + "/checkpoints")) {
    if (e.path().extension() != ".pt") continue;
    ++checked;
    torch::serialize::InputArchive a, depth;
    a.load_from(e.path().string());
    ASSERT_TRUE(a.try_read("depth", depth));
    for (const auto& key : depth.keys()) {
      torch::Tensor t;
      depth.read(key, t);
      EXPECT_TRUE(torch::isfinite(t).all().item<bool>()) << e.path() << " " << key;
    }
  }
  EXPECT_GE(checked, 1);
}

}  // namespace
}  // namespace geo
