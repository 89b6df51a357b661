#include "core/lanes.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <utility>

namespace geo {

LanePlan plan_lanes(int threads, int max_lanes) {
  const int lanes = std::max(1, std::min(threads, max_lanes));
  return {lanes, std::max(1, threads / lanes)};
}

Lanes::Lanes(const LanePlan& plan) : process_threads_(at::get_num_threads()) {
  at::set_num_threads(1);
  for (int i = 0; i < std::max(1, plan.lanes); ++i)
    threads_.emplace_back([this, n = std::max(1, plan.threads_each)] { run(n); });
}

Lanes::~Lanes() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  ready_.notify_all();
  for (auto& t : threads_) t.join();
  // at::set_num_threads in the lanes also set the count new threads start with: back to the caller's.
  at::set_num_threads(process_threads_);
}

void Lanes::push(std::function<void()> work) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(work));
  }
  ready_.notify_one();
}

void Lanes::run(int threads_each) {
  at::set_num_threads(threads_each);  // this thread's OpenMP team (and oneDNN's, which follows it)
  for (;;) {
    std::function<void()> work;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      ready_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      work = std::move(queue_.front());
      queue_.pop_front();
    }
    work();  // a packaged_task: its exception goes to its future
  }
}

}  // namespace geo
