// The console sink of training (train/metrics.h ProgressSink): what it says beside the progress line.
#include "train/metrics.h"

#include <gtest/gtest.h>

#include "log_capture.h"

namespace geo {
namespace {

// The log of a stage of `iterations` steps whose auto-masked share is `masked(i)` at step i (1-based;
// negative: no auto-masking, the term absent as LossTerms::values leaves it out).
template <class F>
std::string stage_log(int64_t iterations, F masked) {
  return test::captured_log("%l %v", [&] {
    ProgressSink progress(1000);
    for (int64_t i = 1; i <= iterations; ++i) {
      StepRecord r;
      r.stage = "s1";
      r.iteration = i;
      r.stage_iterations = iterations;
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

// Most pixels auto-masked over a window of 50 steps (or a shorter stage): warned once per stage,
// with the window and the share; a forward drive's 26-50% is not.
TEST(ProgressSink, WarnsOnceWhenMostPixelsAreAutoMasked) {
  const auto traffic = stage_log(120, [](int64_t) { return 0.7; });
  EXPECT_EQ(count(traffic, "warning "), 1u) << traffic;
  EXPECT_NE(traffic.find("stage s1: 70% of the pixels were auto-masked over iterations 1-50"), std::string::npos)
      << traffic;
  EXPECT_NE(traffic.find("geo_train --init RUN"), std::string::npos) << traffic;

  const auto forward = stage_log(120, [](int64_t i) { return i % 2 ? 0.26 : 0.5; });
  EXPECT_EQ(forward.find("warning "), std::string::npos) << forward;
  // The first window under the bound, the second over it: said for the second.
  const auto later = stage_log(100, [](int64_t i) { return i <= 50 ? 0.3 : 0.6; });
  EXPECT_NE(later.find("60% of the pixels were auto-masked over iterations 51-100"), std::string::npos) << later;
  // A stage shorter than the window is judged whole (geo_infer --refine 25).
  const auto refine = stage_log(25, [](int64_t) { return 0.64; });
  EXPECT_NE(refine.find("64% of the pixels were auto-masked over iterations 1-25"), std::string::npos) << refine;
  // Without auto-masking nothing is said.
  EXPECT_EQ(stage_log(60, [](int64_t) { return -1.0; }).find("warning "), std::string::npos);
}

}  // namespace
}  // namespace geo
