// The console sink of training (train/metrics.h ProgressSink): what it says beside the progress line.
#include "train/metrics.h"

#include <gtest/gtest.h>

#include "log_capture.h"

namespace geo {
namespace {

// The log of a stage of `iterations` steps whose auto-masked share is `masked(i)` at step i (1-based;
// negative: no auto-masking, the term absent as LossTerms::values leaves it out).
template <class F>
std::string stage_log(int64_t iterations, F masked, bool trains_depth = true) {
  return test::captured_log("%l %v", [&] {
    ProgressSink progress(1000);
    for (int64_t i = 1; i <= iterations; ++i) {
      StepRecord r;
      r.stage = "s1";
      r.iteration = i;
      r.stage_iterations = iterations;
      r.trains_depth = trains_depth;
      r.losses = {{"rigid", 0.5}, {"total", 0.5}};
      if (masked(i) >= 0) r.losses.emplace_back("automasked", masked(i));
      progress.on_step(r);
    }
  });
}

size_t count(const std::string& text, const std::string& part) {
  size_t n = 0;
  for (auto at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
  return n;
}

// Most pixels auto-masked over two windows of 50 steps in a row (of half the stage when shorter):
// warned once per stage, with the span and the share; a forward drive's 26-50% is not, nor the first
// window of one whose networks start from random weights (measured on the real KITTI runs: 62%,
// then 56%, 48%, 44%).
TEST(ProgressSink, WarnsOnceWhenMostPixelsStayAutoMasked) {
  const auto traffic = stage_log(220, [](int64_t) { return 0.7; });
  EXPECT_EQ(count(traffic, "warning "), 1u) << traffic;
  EXPECT_NE(traffic.find("stage s1: 70% of the pixels were auto-masked over iterations 1-100"), std::string::npos)
      << traffic;
  EXPECT_NE(traffic.find("geo_train --init RUN"), std::string::npos) << traffic;

  const auto forward = stage_log(120, [](int64_t i) { return i % 2 ? 0.26 : 0.5; });
  EXPECT_EQ(forward.find("warning "), std::string::npos) << forward;
  const auto from_scratch = stage_log(200, [](int64_t i) { return i <= 50 ? 0.62 : i <= 100 ? 0.56 : 0.46; });
  EXPECT_EQ(from_scratch.find("warning "), std::string::npos) << from_scratch;
  // Over the bound from the second window on: said for the second and third (the mean of both).
  const auto later = stage_log(150, [](int64_t i) { return i <= 50 ? 0.3 : i <= 100 ? 0.6 : 0.7; });
  EXPECT_NE(later.find("65% of the pixels were auto-masked over iterations 51-150"), std::string::npos) << later;
  // One window over the bound between two under it: nothing.
  EXPECT_EQ(stage_log(150, [](int64_t i) { return i > 50 && i <= 100 ? 0.9 : 0.3; }).find("warning "),
            std::string::npos);
  // A short stage in windows of half its length (geo_infer --refine 25: 12 steps each).
  const auto refine = stage_log(25, [](int64_t) { return 0.64; });
  EXPECT_NE(refine.find("64% of the pixels were auto-masked over iterations 1-24"), std::string::npos) << refine;
  EXPECT_EQ(stage_log(1, [](int64_t) { return 0.9; }).find("warning "), std::string::npos);
  // A stage that holds depth (stages[].hold_masked) has no depth to unlearn: nothing is said.
  EXPECT_EQ(stage_log(
                220, [](int64_t) { return 0.7; }, false)
                .find("warning "),
            std::string::npos);
  // Without auto-masking nothing is said.
  EXPECT_EQ(stage_log(60, [](int64_t) { return -1.0; }).find("warning "), std::string::npos);
}

}  // namespace
}  // namespace geo
