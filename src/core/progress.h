// Console progress of long loops (training, evaluation, geo_prepare): "<what> 120/350000 | 2.31 it/s,
// ETA 42h05m | <details>". On a terminal (stderr is a TTY) the line is redrawn in place after every
// update (at most 5 times a second); every `log_every` items, and at the end, it is also written as
// a log line (spdlog), which is all that a log file or pipe receives.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace geo {

class Progress {
 public:
  // log_every <= 0: every 10% of `total`.
  Progress(std::string what, int64_t total, int64_t log_every = 0, const char* unit = "it");
  // `done` items of `total` are finished; `details` is appended (e.g. the latest losses).
  void update(int64_t done, const std::string& details = "");
  // Clears the in-place line (before other output on a terminal); no-op elsewhere.
  void clear() const;

  // Whether progress is redrawn in place (stderr is a terminal; GEO_PROGRESS=lines forces lines).
  static bool interactive();

 private:
  std::string text(int64_t done, const std::string& details) const;
  std::string what_;
  int64_t total_, log_every_;
  const char* unit_;
  bool interactive_;
  std::chrono::steady_clock::time_point last_log_time_, last_draw_;
  int64_t last_log_done_ = -1;
  double rate_ = 0;  // items per second since the last log line
};

// Wall time per named step of a run (geo_infer --timing): time("depth", f) runs f and adds its
// duration to "depth"; table() lists each step's total, its time per item and its share, in the
// order the steps first ran. Calls from one thread.
class StepTimes {
 public:
  template <class F>
  decltype(auto) time(const std::string& step, F&& f) {
    const Scope scope(*this, step);
    return f();
  }
  void add(const std::string& step, double seconds);
  double total() const;
  // "<step> <total s> <ms per item> <share>" lines, then the sum and `items` per second over `wall`
  // seconds (the whole run, which includes what no step timed).
  std::string table(int64_t items, const char* unit, double wall) const;

 private:
  struct Scope {
    Scope(StepTimes& t, const std::string& s) : times(t), step(s), start(std::chrono::steady_clock::now()) {}
    ~Scope() { times.add(step, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()); }
    StepTimes& times;
    const std::string& step;
    std::chrono::steady_clock::time_point start;
  };
  std::vector<std::pair<std::string, double>> steps_;
};

// "1h02m", "3m07s", "12s"; "?" for negative or absurd values.
std::string format_duration(double seconds);

}  // namespace geo
