// The progress line: log lines every N items and at the end; in-place drawing only on a terminal.
#include "core/progress.h"
#include "core/runtime.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <thread>
#include <sstream>

#include "log_capture.h"

namespace geo {
namespace {

TEST(Progress, LogLinesEveryNItemsAndAtTheEndWhenNotATerminal) {
  bool interactive = true;
  const std::string out = test::captured_log("%v", [&] {
    Progress p("pack", 12, 5, "snippets");
    for (int64_t i = 1; i <= 12; ++i) p.update(i, "x");
    interactive = Progress::interactive();
  });
  std::istringstream lines(out);
  std::vector<std::string> got;
  for (std::string l; std::getline(lines, l);) got.push_back(l);
  ASSERT_EQ(got.size(), 3u) << out;  // 5, 10, 12
  EXPECT_EQ(got[0].rfind("pack 5/12 x | ", 0), 0u) << got[0];
  EXPECT_EQ(got[1].rfind("pack 10/12 x | ", 0), 0u) << got[1];
  EXPECT_EQ(got[2].rfind("pack 12/12 x | ", 0), 0u) << got[2];
  EXPECT_NE(got[1].find(" snippets/s, ETA "), std::string::npos) << got[1];
  EXPECT_EQ(out.find('\r'), std::string::npos);  // nothing drawn in place
  EXPECT_FALSE(interactive);
}

TEST(Progress, FormatDuration) {
  EXPECT_EQ(format_duration(12.4), "12s");
  EXPECT_EQ(format_duration(187), "3m07s");
  EXPECT_EQ(format_duration(3720), "1h02m");
  EXPECT_EQ(format_duration(-1), "?");
}

// geo_infer --timing's table: each step's total, its time per item and its share of the run, in the
// order the steps first ran, then what no step timed and the whole run.
TEST(StepTimes, TotalsPerStepInFirstUseOrder) {
  StepTimes t;
  t.add("depth", 1.0);
  t.add("flow", 0.5);
  t.add("depth", 1.0);
  EXPECT_DOUBLE_EQ(t.total(), 2.5);
  EXPECT_EQ(t.time("pose", [] { return 7; }), 7);  // returns what the step returns
  const auto table = t.table(10, "frame", 4.0);
  std::istringstream lines(table);
  std::string header, depth, flow, pose, rest, whole;
  std::getline(lines, header), std::getline(lines, depth), std::getline(lines, flow), std::getline(lines, pose);
  std::getline(lines, rest), std::getline(lines, whole);
  EXPECT_NE(header.find("ms/frame"), std::string::npos) << table;
  EXPECT_NE(depth.find("depth"), std::string::npos) << table;
  EXPECT_NE(depth.find("2.00"), std::string::npos) << table;   // total s
  EXPECT_NE(depth.find("200.0"), std::string::npos) << table;  // ms per frame
  EXPECT_NE(depth.find("50.0%"), std::string::npos) << table;  // of 4 s
  EXPECT_NE(flow.find("12.5%"), std::string::npos) << table;
  EXPECT_EQ(pose.rfind("pose", 0), 0u) << table;
  EXPECT_NE(rest.find("(not in a step)"), std::string::npos) << table;
  EXPECT_NE(whole.find("-> 2.5 frame/s"), std::string::npos) << table;
}

// Tools start LibTorch on every core unless OMP_NUM_THREADS says otherwise.
TEST(Runtime, ToolsUseEveryCoreUnlessOmpNumThreadsIsSet) {
  const char* saved = std::getenv("OMP_NUM_THREADS");
  const std::string before = saved ? saved : "";
  const int threads = torch::get_num_threads();
  unsetenv("OMP_NUM_THREADS");
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  EXPECT_EQ(use_all_cores(), cores);
  EXPECT_EQ(torch::get_num_threads(), cores);
  setenv("OMP_NUM_THREADS", "1", 1);
  torch::set_num_threads(1);
  EXPECT_EQ(use_all_cores(), 1);
  EXPECT_EQ(torch::get_num_threads(), 1);
  if (saved) setenv("OMP_NUM_THREADS", before.c_str(), 1);
  else unsetenv("OMP_NUM_THREADS");
  torch::set_num_threads(threads);
}

}  // namespace
}  // namespace geo
