// The metrics sinks (train/metrics.h): the CSV sink's resume trimming, TensorBoard against the global
// step, summary images where the run folder says.
#include "train/metrics.h"
#include "pipeline/run_folder.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>

#include <unistd.h>

#include "tensorboard_reader.h"
#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

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
            "stage_index,stage,iteration,total,rigid,disp_smooth,flow,flow_smooth,flow_consistency,ground,anchor,lr\n"
            "0,s1,1,1,0.5,,,,,,,0.0001\n0,s1,2,2,1,,,,,,,0.0001\n0,s1,3,3,1.5,,,,,,,0.0001\n"
            "1,s2,1,11,5.5,,,,,,,0.0001\n1,s2,2,12,6,,,,,,,0.0001\n");
  EXPECT_EQ(test::read_file(dir + "/val.csv"),
            "stage_index,stage,iteration,photometric,flow,score\n1,s2,2,0.5,0.25,0.75\n");
  csv.trim_after(1, 1);  // resumed from s2 iteration 1: later rows go
  EXPECT_EQ(test::read_file(dir + "/metrics.csv"),
            "stage_index,stage,iteration,total,rigid,disp_smooth,flow,flow_smooth,flow_consistency,ground,anchor,lr\n"
            "0,s1,1,1,0.5,,,,,,,0.0001\n0,s1,2,2,1,,,,,,,0.0001\n0,s1,3,3,1.5,,,,,,,0.0001\n"
            "1,s2,1,11,5.5,,,,,,,0.0001\n");
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

}  // namespace
}  // namespace geo
