// Where training reports go: MetricsSink receives every step, validation and summary image;
// CsvSink writes metrics.csv / val.csv, TensorBoardSink <run>/tb/events.out.tfevents.*,
// SummaryPngSink the summary images as summaries/*.png, and ProgressSink the console progress
// line (the run folder's paths: pipeline/run_folder.h). Library users add their own sinks
// (TrainOptions::sinks). LibTorch-free.
#pragma once

#include "core/progress.h"
#include "pipeline/run_folder.h"
#include "train/tensorboard.h"

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace geo {

struct StepRecord {
  int64_t stage_index = 0;
  std::string stage;
  int64_t iteration = 0;                               // iterations done in the stage after this step (1-based)
  int64_t stage_iterations = 0;                        // the stage's total
  int64_t global_step = 0;                             // iterations done over all stages (TensorBoard's step)
  std::vector<std::pair<std::string, double>> losses;  // defined terms and "total" (LossTerms::values)
  double lr = 0;
  double grad_norm = 0;
  int64_t skipped_steps = 0;   // NaN/Inf steps skipped so far in this process
  std::vector<double> camera;  // a learned camera (model.learn_intrinsics): fx, fy, cx, cy in training pixels
  bool trains_depth = true;    // the stage trains the DepthNet (not when it holds depth)
};

struct ValidationRecord {
  int64_t stage_index = 0;
  std::string stage;
  int64_t iteration = 0;
  int64_t global_step = 0;
  double rigid = 0;            // mean L_br
  std::optional<double> flow;  // mean L_fr, when the stage trains flow
  double score = 0;            // what selects best-<stage>.pt (validate.h)
  bool best = false;
  size_t snippets = 0;
};

struct ImageRecord {
  std::string stage;
  int64_t iteration = 0, global_step = 0;
  std::string tag;  // e.g. "disp"
  std::string png;  // PNG file bytes
  int height = 0, width = 0, channels = 3;
};

class MetricsSink {
 public:
  virtual ~MetricsSink() = default;
  virtual void on_step(const StepRecord&) {}
  virtual void on_validation(const ValidationRecord&) {}
  virtual void on_image(const ImageRecord&) {}
  virtual void flush() {}  // at checkpoints: what was reported so far reaches the disk
};

// metrics.csv: stage_index,stage,iteration,total,rigid,disp_smooth,flow,flow_smooth,flow_consistency,lr
// (terms a stage does not compute are empty). val.csv: stage_index,stage,iteration,photometric,flow,score.
class CsvSink : public MetricsSink {
 public:
  explicit CsvSink(RunFolder folder);
  // Resume: drops rows after (stage_index, iteration), which an interrupted process logged past
  // its last checkpoint.
  void trim_after(int64_t stage_index, int64_t iteration);
  void on_step(const StepRecord& r) override;
  void on_validation(const ValidationRecord& r) override;

 private:
  void append(const std::string& path, const std::string& header, const std::string& row);
  RunFolder folder_;
};

// Scalars "loss/<term>", "lr", "grad_norm", "camera/fx|fy|cx|cy" (a learned camera), "iterations_per_s", "val/photometric", "val/flow",
// "val/score", and the summary images "<stage>/<tag>", against the global step.
class TensorBoardSink : public MetricsSink {
 public:
  // Events go to the folder's tb/; `resumed_at` >= 0 first writes a SessionLog START at that global step.
  explicit TensorBoardSink(const RunFolder& folder, int64_t resumed_at = -1);
  void on_step(const StepRecord& r) override;
  void on_validation(const ValidationRecord& r) override;
  void on_image(const ImageRecord& r) override;
  void flush() override { writer_.flush(); }
  const std::string& path() const { return writer_.path(); }

 private:
  EventWriter writer_;
  std::optional<std::pair<int64_t, std::chrono::steady_clock::time_point>> last_;
};

// Each summary image as summaries/<stage>-<iteration>-<tag>.png (the PNG bytes it carries).
class SummaryPngSink : public MetricsSink {
 public:
  explicit SummaryPngSink(RunFolder folder);  // creates summaries/
  void on_image(const ImageRecord& r) override;

 private:
  RunFolder folder_;
};

// The console progress (core/progress.h): every `interval` iterations a log line (stage,
// iteration, rate, ETA, the losses); on a terminal also a line redrawn in place after every step.
class ProgressSink : public MetricsSink {
 public:
  explicit ProgressSink(int64_t interval) : interval_(interval) {}
  void on_step(const StepRecord& r) override;
  void on_validation(const ValidationRecord& r) override;

 private:
  int64_t interval_;
  std::string stage_;
  std::optional<Progress> progress_;  // of the current stage
  // The auto-masked share over the current window of steps and the window before it
  // (warn_if_mostly_masked; negative: none yet).
  double masked_sum_ = 0;
  int64_t masked_steps_ = 0;
  double masked_before_ = -1;
  bool masked_warned_ = false;  // in this stage
  void warn_if_mostly_masked(const StepRecord& r, double masked);
};

}  // namespace geo
