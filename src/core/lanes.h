// Independent pieces of LibTorch work computed a few at once, each on its own thread with its own
// share of the intra-op threads, their results taken in the order they were given.
//
// Why: at batch 1 a network parallelises poorly over cores (the int8 DepthNet at 128x416: 37 ms on
// one core, 32 ms on two, a 2-core AMD EPYC), while two frames computed side by side on one core
// each go at one core's speed. A sequence's frames are independent once read (Model::run_sequence),
// so lanes turn the idle half of the machine into a second frame.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace geo {

struct LanePlan {
  int lanes = 1;         // work items computed at once
  int threads_each = 1;  // LibTorch intra-op threads of each
};

// How `threads` intra-op threads (LibTorch's, e.g. at::get_num_threads()) are split: up to
// `max_lanes` lanes of at least one thread each, the threads shared evenly (2 -> 2 lanes of 1,
// 8 -> 4 of 2 with max_lanes 4). One lane where threads or max_lanes is 1 or less.
LanePlan plan_lanes(int threads, int max_lanes);

class Lanes {
 public:
  // plan.lanes threads, each running its work with plan.threads_each intra-op threads. While the
  // lanes live the calling thread runs with one (what it does between, handing results on, is
  // small; a team of its own would spin on the cores the lanes use: measured, 2 frames in flight on
  // 2 cores took 1.6x one frame's time until it stopped). The caller's count comes back when the
  // lanes end (LibTorch sets a thread's count through a process-wide value, also put back).
  explicit Lanes(const LanePlan& plan);
  // Waits for the work being computed; work not started is dropped (its future reports a broken
  // promise).
  ~Lanes();
  Lanes(const Lanes&) = delete;
  Lanes& operator=(const Lanes&) = delete;

  // Queues f; its result (or its exception) comes through the future.
  template <class F>
  std::future<std::invoke_result_t<F>> submit(F f) {
    auto task = std::make_shared<std::packaged_task<std::invoke_result_t<F>()>>(std::move(f));
    auto result = task->get_future();
    push([task] { (*task)(); });
    return result;
  }

 private:
  void push(std::function<void()> work);
  void run(int threads_each);

  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  int process_threads_ = 1;
  std::vector<std::thread> threads_;
};

}  // namespace geo
