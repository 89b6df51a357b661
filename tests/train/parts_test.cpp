// The training loop's parts on their own: TensorBoard encoding, the CSV sink's resume trimming, the
// LR schedule, checkpoint rotation and best files, and run-folder resolution.
#include "core/runtime.h"
#include "models/sync_batch_norm.h"
#include "train/checkpoints.h"
#include "train/metrics.h"
#include "train/tensorboard.h"
#include "train/train_step.h"
#include "train/validate.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <map>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <numeric>

#include "tensorboard_reader.h"
#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

TEST(TensorBoard, Crc32cOfTheStandardCheckString) {
  EXPECT_EQ(crc32c("123456789"), 0xE3069283u);  // the CRC-32C check value (RFC 3720 B.4)
  EXPECT_EQ(crc32c(""), 0u);
  const uint32_t c = 0xE3069283u;
  EXPECT_EQ(masked_crc32c("123456789"), ((c >> 15) | (c << 17)) + 0xa282ead8u);
}

TEST(TensorBoard, ScalarEventBytesByHand) {
  // Event{wall_time 0.0 (field 1, fixed64), step 3 (field 2), summary (5){value (1){tag "a" (1),
  // simple_value 1.0f (2, fixed32)}}}.
  const std::string e = encode_scalar_event(0.0, 3, "a", 1.0f);
  const std::string want = std::string("\x09", 1) + std::string(8, '\0') + "\x10\x03" + "\x2a\x0a" + "\x0a\x08" +
                           "\x0a\x01" "a" + "\x15" + std::string("\x00\x00\x80\x3f", 4);
  EXPECT_EQ(e, want);
  // The TFRecord around it: 8-byte length, its masked CRC, the payload, its masked CRC.
  const std::string r = tfrecord(e);
  ASSERT_EQ(r.size(), 8 + 4 + e.size() + 4);
  EXPECT_EQ(static_cast<unsigned char>(r[0]), e.size());
  EXPECT_EQ(r.substr(12, e.size()), e);
}

TEST(TensorBoard, WriterFileReadsBack) {
  const auto dir = test::fresh_dir("tb");
  std::string path;
  {
    EventWriter w(dir);
    path = w.path();
    w.add_scalar("loss/total", 7, 0.25);
    w.add_scalar("lr", 8, 2e-4);
    w.add_image("s1/disp", 9, std::string("\x89PNG\r\n\x1a\n", 8) + std::string(300, 'x'), 4, 5, 3);
    w.add_session_start(6);
    w.flush();
  }
  EXPECT_EQ(fs::path(path).filename().string().rfind("events.out.tfevents.", 0), 0u);
  const auto ev = test::read_tensorboard_file(path);
  ASSERT_EQ(ev.size(), 5u);
  EXPECT_EQ(ev[0].file_version, "brain.Event:2");
  ASSERT_EQ(ev[1].values.size(), 1u);
  EXPECT_EQ(ev[1].step, 7);
  EXPECT_EQ(ev[1].values[0].tag, "loss/total");
  EXPECT_EQ(ev[1].values[0].simple_value, 0.25f);
  EXPECT_EQ(ev[2].values[0].simple_value, 2e-4f);
  const auto& img = ev[3].values[0];
  EXPECT_TRUE(img.has_image);
  EXPECT_EQ(img.tag, "s1/disp");
  EXPECT_EQ(ev[3].step, 9);
  EXPECT_EQ(img.height, 4);
  EXPECT_EQ(img.width, 5);
  EXPECT_EQ(img.colorspace, 3);
  EXPECT_EQ(img.png.size(), 308u);
  EXPECT_EQ(ev[4].session_status, 1);  // START
  EXPECT_EQ(ev[4].step, 6);
  EXPECT_GT(ev[1].wall_time, 1.7e9);  // seconds since 1970
}

StepRecord step_record(int64_t stage, const std::string& name, int64_t it, double total) {
  StepRecord r;
  r.stage_index = stage;
  r.stage = name;
  r.iteration = it;
  r.stage_iterations = 10;
  r.global_step = stage * 10 + it;
  r.losses = {{"rigid", total / 2}, {"total", total}};
  r.lr = 1e-4;
  return r;
}

TEST(CsvSink, RowsAndResumeTrimming) {
  const auto dir = test::fresh_dir("csv");
  CsvSink csv{RunFolder(dir)};
  for (int64_t it = 1; it <= 3; ++it) csv.on_step(step_record(0, "s1", it, it));
  for (int64_t it = 1; it <= 2; ++it) csv.on_step(step_record(1, "s2", it, 10 + it));
  ValidationRecord v;
  v.stage_index = 1;
  v.stage = "s2";
  v.iteration = 2;
  v.rigid = 0.5;
  v.flow = 0.25;
  v.score = 0.75;
  csv.on_validation(v);
  EXPECT_EQ(test::read_file(dir + "/metrics.csv"),
            "stage_index,stage,iteration,total,rigid,disp_smooth,flow,flow_smooth,flow_consistency,ground,lr\n"
            "0,s1,1,1,0.5,,,,,,0.0001\n0,s1,2,2,1,,,,,,0.0001\n0,s1,3,3,1.5,,,,,,0.0001\n"
            "1,s2,1,11,5.5,,,,,,0.0001\n1,s2,2,12,6,,,,,,0.0001\n");
  EXPECT_EQ(test::read_file(dir + "/val.csv"),
            "stage_index,stage,iteration,photometric,flow,score\n1,s2,2,0.5,0.25,0.75\n");
  csv.trim_after(1, 1);  // resumed from s2 iteration 1: later rows go
  EXPECT_EQ(test::read_file(dir + "/metrics.csv"),
            "stage_index,stage,iteration,total,rigid,disp_smooth,flow,flow_smooth,flow_consistency,ground,lr\n"
            "0,s1,1,1,0.5,,,,,,0.0001\n0,s1,2,2,1,,,,,,0.0001\n0,s1,3,3,1.5,,,,,,0.0001\n"
            "1,s2,1,11,5.5,,,,,,0.0001\n");
  EXPECT_EQ(test::read_file(dir + "/val.csv"), "stage_index,stage,iteration,photometric,flow,score\n");
}

TEST(TensorBoardSink, LossesLrAndValidationAgainstTheGlobalStep) {
  const auto dir = test::fresh_dir("tbsink");
  {
    TensorBoardSink tb(RunFolder(dir), 12);
    tb.on_step(step_record(1, "s2", 3, 2.5));
    ValidationRecord v;
    v.global_step = 13;
    v.rigid = 0.5;
    v.score = 0.5;
    tb.on_validation(v);
  }
  const auto ev = test::read_tensorboard_dir(dir + "/tb");
  std::map<std::string, std::pair<int64_t, float>> seen;
  for (const auto& e : ev)
    for (const auto& v : e.values) seen[v.tag] = {e.step, v.simple_value};
  EXPECT_EQ(ev[1].session_status, 1);  // resumed at global step 12
  EXPECT_EQ(ev[1].step, 12);
  EXPECT_EQ(seen["loss/total"], std::make_pair(int64_t{13}, 2.5f));
  EXPECT_EQ(seen["loss/rigid"], std::make_pair(int64_t{13}, 1.25f));
  EXPECT_EQ(seen["lr"], std::make_pair(int64_t{13}, 1e-4f));
  EXPECT_EQ(seen["val/photometric"], std::make_pair(int64_t{13}, 0.5f));
  EXPECT_EQ(seen.count("val/flow"), 0u);  // no flow validation in this record
}

TEST(LrSchedule, ConstantAndStep) {
  StageConfig s;
  s.learning_rate = 1e-3;
  EXPECT_EQ(LrSchedule::of(s).at(123456), 1e-3);
  s.lr_schedule = LrScheduleKind::kStep;
  s.lr_step = 10;
  s.lr_gamma = 0.5;
  const auto l = LrSchedule::of(s);
  EXPECT_EQ(l.at(0), 1e-3);
  EXPECT_EQ(l.at(9), 1e-3);
  EXPECT_EQ(l.at(10), 5e-4);
  EXPECT_EQ(l.at(25), 2.5e-4);
}

TEST(CheckpointNames, RoundTrip) {
  EXPECT_EQ(checkpoint_name("stage-2", 42), "stage-2-00000042.pt");
  EXPECT_EQ(stage_of_checkpoint("stage-2-00000042.pt"), "stage-2");
  EXPECT_EQ(stage_of_checkpoint("best-s1.pt"), "");
  EXPECT_EQ(stage_of_checkpoint("latest"), "");
}

// Every path of a run is the folder's: the layout written out here by hand.
TEST(RunFolder, PathsNewFoldersAndTheFilesOfARun) {
  const auto dir = test::fresh_dir("run_folder");
  const RunFolder f(dir + "/r");
  EXPECT_EQ(f.config(), dir + "/r/config.yaml");
  EXPECT_EQ(f.log(), dir + "/r/train.log");
  EXPECT_EQ(f.metrics_csv(), dir + "/r/metrics.csv");
  EXPECT_EQ(f.validation_csv(), dir + "/r/val.csv");
  EXPECT_EQ(f.tensorboard(), dir + "/r/tb");
  EXPECT_EQ(f.summary("stage2", 120, "flow"), dir + "/r/summaries/stage2-120-flow.png");
  EXPECT_EQ(f.checkpoint("stage2", 120), dir + "/r/checkpoints/stage2-00000120.pt");
  EXPECT_EQ(f.best("stage2"), dir + "/r/checkpoints/best-stage2.pt");
  EXPECT_EQ(f.latest_pointer(), dir + "/r/checkpoints/latest");
  EXPECT_EQ(f.latest(), "");
  EXPECT_TRUE(f.run_files().empty());
  fs::create_directories(f.checkpoints());
  test::write_text(f.metrics_csv(), "x\n");
  EXPECT_EQ(f.run_files(), (std::vector<std::string>{"metrics.csv", "checkpoints"}));
  test::write_text(f.latest_pointer(), "stage2-00000120.pt\n");
  EXPECT_EQ(f.latest(), f.checkpoint("stage2", 120));
  // New folders: <name>-<date>-<time>, never one that exists (a second in the same second gets -2).
  const RunFolder a = RunFolder::create_new(dir + "/runs", "demo"), b = RunFolder::create_new(dir + "/runs", "demo");
  EXPECT_NE(a.root(), b.root());
  EXPECT_TRUE(fs::is_directory(a.root()) && fs::is_directory(b.root()));
  EXPECT_EQ(fs::path(a.root()).filename().string().rfind("demo-", 0), 0u);
  EXPECT_EQ(fs::path(a.root()).filename().string().size(), std::string("demo-20261124-120000").size());
}

// Summary images land as the PNG bytes they carry, named by stage, iteration and tag.
TEST(SummaryPngSink, WritesEachImageWhereTheRunFolderSays) {
  const auto dir = test::fresh_dir("summary_sink");
  SummaryPngSink sink{RunFolder(dir)};
  ImageRecord r;
  r.stage = "stage1";
  r.iteration = 40;
  r.tag = "disp";
  r.png = std::string("\x89PNG\r\n\x1a\n fake", 13);
  sink.on_image(r);
  EXPECT_EQ(test::read_file(dir + "/summaries/stage1-40-disp.png"), r.png);
}

void fill_state(torch::serialize::OutputArchive& a, int64_t stage, int64_t it) {
  TrainState s;
  s.stage = stage;
  s.iteration = it;
  s.best_score = 0.5;
  write_train_state(a, s);
}

TrainState state_of(const std::string& path) {
  return CheckpointFile(path).train_state();
}

TEST(CheckpointManager, RotationKeepsBestFilesAndLatest) {
  const auto dir = test::fresh_dir("ckpt");
  {
    CheckpointManager m(RunFolder(dir), 2);
    EXPECT_EQ(m.latest(), "");
    m.save("s1", 1, true, [](auto& a) { fill_state(a, 0, 1); });
    m.save("s1", 2, false, [](auto& a) { fill_state(a, 0, 2); });
    m.save("s2", 1, false, [](auto& a) { fill_state(a, 1, 1); });
    m.save("s2", 2, true, [](auto& a) { fill_state(a, 1, 2); });
    EXPECT_EQ(m.latest(), dir + "/checkpoints/s2-00000002.pt");
  }
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints")) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"best-s1.pt", "best-s2.pt", "latest", "s2-00000001.pt", "s2-00000002.pt"}));
  // best-s1.pt outlived the rotation of s1-00000001.pt, its content intact.
  EXPECT_EQ(state_of(dir + "/checkpoints/best-s1.pt").iteration, 1);
  EXPECT_EQ(resolve_checkpoint(dir), dir + "/checkpoints/best-s2.pt");
  // A resumed manager continues the rotation from the files present.
  CheckpointManager again(RunFolder(dir), 2);
  again.save("s2", 3, false, [](auto& a) { fill_state(a, 1, 3); });
  EXPECT_FALSE(fs::exists(dir + "/checkpoints/s2-00000001.pt"));
  EXPECT_TRUE(fs::exists(dir + "/checkpoints/s2-00000002.pt"));
}

// Names decide what rotates and what is cleaned up: a stage named "best_fit" keeps its checkpoints
// in the rotation (they are not best files), and only real temporary files are removed.
TEST(CheckpointManager, NamesDecideWhatRotatesAndWhatIsATemporaryFile) {
  EXPECT_TRUE(is_best_checkpoint_name("best-stage1.pt"));
  EXPECT_TRUE(is_best_checkpoint_name("best-best_fit.pt"));
  EXPECT_FALSE(is_best_checkpoint_name("best_fit-00000010.pt"));
  EXPECT_FALSE(is_best_checkpoint_name("best-x-00000010.pt"));  // stage "best-x"'s checkpoint
  EXPECT_FALSE(is_best_checkpoint_name("bestiary.pt"));
  EXPECT_TRUE(is_rotation_checkpoint_name("best_fit-00000010.pt"));
  EXPECT_FALSE(is_rotation_checkpoint_name("s1-0000010.pt"));
  EXPECT_TRUE(is_temporary_file_name("s1-00000002.pt.tmp.1234"));
  EXPECT_TRUE(is_temporary_file_name("best-s1.pt.tmp"));
  EXPECT_FALSE(is_temporary_file_name("notes.tmp.txt"));
  EXPECT_FALSE(is_temporary_file_name("my.tmp.backup.pt"));

  const auto dir = test::fresh_dir("ckpt_names");
  fs::create_directories(dir + "/checkpoints");
  for (const char* f : {"notes.tmp.txt", "s1-00000002.pt.tmp.1234", "best-s1.pt.tmp"})
    test::write_text(dir + "/checkpoints/" + f, "x");
  {
    CheckpointManager m(RunFolder(dir), 2);
    for (int64_t it = 1; it <= 3; ++it)
      m.save("best_fit", it, it == 1, [it](auto& a) { fill_state(a, 0, it); });
  }
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints")) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"best-best_fit.pt", "best_fit-00000002.pt", "best_fit-00000003.pt",
                                          "latest", "notes.tmp.txt"}));
  EXPECT_EQ(state_of(dir + "/checkpoints/best-best_fit.pt").iteration, 1);
}

TEST(CheckpointManager, AFailedWriteKeepsTheLastCheckpointAndLatest) {
  const auto dir = test::fresh_dir("ckpt_full");
  CheckpointManager m(RunFolder(dir), 3);
  m.save("s1", 1, true, [](auto& a) { fill_state(a, 0, 1); });
  // The disk is full for the next checkpoint (its temporary file is a link to /dev/full).
  const std::string next = dir + "/checkpoints/s1-00000002.pt";
  ASSERT_EQ(::symlink("/dev/full", (next + ".tmp." + std::to_string(::getpid())).c_str()), 0);
  GEO_EXPECT_THROW_WITH(m.save("s1", 2, true, [](auto& a) { fill_state(a, 0, 2); }), next,
                        "No space left on device");
  EXPECT_EQ(m.latest(), dir + "/checkpoints/s1-00000001.pt");
  EXPECT_EQ(state_of(dir + "/checkpoints/best-s1.pt").iteration, 1);
  EXPECT_FALSE(fs::exists(next));
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints"))
    EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << e.path();
}

TEST(CheckpointManager, ATruncatedLatestNamesTheNewestReadableCheckpoint) {
  const auto dir = test::fresh_dir("ckpt_trunc");
  CheckpointManager m(RunFolder(dir), 5);
  m.save("s1", 1, false, [](auto& a) { fill_state(a, 0, 1); });
  const std::string last = m.save("s1", 2, false, [](auto& a) { fill_state(a, 0, 2); });
  EXPECT_NO_THROW(m.check_resumable(last));
  const std::string bytes = test::read_file(last);
  test::write_text(last, bytes.substr(0, bytes.size() / 2));  // a kill in the middle of a copy
  GEO_EXPECT_THROW_WITH(m.check_resumable(last), "cannot resume", last, "truncated",
                        "The newest readable checkpoint is s1-00000001.pt");
  test::write_text(dir + "/checkpoints/random.pt", "not a checkpoint");
  GEO_EXPECT_THROW_WITH(m.check_resumable(dir + "/checkpoints/random.pt"), "random.pt", "s1-00000001.pt");
}

TEST(ResolveCheckpoint, FilesFoldersAndErrors) {
  const auto dir = test::fresh_dir("resolve");
  const std::string missing = dir + "/nothing";
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(missing), missing.c_str(), "does not exist");
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(dir), "has no checkpoint");
  CheckpointManager m(RunFolder(dir), 3);
  m.save("s1", 4, true, [](auto& a) { fill_state(a, 0, 4); });
  m.save("s2", 1, false, [](auto& a) { fill_state(a, 1, 1); });
  // The last stage has no best yet (no validation): its latest checkpoint, not stage 1's best.
  EXPECT_EQ(resolve_checkpoint(dir), dir + "/checkpoints/s2-00000001.pt");
  EXPECT_EQ(resolve_checkpoint(dir + "/checkpoints/best-s1.pt"), dir + "/checkpoints/best-s1.pt");
  test::write_text(dir + "/checkpoints/latest", "s2-00000009.pt\n");
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(dir), "s2-00000009.pt", "does not exist");
}

TEST(Networks, GeoNetBatchNormByDefaultAndTrainableSetOncePerStage) {
  Config c = parse_config("model: {encoder_depth: 18}\n");
  Networks n = Networks::create(NetworkSpec::of(c), true);
  int bns = 0;
  for (const auto& m : n.depth->modules())
    if (const auto* bn = m->as<SyncBatchNorm2d>()) {
      ++bns;
      EXPECT_EQ(bn->options.eps(), 1e-3);            // slim's epsilon
      EXPECT_EQ(bn->options.momentum().value(), 1e-3);  // slim's decay 0.999
      EXPECT_FALSE(bn->weight.requires_grad());     // scale=False: gamma stays 1
    }
  EXPECT_GT(bns, 20);
  StageConfig flow_only;
  flow_only.train = NetworkSet{false, false, true};
  n.set_trainable(flow_only);
  const auto params = n.trainable_parameters();
  int64_t flow_trainable = 0;
  for (const auto& p : n.flow->parameters()) flow_trainable += p.requires_grad();
  EXPECT_EQ(static_cast<int64_t>(params.size()), flow_trainable);
  EXPECT_EQ(static_cast<int64_t>(n.flow->parameters().size() - batchnorm_scales(*n.flow).size()), flow_trainable);
  for (const auto& p : n.depth->parameters()) EXPECT_FALSE(p.requires_grad());
  // trainable_parameters() only reads: calling it again changes nothing.
  EXPECT_EQ(n.trainable_parameters().size(), params.size());

  // LibTorch's convention as the option: learned gamma, eps 1e-5, momentum 0.1.
  c = parse_config("model: {encoder_depth: 18, bn_eps: 1.0e-5, bn_momentum: 0.1, bn_scale: true}\n");
  Networks t = Networks::create(NetworkSpec::of(c), false);
  t.set_trainable(c.stages[0]);
  EXPECT_EQ(t.trainable_parameters().size(), t.depth->parameters().size() + t.pose->parameters().size());
  for (const auto& m : t.pose->modules())
    if (const auto* bn = m->as<SyncBatchNorm2d>()) {
      EXPECT_EQ(bn->options.momentum().value(), 0.1);
    }
}

}  // namespace
}  // namespace geo

namespace geo {
namespace {

TEST(ComputeLosses, NumScalesSetsTheScalesOfEveryTerm) {
  torch::manual_seed(5);
  for (int scales : {1, 4}) {
    Config c = parse_config("model: {encoder_depth: 18, num_scales: " + std::to_string(scales) + "}\n");
    c.stages[0].train = NetworkSet{true, true, true};
    Networks n = Networks::create(NetworkSpec::of(c), true);
    // Batch 2 at 64x128: BatchNorm in training needs more than one value per channel at the
    // PoseNet's 1x1 output.
    const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
    const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
    const auto out = compute_losses(n, tgt, srcs, K, c.stages[0], c);
    EXPECT_EQ(out.tgt_disp.size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.rigid.fwd_flow[1].size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.fwd_full[0].size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.flow->fwd_visible[0].size(), static_cast<size_t>(scales));
    EXPECT_TRUE(std::isfinite(out.losses.total.item<double>()));
  }
}

// Training and inference feed the FlowNet the same input (rigid_flow_net_input): in eval mode the
// training forward's full flow to the next frame equals predict_pair's for the same weights and
// frames. Not bit for bit: training runs the DepthNet over the target and its sources in one batch,
// inference over the target alone, and oneDNN's convolutions round differently per batch size.
TEST(ComputeLosses, FullFlowEqualsInferencesFlow) {
  torch::manual_seed(9);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  Networks n = Networks::create(NetworkSpec::of(c), true);
  n.depth->eval();
  n.pose->eval();
  n.flow->eval();
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  torch::NoGradGuard no_grad;
  const auto out = compute_losses(n, tgt, srcs, K, stage, c);
  const auto p = predict_pair(n, tgt, srcs.select(1, 1), K, srcs.select(1, 0));
  const auto& trained = out.fwd_full[1][0];
  ASSERT_EQ(p.flow.sizes(), trained.sizes());
  const double scale = trained.abs().max().item<double>();
  EXPECT_GT(scale, 0.1);
  EXPECT_LT((p.flow - trained).abs().max().item<double>(), 1e-4 * scale);
  EXPECT_LT((p.rigid_flow - out.rigid.fwd_flow[1][0]).abs().max().item<double>(), 1e-4 * scale);
  // The residual is not zero: the comparison covers the FlowNet, not only the rigid flow.
  EXPECT_GT((trained - out.rigid.fwd_flow[1][0]).abs().max().item<double>(), 1e-3 * scale);
}

// model.learn_intrinsics: the warp uses the PoseNet's camera. The data's K changes nothing, the
// camera starts at fx = fy = ln 2 W with the principal point centred, and the loss trains the head.
TEST(ComputeLosses, LearnedIntrinsicsReplaceTheDataCamera) {
  torch::manual_seed(13);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2, learn_intrinsics: true}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  n.set_trainable(c.stages[0]);
  n.set_modes(c.stages[0]);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  {
    // Move the pose away from identity so that the camera matters to the warp.
    torch::NoGradGuard no_grad;
    n.pose->pred->bias.fill_(3.0);
  }
  const auto K1 = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const auto K2 = K1 * torch::tensor({3.f, 3.f, 1.f}).view({1, 3, 1});
  const auto a = compute_losses(n, tgt, srcs, K1, c.stages[0], c);
  const auto b = compute_losses(n, tgt, srcs, K2, c.stages[0], c);
  EXPECT_DOUBLE_EQ(a.losses.total.item<double>(), b.losses.total.item<double>());
  const auto K = n.pose->predict(tgt, {srcs.select(1, 0), srcs.select(1, 1)}).K;
  ASSERT_TRUE(K.defined());
  EXPECT_NEAR(K[0][0][0].item<double>(), std::log(2.0) * 128, 1e-4);
  EXPECT_NEAR(K[0][1][1].item<double>(), std::log(2.0) * 128, 1e-4);
  EXPECT_NEAR(K[0][0][2].item<double>(), 64, 1e-4);
  EXPECT_NEAR(K[0][1][2].item<double>(), 32, 1e-4);
  a.losses.total.backward();
  ASSERT_TRUE(n.pose->intrinsics->weight.grad().defined());
  EXPECT_GT(n.pose->intrinsics->weight.grad().abs().sum().item<double>(), 0);
  // Without learning, the data's camera is used: the two K give different losses.
  Config plain = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  torch::manual_seed(13);
  Networks m = Networks::create(NetworkSpec::of(plain), false);
  m.set_modes(plain.stages[0]);
  {
    torch::NoGradGuard no_grad;
    m.pose->pred->bias.fill_(3.0);
  }
  torch::NoGradGuard no_grad;
  EXPECT_NE(compute_losses(m, tgt, srcs, K1, plain.stages[0], plain).losses.total.item<double>(),
            compute_losses(m, tgt, srcs, K2, plain.stages[0], plain).losses.total.item<double>());
}

}  // namespace
}  // namespace geo

namespace geo {
namespace {

// Three parameters; the third gets its first gradient at step 3 (so it lags two steps behind).
std::vector<torch::Tensor> adam_params() {
  torch::manual_seed(11);
  return {torch::randn({4, 3}).requires_grad_(), torch::randn({5}).requires_grad_(),
          torch::randn({2, 2, 3}).requires_grad_()};
}

std::vector<torch::Tensor> clones(const std::vector<torch::Tensor>& ps) {
  std::vector<torch::Tensor> out;
  for (const auto& p : ps) out.push_back(p.detach().clone().requires_grad_());
  return out;
}

void set_grads(std::vector<torch::Tensor>& ps, int step) {
  torch::manual_seed(100 + step);
  for (size_t i = 0; i < ps.size(); ++i) {
    auto g = torch::randn_like(ps[i]) * static_cast<double>(i + 1);
    if (i == 2 && step < 3) ps[i].mutable_grad() = torch::Tensor();
    else ps[i].mutable_grad() = g;
  }
}

// Validation weighs every snippet once: 5 snippets in batches of 2 (the loader fills the last batch
// from the start of the list again) score the mean of the 5 validated one at a time. The PoseNet
// predicts no motion (its last layer zeroed), so every pixel stays in view and each snippet's loss
// is a mean over the same number of pixels: the mean of the 5 is then exact.
TEST(Validation, EverySnippetCountsOnce) {
  struct Fixed : SnippetSource {
    std::vector<Snippet> s;
    size_t size() const override { return s.size(); }
    Snippet get(size_t i) const override { return s.at(i); }
    std::string id(size_t i) const override { return std::to_string(i); }
    int64_t seq_length() const override { return 3; }
  };
  torch::manual_seed(4);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 1}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  {
    torch::NoGradGuard no_grad;
    n.pose->pred->weight.zero_();
    n.pose->pred->bias.zero_();
  }
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({3, 3});
  auto all = std::make_shared<Fixed>();
  for (int i = 0; i < 5; ++i)  // snippet 0 of high contrast: a loss unlike the others'
    all->s.push_back(Snippet{torch::rand({3, 3, 64, 128}) * (i == 0 ? 1.0 : 0.1), K, "s" + std::to_string(i)});
  StageConfig stage = c.stages[0];
  stage.batch_size = 2;
  const auto batched = validate(n, all, stage, c, torch::kCPU, nullptr);
  EXPECT_EQ(batched.snippets, 5u);
  stage.batch_size = 1;
  std::vector<double> each;
  for (int i = 0; i < 5; ++i) {
    auto one = std::make_shared<Fixed>();
    one->s = {all->s[static_cast<size_t>(i)]};
    each.push_back(validate(n, one, stage, c, torch::kCPU, nullptr).rigid);
  }
  const double sum = std::accumulate(each.begin(), each.end(), 0.0), mean = sum / 5;
  // The mean of the batch means, the wrapped snippet 0 counted twice, is measurably off.
  EXPECT_GT(std::abs((sum + each[0]) / 6 - mean), 1e-2 * mean);
  EXPECT_NEAR(batched.rigid, mean, 1e-5 * mean);
  EXPECT_EQ(batched.score, batched.rigid);  // a depth-and-pose stage is ranked by L_br
}

TEST(MultiTensorAdam, BitIdenticalToTorchAdamAndStateInterchangeable) {
  auto a = adam_params(), b = clones(a);
  const auto options = torch::optim::AdamOptions(1e-2).betas({0.9, 0.999}).eps(1e-8).weight_decay(0.01);
  MultiTensorAdam fast(a, options);
  torch::optim::Adam reference(b, options);
  for (int step = 1; step <= 5; ++step) {
    set_grads(a, step);
    set_grads(b, step);
    fast.step();
    reference.step();
    for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(a[i], b[i])) << "step " << step << " param " << i;
  }
  // The third parameter got gradients from step 3 on: 3 steps, the others 5; its moments are the
  // reference's.
  for (size_t i = 0; i < a.size(); ++i) {
    const auto* mine = adam_state_of(fast, a[i]);
    const auto* theirs = adam_state_of(reference, b[i]);
    ASSERT_TRUE(mine && theirs) << "param " << i;
    EXPECT_EQ(mine->step(), i == 2 ? 3 : 5) << "param " << i;
    EXPECT_EQ(theirs->step(), mine->step()) << "param " << i;
    EXPECT_TRUE(torch::equal(mine->exp_avg_sq(), theirs->exp_avg_sq())) << "param " << i;
  }
  // Saved by one, loaded by the other (the checkpoint format is torch::optim::Adam's): the next
  // update is the same again.
  const auto dir = test::fresh_dir("adam_state");
  torch::serialize::OutputArchive out;
  fast.save(out);
  out.save_to(dir + "/fast.pt");
  auto c = clones(a);
  torch::optim::Adam loaded(c, options);
  torch::serialize::InputArchive in;
  in.load_from(dir + "/fast.pt");
  loaded.load(in);
  set_grads(a, 6);
  set_grads(c, 6);
  fast.step();
  loaded.step();
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(a[i], c[i])) << "param " << i;
}

TEST(GradientNorm, OneReductionOverAllGradients) {
  std::vector<torch::Tensor> ps{torch::zeros({2}).requires_grad_(), torch::zeros({1}).requires_grad_(),
                                torch::zeros({3}).requires_grad_()};
  ps[0].mutable_grad() = torch::tensor({3.0f, 4.0f});
  ps[1].mutable_grad() = torch::tensor({12.0f});
  // ps[2] has no gradient: left out.
  EXPECT_FLOAT_EQ(gradient_norm(ps).item<float>(), 13.0f);
  EXPECT_FALSE(gradient_norm({ps[2]}).defined());
}

// optimizer.grad_clip: the step reports the norm before clipping and leaves the gradients it
// applied scaled to the bound (torch::nn::utils::clip_grad_norm_'s rule); the losses it reports
// are the loss terms of the step.
TEST(TrainStep, ClipsToTheBoundAndReportsTheNormBefore) {
  torch::manual_seed(5);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 1}\noptimizer: {grad_clip: 0.001}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  TrainStep step(n, c, c.stages[0]);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const StepResult r = step.run(tgt, srcs, K, 1e-4);
  ASSERT_TRUE(r.finite);
  EXPECT_GT(r.grad_norm, 0.001);
  const double after = gradient_norm(n.trainable_parameters()).item<double>();
  EXPECT_NEAR(after, 0.001 * r.grad_norm / (r.grad_norm + 1e-6), 1e-7);
  ASSERT_EQ(r.losses.back().first, "total");
  EXPECT_EQ(r.losses.size(), 3u);  // rigid, disp_smooth, total
}

// run.precision bf16: the networks run under bf16 autocast, the losses stay float32 and close to
// the fp32 step's; gradients reach every parameter in float32; autocast is off again afterwards.
TEST(Precision, Bf16NetworksWithFloat32Losses) {
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  torch::manual_seed(5);
  Networks n = Networks::create(NetworkSpec::of(c), true);
  n.set_modes(stage);
  n.set_trainable(stage);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const auto fp32 = compute_losses(n, tgt, srcs, K, stage, c).losses.values();
  Config b = parse_config("model: {encoder_depth: 18, num_scales: 2}\nrun: {precision: bf16}\n");
  auto out = compute_losses(n, tgt, srcs, K, stage, b);
  EXPECT_FALSE(autocast_enabled(torch::kCPU));
  EXPECT_EQ(out.tgt_disp[0].scalar_type(), torch::kFloat32);
  EXPECT_EQ(out.fwd_full[0][0].scalar_type(), torch::kFloat32);
  EXPECT_EQ(out.losses.total.scalar_type(), torch::kFloat32);
  const auto bf16 = out.losses.values();
  ASSERT_EQ(bf16.size(), fp32.size());
  EXPECT_NE(bf16.back().second, fp32.back().second);  // the networks did run in bfloat16
  for (size_t i = 0; i < fp32.size(); ++i)  // bfloat16 keeps 8 bits of mantissa
    EXPECT_NEAR(bf16[i].second, fp32[i].second, 0.05 * std::abs(fp32[i].second) + 1e-3) << fp32[i].first;
  out.losses.total.backward();
  for (const auto& p : n.trainable_parameters()) {
    ASSERT_TRUE(p.grad().defined());
    EXPECT_EQ(p.grad().scalar_type(), torch::kFloat32);
    EXPECT_TRUE(torch::isfinite(p.grad()).all().item<bool>());
  }
  GEO_EXPECT_THROW_WITH(parse_config("run: {precision: fp16}\n"), "run.precision", "fp32, tf32, bf16");
  {
    Bf16Autocast on(true, torch::kCPU);
    EXPECT_EQ(torch::conv2d(torch::rand({1, 2, 4, 4}), torch::rand({3, 2, 1, 1})).scalar_type(), torch::kBFloat16);
    Bf16Autocast off(false, torch::kCPU);
    EXPECT_TRUE(autocast_enabled(torch::kCPU));
  }
  EXPECT_FALSE(autocast_enabled(torch::kCPU));
}

// stages[].freeze_batch_norm (geo_infer --refine): the weights train while every BatchNorm
// normalises with, and keeps, its running statistics; without it a step moves them.
TEST(ComputeLosses, FrozenBatchNormKeepsItsRunningStatistics) {
  auto running = [](const Networks& n) {
    std::vector<torch::Tensor> out;
    for (const torch::nn::Module* net : {static_cast<const torch::nn::Module*>(n.depth.get()),
                                         static_cast<const torch::nn::Module*>(n.pose.get())})
      for (const auto& m : net->modules())
        if (const auto* bn = m->as<SyncBatchNorm2d>()) out.push_back(bn->running_mean.clone());
    return out;
  };
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  for (const bool frozen : {true, false}) {
    Config c = parse_config(std::string("model: {encoder_depth: 18, num_scales: 2}\nstages: [{freeze_batch_norm: ") +
                            (frozen ? "true" : "false") + "}]\n");
    torch::manual_seed(5);
    Networks n = Networks::create(NetworkSpec::of(c), false);
    n.set_trainable(c.stages[0]);
    n.set_modes(c.stages[0]);
    EXPECT_TRUE(n.depth->is_training());
    const auto before = running(n);
    ASSERT_GT(before.size(), 20u);
    compute_losses(n, tgt, srcs, K, c.stages[0], c).losses.total.backward();
    const auto after = running(n);
    size_t moved = 0;
    for (size_t i = 0; i < before.size(); ++i) moved += torch::equal(before[i], after[i]) ? 0 : 1;
    EXPECT_EQ(moved, frozen ? 0u : before.size()) << (frozen ? "frozen" : "training");
    ASSERT_TRUE(n.depth->parameters().front().grad().defined());  // the weights train either way
    EXPECT_GT(n.depth->parameters().front().grad().abs().sum().item<double>(), 0);
  }
}

// loss.flow_input_gradient (GeoNet's graph): in a stage that trains depth and pose with the flow,
// L_fr reaches the DepthNet and PoseNet through the FlowNet's input too. The FlowNet's own gradients
// are the same either way (bit for bit: the same forward values and the same gradient from the loss);
// the DepthNet's and PoseNet's differ; in a flow-only stage the setting changes nothing.
TEST(ComputeLosses, FlowInputGradientReachesDepthAndPoseOnlyInAJointStage) {
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  auto gradients = [&](bool keep, bool joint) {
    Config c = parse_config(std::string("model: {encoder_depth: 18, num_scales: 2}\nloss: {flow_input_gradient: ") +
                            (keep ? "true" : "false") +
                            "}\nstages: [{weights: {rigid: 0, disp_smooth: 0, flow: 1, flow_smooth: 0, "
                            "flow_consistency: 0}}]\n");
    c.stages[0].train = NetworkSet{joint, joint, true};
    torch::manual_seed(5);
    Networks n = Networks::create(NetworkSpec::of(c), true);
    n.set_trainable(c.stages[0]);
    n.set_modes(c.stages[0]);
    compute_losses(n, tgt, srcs, K, c.stages[0], c).losses.total.backward();
    std::map<std::string, std::vector<torch::Tensor>> g;
    for (auto [name, net] : std::vector<std::pair<std::string, torch::nn::Module*>>{
             {"depth", n.depth.get()}, {"pose", n.pose.get()}, {"flow", n.flow.get()}})
      for (const auto& p : net->parameters())
        g[name].push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
    return g;
  };
  auto same = [](const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
    for (size_t i = 0; i < a.size(); ++i)
      if (!torch::equal(a[i], b[i])) return false;
    return true;
  };
  auto norm = [](const std::vector<torch::Tensor>& a) {
    double s = 0;
    for (const auto& t : a) s += t.square().sum().item<double>();
    return std::sqrt(s);
  };
  auto distance = [](const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
    double s = 0;
    for (size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]).square().sum().item<double>();
    return std::sqrt(s);
  };
  const auto kept = gradients(true, true), cut = gradients(false, true);
  EXPECT_TRUE(same(kept.at("flow"), cut.at("flow")));
  for (const char* net : {"depth", "pose"}) {
    ASSERT_GT(norm(cut.at(net)), 0) << net << ": L_fr reaches it through the rigid flow either way";
    EXPECT_GT(distance(kept.at(net), cut.at(net)), 1e-3 * norm(cut.at(net))) << net;
  }
  const auto flow_only_kept = gradients(true, false), flow_only_cut = gradients(false, false);
  for (const char* net : {"depth", "pose", "flow"}) EXPECT_TRUE(same(flow_only_kept.at(net), flow_only_cut.at(net))) << net;
  EXPECT_EQ(norm(flow_only_kept.at("depth")), 0.0);
}

}  // namespace
}  // namespace geo
