#include "core/progress.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace geo {

std::string format_duration(double s) {
  if (!(s >= 0) || s > 1e9) return "?";
  const auto t = static_cast<long long>(s + 0.5);
  char buf[32];
  if (t >= 3600) std::snprintf(buf, sizeof buf, "%lldh%02lldm", t / 3600, (t % 3600) / 60);
  else if (t >= 60) std::snprintf(buf, sizeof buf, "%lldm%02llds", t / 60, t % 60);
  else std::snprintf(buf, sizeof buf, "%llds", t);
  return buf;
}

bool Progress::interactive() {
  const char* env = std::getenv("GEO_PROGRESS");
  if (env && std::strcmp(env, "lines") == 0) return false;
  return isatty(STDERR_FILENO) != 0;
}

Progress::Progress(std::string what, int64_t total, int64_t log_every, const char* unit)
    : what_(std::move(what)), total_(std::max<int64_t>(total, 1)),
      log_every_(log_every > 0 ? log_every : std::max<int64_t>(1, total / 10)), unit_(unit),
      interactive_(interactive()) {}

std::string Progress::text(int64_t done, const std::string& details) const {
  std::string rate = "--";
  std::string eta;
  if (rate_ > 0) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.2f", rate_);
    rate = buf;
    eta = ", ETA " + format_duration(static_cast<double>(total_ - done) / rate_);
  }
  return what_ + " " + std::to_string(done) + "/" + std::to_string(total_) + (details.empty() ? "" : " " + details) +
         " | " + rate + " " + unit_ + "/s" + eta;
}

void Progress::update(int64_t done, const std::string& details) {
  const auto now = std::chrono::steady_clock::now();
  const bool log = done % log_every_ == 0 || done >= total_;
  if (last_log_done_ < 0 || done < last_log_done_) {  // the first update (or a restart) opens a stretch
    last_log_done_ = done;
    last_log_time_ = now;
  } else {
    const double secs = std::chrono::duration<double>(now - last_log_time_).count();
    if (done > last_log_done_ && secs > 0) rate_ = static_cast<double>(done - last_log_done_) / secs;
    if (log) {  // the rate is measured over the stretch since the last log line
      last_log_done_ = done;
      last_log_time_ = now;
    }
  }
  if (log) {
    clear();
    spdlog::info("{}", text(done, details));
    return;
  }
  if (!interactive_ || std::chrono::duration<double>(now - last_draw_).count() < 0.2) return;
  last_draw_ = now;
  std::fprintf(stderr, "\r\033[K%s\r", text(done, details).c_str());  // cursor back at column 0
  std::fflush(stderr);
}

void Progress::clear() const {
  if (!interactive_) return;
  std::fputs("\r\033[K", stderr);
  std::fflush(stderr);
}

void StepTimes::add(const std::string& step, double seconds) {
  for (auto& [name, total] : steps_)
    if (name == step) {
      total += seconds;
      return;
    }
  steps_.emplace_back(step, seconds);
}

double StepTimes::total() const {
  double sum = 0;
  for (const auto& step : steps_) sum += step.second;
  return sum;
}

std::string StepTimes::table(int64_t items, const char* unit, double wall) const {
  const double n = static_cast<double>(std::max<int64_t>(items, 1));
  std::string out;
  char line[160];
  std::snprintf(line, sizeof line, "%-28s %9s %12s %7s\n", "step", "total s",
                std::string(std::string("ms/") + unit).c_str(), "share");
  out += line;
  for (const auto& [name, seconds] : steps_) {
    std::snprintf(line, sizeof line, "%-28s %9.2f %12.1f %6.1f%%\n", name.c_str(), seconds, 1000 * seconds / n,
                  wall > 0 ? 100 * seconds / wall : 0.0);
    out += line;
  }
  std::snprintf(line, sizeof line, "%-28s %9.2f %12.1f %6.1f%%\n", "(not in a step)", wall - total(),
                1000 * (wall - total()) / n, wall > 0 ? 100 * (wall - total()) / wall : 0.0);
  out += line;
  std::snprintf(line, sizeof line, "%-28s %9.2f %12.1f  -> %.1f %s/s\n", "whole run", wall, 1000 * wall / n,
                wall > 0 ? n / wall : 0.0, unit);
  out += line;
  return out;
}

}  // namespace geo
