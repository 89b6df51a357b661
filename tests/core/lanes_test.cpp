// Lanes: work computed on a few threads, each with its share of the intra-op threads, taken in order.
#include "core/lanes.h"

#include <ATen/Parallel.h>
#include <gtest/gtest.h>

#include <future>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace geo {
namespace {

TEST(Lanes, PlanSharesTheThreadsEvenly) {
  const auto plan = [](int threads, int max_lanes) {
    const auto p = plan_lanes(threads, max_lanes);
    return std::to_string(p.lanes) + "x" + std::to_string(p.threads_each);
  };
  EXPECT_EQ(plan(1, 4), "1x1");
  EXPECT_EQ(plan(2, 4), "2x1");
  EXPECT_EQ(plan(3, 4), "3x1");
  EXPECT_EQ(plan(8, 4), "4x2");
  EXPECT_EQ(plan(16, 4), "4x4");
  EXPECT_EQ(plan(10, 4), "4x2");  // the rest unused rather than uneven lanes
  EXPECT_EQ(plan(8, 1), "1x8");
  EXPECT_EQ(plan(0, 4), "1x1");
  EXPECT_EQ(plan(4, 0), "1x4");
}

TEST(Lanes, ResultsComeInOrderWithEachLanesThreadsAndTheCountsComeBack) {
  at::set_num_threads(4);
  const auto caller = std::this_thread::get_id();
  std::vector<std::future<std::vector<int64_t>>> results;
  {
    Lanes lanes(LanePlan{2, 2});
    EXPECT_EQ(at::get_num_threads(), 1);  // the caller's own, while the lanes live
    for (int64_t i = 0; i < 6; ++i)
      results.push_back(lanes.submit([i, caller] {
        // [i, this lane's intra-op threads, whether it runs on another thread, an op's result]
        return std::vector<int64_t>{i, at::get_num_threads(), std::this_thread::get_id() != caller,
                                    at::arange(i + 1).sum().item<int64_t>()};
      }));
    for (int64_t i = 0; i < 6; ++i) EXPECT_EQ(results[i].get(), (std::vector<int64_t>{i, 2, 1, i * (i + 1) / 2}));
  }
  EXPECT_EQ(at::get_num_threads(), 4);
  // A new thread starts with the process's count again.
  int fresh = 0;
  std::thread([&] { fresh = at::get_num_threads(); }).join();
  EXPECT_EQ(fresh, 4);
}

TEST(Lanes, AnExceptionComesThroughItsFuture) {
  Lanes lanes(LanePlan{2, 1});
  auto bad = lanes.submit([]() -> int { throw std::runtime_error("frame 3 is damaged"); });
  auto good = lanes.submit([] { return 7; });
  try {
    bad.get();
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "frame 3 is damaged");
  }
  EXPECT_EQ(good.get(), 7);
}

}  // namespace
}  // namespace geo
