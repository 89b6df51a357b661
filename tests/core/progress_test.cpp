// The progress line: log lines every N items and at the end; in-place drawing only on a terminal.
#include "core/progress.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <sstream>

namespace geo {
namespace {

TEST(Progress, LogLinesEveryNItemsAndAtTheEndWhenNotATerminal) {
  setenv("GEO_PROGRESS", "lines", 1);
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  sink->set_pattern("%v");
  auto saved = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("progress_test", sink));
  {
    Progress p("pack", 12, 5, "snippets");
    for (int64_t i = 1; i <= 12; ++i) p.update(i, "x");
  }
  spdlog::set_default_logger(saved);
  std::istringstream lines(out.str());
  std::vector<std::string> got;
  for (std::string l; std::getline(lines, l);) got.push_back(l);
  ASSERT_EQ(got.size(), 3u) << out.str();  // 5, 10, 12
  EXPECT_EQ(got[0].rfind("pack 5/12 x | ", 0), 0u) << got[0];
  EXPECT_EQ(got[1].rfind("pack 10/12 x | ", 0), 0u) << got[1];
  EXPECT_EQ(got[2].rfind("pack 12/12 x | ", 0), 0u) << got[2];
  EXPECT_NE(got[1].find(" snippets/s, ETA "), std::string::npos) << got[1];
  EXPECT_EQ(out.str().find('\r'), std::string::npos);  // nothing drawn in place
  EXPECT_FALSE(Progress::interactive());
  unsetenv("GEO_PROGRESS");
}

TEST(Progress, FormatDuration) {
  EXPECT_EQ(format_duration(12.4), "12s");
  EXPECT_EQ(format_duration(187), "3m07s");
  EXPECT_EQ(format_duration(3720), "1h02m");
  EXPECT_EQ(format_duration(-1), "?");
}

}  // namespace
}  // namespace geo
