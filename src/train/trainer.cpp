#include "train/trainer.h"

#include "core/files.h"
#include "core/logging.h"
#include "core/runtime.h"
#include "core/state_io.h"
#ifdef GEO_WITH_OPENCV
#include "data/image_io.h"
#endif
#include "data/loader.h"
#include "data/text_io.h"
#include "data/training_data.h"
#include "train/distributed.h"
#include "train/compute_losses.h"
#include "train/train_step.h"
#include "train/validate.h"

#include <spdlog/spdlog.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <functional>
#include <optional>

namespace fs = std::filesystem;

namespace geo {
namespace {

std::atomic<int> g_signal{0};

// SIGINT/SIGTERM set a flag the loop polls; the previous handlers return when the scope ends.
class SignalScope {
 public:
  SignalScope() {
    g_signal = 0;
    prev_int_ = std::signal(SIGINT, [](int s) { g_signal = s; });
    prev_term_ = std::signal(SIGTERM, [](int s) { g_signal = s; });
  }
  ~SignalScope() {
    std::signal(SIGINT, prev_int_);
    std::signal(SIGTERM, prev_term_);
  }
  int received() const { return g_signal; }

 private:
  void (*prev_int_)(int) = SIG_DFL;
  void (*prev_term_)(int) = SIG_DFL;
};

class Run {
 public:
  // `group`: this process's group (a SingleProcess alone). Only rank 0 writes to the run folder
  // (checkpoints, logs, summaries) and validates.
  Run(Config config, RunFolder folder, const TrainOptions& options, bool resuming, ProcessGroup& group)
      : cfg_(std::move(config)), folder_(std::move(folder)), opts_(options), group_(group), writer_(group.rank() == 0),
        device_(process_device(options.device.empty() ? cfg_.run.device : options.device, group)),
        checkpoints_(folder_, cfg_.logging.keep_last, !writer_) {
    apply_run_settings(cfg_.run, device_);
    data_ = open_training_data(cfg_.data);
    if (writer_) keep_or_check_clips(resuming);
    bool with_flow = false;
    for (const auto& s : cfg_.stages) with_flow = with_flow || s.uses_flow();
    nets_ = Networks::create(NetworkSpec::of(cfg_), with_flow);
    nets_.to(device_);
    // One process has nothing to average or synchronise: it keeps PyTorch's own kernels.
    if (several()) averager_ = std::make_unique<GradientAverager>(group_);
    if (several() && cfg_.run.distributed.sync_batchnorm) {
      const int layers = synchronise_batchnorm(group_, nets_);
      if (writer_)
        spdlog::info("BatchNorm synchronised across the {} processes ({} layers: 2 all-reduces each per step)",
                     group_.size(), layers);
    }
    if (resuming) restore();
    else init_networks(stage());  // here, so that a bad --init stops the run before it starts
    if (writer_) {
      auto csv = std::make_shared<CsvSink>(folder_);
      if (resuming) csv->trim_after(state_.stage, state_.iteration);
      sinks_ = {csv, std::make_shared<TensorBoardSink>(folder_, resuming ? global_step() : -1),
                std::make_shared<SummaryPngSink>(folder_), std::make_shared<ProgressSink>(cfg_.logging.interval)};
    }
    sinks_.insert(sinks_.end(), opts_.sinks.begin(), opts_.sinks.end());
  }

  int run() {
    SignalScope signals;
    report_start();
    for (; state_.stage < static_cast<int64_t>(cfg_.stages.size()); next_stage()) {
      const int rc = run_stage(signals);
      if (rc != 0) return rc;
    }
    spdlog::info("training finished; checkpoints in {}", checkpoints_.dir());
    return 0;
  }

 private:
  // What this run is about to do, and the settings that will hurt it.
  void report_start() const {
    spdlog::info(
        "run folder {}; device {} ({}); {} threads; data {} in {} ({} training snippets{}{}, {} validation); "
        "TensorBoard: tensorboard --logdir {}",
        folder_.root(), device_.str(), name_of(cfg_.run.precision), torch::get_num_threads(), data_.format, data_.root,
        data_.train->size(),
        data_.excluded ? ", " + std::to_string(data_.excluded) + " excluded by " + join_list(data_.exclusions, ", ")
                       : "",
        data_.dropped ? ", " + std::to_string(data_.dropped) + " without neighbours" : "",
        data_.val ? data_.val->size() : 0, fs::path(folder_.root()).parent_path().string());
    if (!data_.val && cfg_.logging.val_interval > 0)
      spdlog::warn(
          "no validation data ({}): nothing is validated, no best-<stage>.pt is kept, and a run folder "
          "resolves to its latest checkpoint",
          data_.format == "packed" ? "the cache has no val/" : "no validation list found");
    int64_t total = 0;
    for (const auto& s : cfg_.stages) total += s.iterations;
    // The advice (0.1) only where it helps: a run too short even for 0.1 gets the count it needs.
    if (static_cast<double>(total) * cfg_.model.bn_momentum < 5.0)
      spdlog::warn(
          "model.bn_momentum {} averages BatchNorm's running statistics over ~{:.0f} batches but this run "
          "has {} iterations: evaluation will see statistics close to their initial values ({})",
          cfg_.model.bn_momentum, 1.0 / cfg_.model.bn_momentum, total,
          cfg_.model.bn_momentum < 0.1 && total * 0.1 >= 5.0
              ? "use model.bn_momentum: 0.1 for short runs"
              : "train for at least " + std::to_string(static_cast<int64_t>(std::ceil(5.0 / cfg_.model.bn_momentum))) +
                    " iterations");
    if (several())
      spdlog::info(
          "distributed: {} processes ({}), this is rank {} on {}; batch_size is per process ({} in all); "
          "{}",
          group_.size(), group_.backend(), group_.rank(), device_.str(), stage().batch_size * group_.size(),
          cfg_.run.distributed.shard_data ? "each reads its own shard of the data stream"
                                          : "all read the same batches (run.distributed.shard_data false)");
  }

  // data.videos: what each clip gave (frames kept, a digest) is kept with the run (clips.txt); a
  // resumed run refuses a clip that changed since, before anything is written: its snippets would
  // not be those the run trained on (nor its validation blocks).
  void keep_or_check_clips(bool resuming) const {
    const auto& now = data_.clip_records;
    const std::string file = folder_.clips();
    if (!resuming) {
      if (!now.empty()) write_file_atomic(file, join_list(now, "\n") + "\n");
      return;
    }
    if (!fs::exists(file)) return;  // a run on other data
    const auto then = read_lines(file);
    for (size_t i = 0; i < std::max(then.size(), now.size()); ++i) {
      const std::string was = i < then.size() ? then[i] : "(none)", is = i < now.size() ? now[i] : "(none)";
      if (was == is) continue;
      throw std::runtime_error("--resume " + folder_.root() + ": a clip changed since the run started: then " + was +
                               "; now " + is + " (" + file +
                               "). Resuming on other frames would train on snippets "
                               "the run never had: restore the clip, or start a new run from this one's weights "
                               "(geo_train --init " +
                               folder_.root() + ")");
    }
  }

  // The current stage as it trains: held (StageConfig::held_depth) when it holds depth.
  const StageConfig& stage() const { return held_ ? *held_ : cfg_.stages[state_.stage]; }

  // Sets state_.depth_held and what follows from it, the held stage (held_): the one place either changes.
  void hold_depth(bool held) {
    state_.depth_held = held;
    held_.reset();
    if (held) held_ = cfg_.stages[state_.stage].held_depth();
  }

  // The stage starts from trained weights: an earlier stage's, or init / --init.
  bool starts_trained(const StageConfig& s) const { return state_.stage > 0 || !opts_.init.empty() || !s.init.empty(); }

  // StageConfig::hold_masked, before a fresh stage's first step: the weights it starts from, on up
  // to kHoldProbeSnippets training snippets spread over the data (networks in eval mode, no
  // augmentation), leave this share of the pixels auto-masked. Every process measures the same
  // snippets with the same weights; any that holds makes all hold.
  void decide_hold() {
    const StageConfig& s = cfg_.stages[state_.stage];
    if (s.hold_masked <= 0 || !s.trains(Net::kDepth) || !starts_trained(s)) return;
    if (!s.train.pose && !s.train.flow) {
      if (writer_)
        spdlog::warn(
            "stage {}: hold_masked {} is unused: the stage trains only depth, so holding it would train nothing",
            s.name, s.hold_masked);
      return;
    }
    const auto probe = spread_snippets(data_.train, kHoldProbeSnippets);
    const Validation v = geo::validate(nets_, probe, s, cfg_, device_);
    const double masked = v.automasked.value_or(0);
    const bool hold = agreed_signal(group_, masked >= s.hold_masked ? 1 : 0, device_) != 0;
    hold_depth(hold);
    if (!writer_) return;
    const std::string measured = fmt::format(
        "stage {}: the weights it starts from leave {:.0f}% of the pixels of {} training snippets auto-masked (a "
        "still frame explains them better than the predicted motion)",
        s.name, 100 * masked, probe->size());
    if (hold)
      spdlog::warn(
          "{}, at least stages[{}].hold_masked {}: the clip is unlikely to teach depth (traffic moving with the "
          "camera, a camera that hardly moves), and fine-tuning depth on such footage unlearns. Depth is held: the "
          "DepthNet stays as it starts (its BatchNorm statistics too) and the stage trains [{}]. To train depth all "
          "the same: --set stages.{}.hold_masked=0 (docs/video.md)",
          measured, state_.stage, s.hold_masked, join_list(held_->train.names(), ", "), state_.stage);
    else spdlog::info("{}, below stages[{}].hold_masked {}: depth trains", measured, state_.stage, s.hold_masked);
  }
  bool several() const { return group_.size() > 1; }

  int64_t global_step() const {
    int64_t g = state_.iteration;
    for (int64_t i = 0; i < state_.stage; ++i) g += cfg_.stages[i].iterations;
    return g;
  }

  void next_stage() {
    ++state_.stage;
    state_.iteration = 0;
    state_.best_score = std::numeric_limits<double>::infinity();  // best is per stage
    hold_depth(false);
    resume_from_.clear();
    if (state_.stage < static_cast<int64_t>(cfg_.stages.size())) init_networks(stage());
  }

  // Resume: networks and train state from the latest checkpoint (Adam's state when its stage starts).
  void restore() {
    resume_from_ = checkpoints_.latest();
    if (resume_from_.empty())
      throw std::runtime_error(folder_.root() + ": no checkpoint to resume from (checkpoints/latest missing)");
    checkpoints_.check_resumable(resume_from_);
    CheckpointFile file(resume_from_);
    file.load_networks(nets_, false);
    state_ = file.train_state();
    init_configs_ = file.init_configs();
    if (state_.stage < static_cast<int64_t>(cfg_.stages.size())) hold_depth(state_.depth_held);
    const int64_t was = state_.world_size;
    const int64_t now = group_.size();
    if (was != now && writer_)
      spdlog::warn(
          "{} was written by a run of {} process(es), this one has {}: training continues from it with the "
          "data stream re-sharded for {} (the samples after this point differ from an uninterrupted run's)",
          resume_from_, was, now, now);
    if (state_.stage >= static_cast<int64_t>(cfg_.stages.size()))
      throw std::runtime_error(resume_from_ + ": stage index " + std::to_string(state_.stage) +
                               " beyond the config's stages");
    spdlog::info("resumed from {} (stage {}, iteration {})", resume_from_, stage().name, state_.iteration);
  }

  void init_networks(const StageConfig& s) {
    const std::string spec = state_.stage == 0 && !opts_.init.empty() ? opts_.init : s.init;
    if (spec.empty()) return;
    const std::string path = resolve_checkpoint(spec);
    CheckpointFile file(path);
    // One line saying which setting differs, before the key-by-key comparison of the weights.
    if (file.config() || file.is_model_file()) {
      const std::string diff = architecture_difference(file.spec(), nets_.spec);
      if (!diff.empty())
        throw std::runtime_error(path + ": its networks were trained with " + diff +
                                 "; set those keys to match or initialise from another checkpoint");
    }
    file.load_networks(nets_, true);
    // What those weights were trained on travels with every checkpoint of this run (geo_eval's
    // training-drive check), nearest first, after what earlier stages' inits brought.
    const auto inherited = file.lineage();
    init_configs_.insert(init_configs_.begin(), inherited.begin(), inherited.end());
    spdlog::info("stage {}: networks initialised from {}", s.name, path);
  }

  // stages[].weights.anchor: the DepthNet the stage starts from, frozen (losses/depth_anchor.h).
  // A fresh stage copies it and keeps the copy in the run folder (anchor-<stage>.pt) for a resumed
  // run to read; a first stage without init or --init starts from random weights: nothing to hold.
  DepthNet anchor_teacher(const StageConfig& s) {
    if (s.weights.anchor <= 0) return nullptr;
    const std::string path = folder_.anchor(s.name);
    const bool fresh = resume_from_.empty();
    if (fresh && !starts_trained(s)) {
      if (writer_)
        spdlog::warn(
            "stage {}: weights.anchor {} is unused: the stage starts from random weights, so there is no depth to "
            "hold to (give --init or stages[0].init to fine-tune a trained model)",
            s.name, s.weights.anchor);
      return nullptr;
    }
    if (fresh) {
      DepthNet teacher = nets_.frozen_depth_copy();
      if (writer_) {
        save_state(*teacher, path);
        spdlog::info("stage {}: depth held to the weights it starts from (weights.anchor {}, kept in {})", s.name,
                     s.weights.anchor, path);
      }
      return teacher;
    }
    if (!fs::exists(path)) {  // the stage began without trained weights (said then)
      if (writer_)
        spdlog::warn("stage {}: weights.anchor {} is unused: {} does not exist", s.name, s.weights.anchor, path);
      return nullptr;
    }
    DepthNet teacher = nets_.frozen_depth_copy();
    load_state(*teacher, path);
    return teacher;
  }

  int run_stage(const SignalScope& signals) {
    broadcast_networks(group_, nets_);  // every process starts the stage from rank 0's weights
    if (resume_from_.empty() && state_.iteration == 0) decide_hold();
    const auto& s = stage();
    TrainStep step(nets_, cfg_, s);
    step.set_gradient_averager(averager_.get(), cfg_.run.distributed.overlap);
    step.set_anchor(anchor_teacher(s));
    if (!resume_from_.empty()) CheckpointFile(resume_from_).load_optimizer(step.optimizer());
    const LrSchedule lr = LrSchedule::of(s);
    LoaderOptions lo = loader_options(cfg_.data, s.batch_size);
    lo.seed = static_cast<uint64_t>(cfg_.run.seed) * 131 + static_cast<uint64_t>(state_.stage);
    lo.pin_memory = device_.is_cuda();  // page-locked batches, copied to the GPU without blocking
    if (cfg_.run.distributed.shard_data) {
      lo.rank = group_.rank();
      lo.world_size = group_.size();
    }
    BatchLoader loader(data_.train, lo, state_.iteration);
    spdlog::info("stage {} ({}/{}): training [{}] for {} iterations from {}, batch {}, lr {}", s.name, state_.stage + 1,
                 cfg_.stages.size(), join_list(s.train.names(), ", "), s.iterations, state_.iteration, s.batch_size,
                 s.learning_rate);
    const auto& log = cfg_.logging;
    int bad_in_row = 0;
    // A validation interrupted by a signal before the checkpoint being resumed: done now, on the
    // very weights it was due for, so val.csv and best-<stage>.pt are those of an uninterrupted run.
    if (state_.validation_pending) {
      spdlog::info("validation at {} {} was interrupted: done now", s.name, state_.iteration);
      const bool best = writer_ && data_.val && validate(signals);
      if (writer_ && best) save(step, true);
      if (state_.validation_pending && !several()) {  // interrupted again: stop where it stands
        save(step, false);
        return 130;
      }
      state_.validation_pending = false;
    }
    while (state_.iteration < s.iterations) {
      const Batch batch = loader.next();
      const bool async = device_.is_cuda();  // the batch stays alive until the step has read it
      StepResult r = step.run(batch.tgt.to(device_, async), batch.srcs.to(device_, async), batch.K.to(device_, async),
                              lr.at(state_.iteration));
      if (!r.finite) {
        ++skipped_;
        spdlog::warn("stage {} iteration {}: NaN/Inf loss or gradient, step skipped ({} in a row, {} in all)", s.name,
                     state_.iteration + 1, ++bad_in_row, skipped_);
        if (bad_in_row >= log.max_bad_steps)
          throw std::runtime_error(
              "stopping: " + std::to_string(bad_in_row) + " NaN/Inf steps in a row (logging.max_bad_steps) at stage " +
              s.name + " iteration " + std::to_string(state_.iteration + 1) +
              (checkpoints_.latest().empty() ? "; no checkpoint was written before it"
                                             : "; the last good checkpoint is untouched: " + checkpoints_.latest()) +
              " (try a lower learning rate or optimizer.grad_clip)");
        continue;  // the same iteration again with the next batch
      }
      bad_in_row = 0;
      ++state_.iteration;
      report_step(r, lr.at(state_.iteration - 1));
      const auto due = [&](int64_t every) {
        return every > 0 && (state_.iteration % every == 0 || state_.iteration == s.iterations);
      };
      if (writer_ && due(log.summary_interval)) write_summaries(batch, r.out);
      // A new best is checkpointed at once: best-<stage>.pt holds exactly the weights that earned the score.
      const bool new_best = writer_ && due(log.val_interval) && data_.val && validate(signals);
      const auto& dist = cfg_.run.distributed;
      if (dist.verify_interval > 0 && state_.iteration % dist.verify_interval == 0)
        verify_same_weights(group_, nets_.trainable_parameters(), global_step());
      const int signal = agreed_signal(group_, signals.received(), device_);
      const bool checkpoint = due(log.checkpoint_interval);
      if (writer_ && (checkpoint || signal || new_best)) save(step, new_best);
      if (signal) {
        spdlog::warn(
            "signal {} received: checkpoint written at stage {} iteration {}; continue with "
            "geo_train --resume {}",
            signal, s.name, state_.iteration, folder_.root());
        return 130;
      }
    }
    return 0;
  }

  void report_step(const StepResult& r, double lr) {
    StepRecord rec;
    rec.stage_index = state_.stage;
    rec.stage = stage().name;
    rec.iteration = state_.iteration;
    rec.stage_iterations = stage().iterations;
    rec.global_step = global_step();
    rec.losses = r.losses;
    rec.lr = lr;
    rec.grad_norm = r.grad_norm;
    rec.skipped_steps = skipped_;
    rec.camera = r.camera;
    rec.trains_depth = stage().trains(Net::kDepth);
    for (auto& sink : sinks_) sink->on_step(rec);
  }

  // Validates the stage; true when the score is the stage's best so far. A signal ends the pass
  // early, unrecorded (the checkpoint that follows matters more than the score).
  bool validate(const SignalScope& signals) {
    const Validation v =
        geo::validate(nets_, data_.val, stage(), cfg_, device_, [&] { return signals.received() != 0; });
    if (v.interrupted) {
      spdlog::warn("validation at {} {} interrupted by signal {}: not recorded; a resumed run validates first",
                   stage().name, state_.iteration, signals.received());
      state_.validation_pending = true;  // written by the checkpoint that follows
      return false;
    }
    state_.validation_pending = false;
    ValidationRecord rec;
    rec.stage_index = state_.stage;
    rec.stage = stage().name;
    rec.iteration = state_.iteration;
    rec.global_step = global_step();
    rec.rigid = v.rigid;
    rec.flow = v.flow;
    rec.score = v.score;
    rec.snippets = v.snippets;
    rec.best = v.score < state_.best_score;
    if (rec.best) state_.best_score = v.score;
    for (auto& sink : sinks_) sink->on_validation(rec);
    return rec.best;
  }

  void save(TrainStep& step, bool best) {
    for (auto& sink : sinks_) sink->flush();
    const std::string path =
        checkpoints_.save(stage().name, state_.iteration, best, [&](torch::serialize::OutputArchive& a) {
          TrainState state = state_;
          state.world_size = group_.size();
          write_checkpoint(a, CheckpointContents{nets_, &step.optimizer(), state, cfg_, init_configs_});
        });
    spdlog::info("checkpoint {}{}", path, best ? " (best of stage " + stage().name + ")" : "");
  }

  // Summary images of the first sample, to the sinks (summaries/*.png, TensorBoard): target,
  // disparity, source warped by the rigid flow, and in flow stages the full flow and the forward
  // visibility mask of eq. 13. A build without OpenCV makes no images (said once).
  void write_summaries(const Batch& batch, const StepOutput& out) {
#ifdef GEO_WITH_OPENCV
    torch::NoGradGuard no_grad;
    std::vector<std::pair<std::string, torch::Tensor>> images = {
        {"target", batch.tgt[0]},
        {"disp", colorize_disparity(out.tgt_disp[0][0].cpu())},
        {"warped", from_loss_range(out.rigid.fwd_warp[0][0][0].cpu(), cfg_.loss)}};
    if (out.flow) {
      images.emplace_back("flow", colorize_flow(out.fwd_full[0][0][0].cpu()));
      images.emplace_back("visible", out.flow->fwd_visible[0][0][0].cpu().expand({3, -1, -1}));
    }
    for (const auto& [tag, image] : images) {
      ImageRecord rec{stage().name,
                      state_.iteration,
                      global_step(),
                      tag,
                      encode_png(image),
                      static_cast<int>(image.size(1)),
                      static_cast<int>(image.size(2)),
                      3};
      for (auto& sink : sinks_) sink->on_image(rec);
    }
#else
    if (!summaries_skipped_)
      spdlog::info("image summaries (logging.summary_interval) are skipped: this geo was built without OpenCV");
    summaries_skipped_ = true;
#endif
  }

  Config cfg_;
  RunFolder folder_;
  TrainOptions opts_;
  ProcessGroup& group_;
  bool writer_;
  std::unique_ptr<GradientAverager> averager_;
  torch::Device device_;
  CheckpointManager checkpoints_;
  TrainingData data_;
  Networks nets_;
  std::vector<std::shared_ptr<MetricsSink>> sinks_;
  TrainState state_;
  std::optional<StageConfig> held_;        // the current stage holding depth (state_.depth_held)
  std::string resume_from_;                // the checkpoint the current stage resumes from ("" = a fresh stage)
  std::vector<std::string> init_configs_;  // CheckpointContents::init_configs of this run
  int64_t skipped_ = 0;
#ifndef GEO_WITH_OPENCV
  bool summaries_skipped_ = false;  // said once: image summaries need OpenCV
#endif
};

// This process's group (a SingleProcess alone), its ranks checked to train one configuration.
std::unique_ptr<ProcessGroup> join_group(const Config& config, const TrainOptions& options) {
  const std::string device = options.device.empty() ? config.run.device : options.device;
  auto group = join_launched_group(config.run.distributed, device, options.master_addr);
  if (group->size() > 1) check_same_config(*group, to_yaml(config), process_device(device, *group));
  return group;
}

// A run folder rank 0 made ready for the run, held (locked) while it trains.
struct PreparedFolder {
  RunFolder folder;
  std::unique_ptr<FolderLock> lock;  // one writer per run folder
  bool created = false;              // made for this run: removed again when the run cannot start
};

// What train() and resume() share: rank 0 prepares the run folder (`prepare`) and shares its path,
// or why it could not, with the other ranks, which train in it without writing to it; then every
// process runs.
int run_in_folder(const Config& config, const TrainOptions& options, bool resuming,
                  const std::function<PreparedFolder()>& prepare, std::string* run_dir) {
  keep_freed_memory();  // every step allocates what the step before freed (core/runtime.h)
  auto group = join_group(config, options);
  if (group->rank() != 0) {
    const std::string dir = group->share_from_rank0("run_dir", "");
    if (run_dir) *run_dir = dir;
    const auto& level = config.logging.level;  // rank 0 speaks for the run; the others warn
    setup_logging(level == "info" || level == "debug" || level == "trace" ? "warn" : level);
    Run run(config, RunFolder(dir), options, resuming, *group);
    return run.run();
  }
  std::optional<PreparedFolder> prepared;
  try {
    prepared.emplace(prepare());
  } catch (const std::exception& e) {
    group->share_from_rank0("run_dir", e.what(), true);
    throw;
  }
  const RunFolder& folder = prepared->folder;
  group->share_from_rank0("run_dir", folder.root());
  if (run_dir) *run_dir = folder.root();
  setup_logging(config.logging.level, folder.log());
  std::unique_ptr<Run> run;
  try {
    run = std::make_unique<Run>(config, folder, options, resuming, *group);
  } catch (...) {
    // A run that could not start (bad data root, ...) leaves no half-made folder behind.
    if (prepared->created) {
      setup_logging(config.logging.level);  // release train.log
      remove_tree(folder.root());
    }
    throw;
  }
  return run->run();
}

}  // namespace

int train(const Config& config, const TrainOptions& options, std::string* run_dir) {
  return run_in_folder(
      config, options, false,
      [&] {
        const bool created = options.run_dir.empty() || !fs::exists(options.run_dir);
        PreparedFolder p{options.run_dir.empty() ? RunFolder::create_new(config.run.dir, config.run.name)
                                                 : RunFolder(options.run_dir),
                         nullptr, created};
        const std::string& dir = p.folder.root();
        // A folder the run reads (a clip's frames, the data root, an init run) is not where it writes.
        check_outputs({{"--run-dir", dir}, {"--run-dir", p.folder.config()}}, config_reads(config), true);
        // The lock first: a folder where a run is training right now is said to be in use, never
        // called a stopped run to be removed.
        fs::create_directories(dir);
        p.lock = std::make_unique<FolderLock>(dir);
        if (!p.folder.latest().empty())
          throw std::runtime_error("run folder '" + dir + "' already holds a run; use --resume " + dir +
                                   " or another --run-dir");
        // A run that stopped before its first checkpoint cannot be resumed, and a new one would append
        // to its logs: refused, so that two runs never mix in one folder.
        const auto earlier = p.folder.run_files();
        if (!earlier.empty())
          throw std::runtime_error(
              "run folder '" + dir + "' holds the files of an earlier run (" + join_list(earlier, ", ") +
              ") that stopped before its first checkpoint: remove the folder or use another --run-dir");
        write_file_atomic(p.folder.config(), to_yaml(config));
        return p;
      },
      run_dir);
}

int resume(const std::string& run_dir, const TrainOptions& options) {
  const RunFolder folder(run_dir);
  if (!fs::exists(folder.config()))
    throw std::runtime_error("--resume '" + run_dir + "': not a run folder (no config.yaml)");
  return run_in_folder(
      load_config(folder.config()), options, true,
      [&] {
        return PreparedFolder{folder, std::make_unique<FolderLock>(run_dir), false};
      },
      nullptr);
}

}  // namespace geo
