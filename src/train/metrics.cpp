#include "train/metrics.h"

#include "core/config_stages.h"
#include "core/files.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;

namespace geo {
namespace {

const char* kTermColumns[] = {"rigid", "disp_smooth", "flow", "flow_smooth", "flow_consistency", "ground", "anchor"};

std::optional<double> term(const StepRecord& r, const std::string& name) {
  for (const auto& [n, v] : r.losses)
    if (n == name) return v;
  return std::nullopt;
}

}  // namespace

// ---------------------------------------------------------------- CSV

CsvSink::CsvSink(RunFolder folder) : folder_(std::move(folder)) {}

void CsvSink::append(const std::string& path, const std::string& header, const std::string& row) {
  const bool fresh = !fs::exists(path);
  std::ofstream out(path, std::ios::app);
  if (fresh) out << header << "\n";
  out << row << "\n";
  if (!out) throw std::runtime_error("cannot append to " + path);
}

void CsvSink::trim_after(int64_t stage_index, int64_t iteration) {
  for (const std::string& path : {folder_.metrics_csv(), folder_.validation_csv()}) {
    if (!fs::exists(path)) continue;
    std::ifstream in(path);
    std::string line, kept;
    std::getline(in, line);
    kept = line + "\n";
    while (std::getline(in, line)) {
      std::istringstream ls(line);
      std::string stage_idx, name, it;
      std::getline(ls, stage_idx, ',');
      std::getline(ls, name, ',');
      std::getline(ls, it, ',');
      try {
        const int64_t si = std::stoll(stage_idx), ii = std::stoll(it);
        if (si < stage_index || (si == stage_index && ii <= iteration)) kept += line + "\n";
      } catch (const std::exception&) {
        throw std::runtime_error(path + ": malformed row '" + line + "' (expected stage_index,stage,iteration,...)");
      }
    }
    write_file_atomic(path, kept);
  }
}

void CsvSink::on_step(const StepRecord& r) {
  std::string header = "stage_index,stage,iteration,total";
  std::string row = fmt::format("{},{},{},{:.9g}", r.stage_index, r.stage, r.iteration, term(r, "total").value_or(0));
  for (const char* name : kTermColumns) {
    header += std::string(",") + name;
    const auto v = term(r, name);
    row += v ? fmt::format(",{:.9g}", *v) : ",";
  }
  header += ",lr";
  row += fmt::format(",{:.6g}", r.lr);
  append(folder_.metrics_csv(), header, row);
}

void CsvSink::on_validation(const ValidationRecord& r) {
  append(folder_.validation_csv(), "stage_index,stage,iteration,photometric,flow,score",
         fmt::format("{},{},{},{:.9g},{},{:.9g}", r.stage_index, r.stage, r.iteration, r.rigid,
                     r.flow ? fmt::format("{:.9g}", *r.flow) : "", r.score));
}

// ---------------------------------------------------------------- TensorBoard

TensorBoardSink::TensorBoardSink(const RunFolder& folder, int64_t resumed_at) : writer_(folder.tensorboard()) {
  if (resumed_at >= 0) writer_.add_session_start(resumed_at);
}

void TensorBoardSink::on_step(const StepRecord& r) {
  for (const auto& [name, value] : r.losses)
    writer_.add_scalar((name == "automasked" ? "train/" : "loss/") + name, r.global_step, value);
  writer_.add_scalar("lr", r.global_step, r.lr);
  writer_.add_scalar("grad_norm", r.global_step, r.grad_norm);
  static const char* camera_tags[] = {"camera/fx", "camera/fy", "camera/cx", "camera/cy"};
  for (size_t i = 0; i < r.camera.size() && i < 4; ++i) writer_.add_scalar(camera_tags[i], r.global_step, r.camera[i]);
  const auto now = std::chrono::steady_clock::now();
  if (last_ && r.global_step > last_->first) {
    const double secs = std::chrono::duration<double>(now - last_->second).count();
    if (secs > 0)
      writer_.add_scalar("iterations_per_s", r.global_step, static_cast<double>(r.global_step - last_->first) / secs);
  }
  last_ = std::make_pair(r.global_step, now);
}

void TensorBoardSink::on_validation(const ValidationRecord& r) {
  writer_.add_scalar("val/photometric", r.global_step, r.rigid);
  if (r.flow) writer_.add_scalar("val/flow", r.global_step, *r.flow);
  writer_.add_scalar("val/score", r.global_step, r.score);
  writer_.flush();
}

void TensorBoardSink::on_image(const ImageRecord& r) {
  writer_.add_image(r.stage + "/" + r.tag, r.global_step, r.png, r.height, r.width, r.channels);
}

// ---------------------------------------------------------------- summary images

SummaryPngSink::SummaryPngSink(RunFolder folder) : folder_(std::move(folder)) {
  fs::create_directories(folder_.summaries());
}

void SummaryPngSink::on_image(const ImageRecord& r) {
  write_file_atomic(folder_.summary(r.stage, r.iteration, r.tag), r.png);
}

// ---------------------------------------------------------------- console

// Auto-masking leaves out the pixels a still frame explains better than the camera's motion. When
// it leaves out most of them over two windows of steps in a row (50 steps each, or half the stage
// when shorter), the scene moves with the camera (traffic) or the camera hardly moves: said once per
// stage. One window is not enough: networks that start from random weights explain little at first
// on any footage. Measured (the real KITTI frames, ResNet-18 at 64x208, random weights, windows of
// 50): forward driving 62%, then 56%, 48%, 44%; stop-and-go traffic 76%, then 70%, 66%, 62%.
void ProgressSink::warn_if_mostly_masked(const StepRecord& r, double masked) {
  constexpr double kMostlyMasked = 0.6;
  if (!r.trains_depth) return;  // depth held (the trainer said so) or not trained: nothing to unlearn
  masked_sum_ += masked;
  const int64_t window = std::clamp<int64_t>(r.stage_iterations / 2, 1, 50);
  if (++masked_steps_ < window) return;
  const double mean = masked_sum_ / static_cast<double>(masked_steps_);
  if (mean >= kMostlyMasked && masked_before_ >= kMostlyMasked && !masked_warned_) {
    progress_->clear();
    spdlog::warn(
        "stage {}: {:.0f}% of the pixels were auto-masked over iterations {}-{} (a still frame explains them "
        "better than the predicted motion: traffic moving with the camera, a camera that hardly moves, or "
        "networks that are not learning): such footage is unlikely to teach depth. {}",
        r.stage, 100 * (mean + masked_before_) / 2, r.iteration - 2 * masked_steps_ + 1, r.iteration, kHardClipAdvice);
    masked_warned_ = true;
  }
  masked_before_ = mean;
  masked_sum_ = 0;
  masked_steps_ = 0;
}

void ProgressSink::on_step(const StepRecord& r) {
  if (!progress_ || r.stage != stage_) {
    stage_ = r.stage;
    progress_.emplace(r.stage, r.stage_iterations, interval_);
    masked_sum_ = 0;
    masked_steps_ = 0;
    masked_before_ = -1;
    masked_warned_ = false;
  }
  std::string details;
  std::string masked;
  for (const auto& [name, value] : r.losses)
    if (name == "automasked") {
      masked = fmt::format(" | {:.0f}% of pixels auto-masked", 100 * value);
      warn_if_mostly_masked(r, value);
    } else details += fmt::format("{}{} {:.4f}", details.empty() ? "" : " ", name, value);
  details += masked;
  if (r.skipped_steps) details += fmt::format(" ({} NaN/Inf steps skipped)", r.skipped_steps);
  if (r.camera.size() == 4)
    details += fmt::format(" | camera fx {:.1f} fy {:.1f} cx {:.1f} cy {:.1f}", r.camera[0], r.camera[1], r.camera[2],
                           r.camera[3]);
  progress_->update(r.iteration, details);
}

void ProgressSink::on_validation(const ValidationRecord& r) {
  if (progress_) progress_->clear();
  spdlog::info("validation at {} {}: photometric {:.5f}{}, score {:.5f} over {} snippets{}", r.stage, r.iteration,
               r.rigid, r.flow ? fmt::format(", flow {:.5f}", *r.flow) : "", r.score, r.snippets,
               r.best ? " (best so far)" : "");
}

}  // namespace geo
