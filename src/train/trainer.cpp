#include "train/trainer.h"

#include "core/logging.h"
#include "data/image_io.h"
#include "data/loader.h"
#include "train/data_source.h"
#include "train/networks.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;

namespace geo {
namespace {

std::atomic<int> g_signal{0};
void on_signal(int sig) { g_signal = sig; }

const char* kColumns[] = {"rigid", "disp_smooth", "flow", "flow_smooth", "flow_consistency"};

std::string checkpoint_name(const std::string& stage, int64_t iteration) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%s-%08lld.pt", stage.c_str(), static_cast<long long>(iteration));
  return buf;
}

torch::Device pick_device(const std::string& name) {
  if (name == "cpu") return torch::kCPU;
  if (torch::cuda::is_available()) return torch::kCUDA;
  if (name == "cuda") spdlog::warn("device cuda requested but CUDA is not available: using the CPU");
  return torch::kCPU;
}

std::string read_first_line(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line;
}

class Trainer {
 public:
  Trainer(Config config, std::string run_dir, const TrainOptions& options)
      : cfg_(std::move(config)), dir_(std::move(run_dir)), opts_(options),
        device_(pick_device(options.device.empty() ? cfg_.run.device : options.device)) {
    torch::set_num_threads(cfg_.run.threads > 0 ? cfg_.run.threads
                                                : static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
    torch::manual_seed(static_cast<uint64_t>(cfg_.run.seed));
    data_ = open_training_data(cfg_.data);
    bool with_flow = false;
    for (const auto& s : cfg_.stages) with_flow = with_flow || s.uses_flow();
    nets_ = Networks::create(cfg_, with_flow);
    nets_.to(device_);
    fs::create_directories(dir_ + "/checkpoints");
    fs::create_directories(dir_ + "/summaries");
  }

  // Loads the latest checkpoint of the run folder (resume).
  void restore() {
    const std::string latest = read_first_line(dir_ + "/checkpoints/latest");
    if (latest.empty())
      throw std::runtime_error(dir_ + ": no checkpoint to resume from (checkpoints/latest missing)");
    const std::string path = dir_ + "/checkpoints/" + latest;
    torch::serialize::InputArchive a;
    a.load_from(path);
    nets_.load(a, path, false);
    torch::Tensor meta;
    a.read("meta", meta);
    stage_ = meta[0].item<int64_t>();
    iter_ = meta[1].item<int64_t>();
    best_val_ = meta[2].item<double>();
    if (stage_ >= static_cast<int64_t>(cfg_.stages.size()))
      throw std::runtime_error(path + ": stage index " + std::to_string(stage_) + " beyond the config's stages");
    make_optimizer();
    torch::serialize::InputArchive opt;
    if (a.try_read("optimizer", opt)) optimizer_->load(opt);
    restored_ = true;
    std::vector<std::pair<fs::file_time_type, std::string>> found;
    for (const auto& e : fs::directory_iterator(dir_ + "/checkpoints"))
      if (e.path().extension() == ".pt" && e.path().filename() != "best.pt")
        found.emplace_back(e.last_write_time(), e.path().filename().string());
    std::sort(found.begin(), found.end());
    for (const auto& f : found) kept_.push_back(f.second);
    trim_csv("metrics.csv");
    trim_csv("val.csv");
    spdlog::info("resumed from {} (stage {}, iteration {})", path, cfg_.stages[stage_].name, iter_);
  }

  int run() {
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    spdlog::info("run folder {}; device {}; {} threads; data {} ({} training snippets{}{}, {} validation)",
                 dir_, device_.str(), torch::get_num_threads(), data_.format, data_.train->size(),
                 data_.excluded ? ", " + std::to_string(data_.excluded) + " excluded" : "",
                 data_.dropped ? ", " + std::to_string(data_.dropped) + " without neighbours" : "",
                 data_.val ? data_.val->size() : 0);
    for (; stage_ < static_cast<int64_t>(cfg_.stages.size()); ++stage_) {
      const int rc = run_stage();
      if (rc != 0) return rc;
      iter_ = 0;
      restored_ = false;
    }
    spdlog::info("training finished; checkpoints in {}/checkpoints", dir_);
    return 0;
  }

 private:
  const StageConfig& stage() const { return cfg_.stages[stage_]; }

  void make_optimizer() {
    const auto& o = cfg_.optimizer;
    optimizer_ = std::make_unique<torch::optim::Adam>(
        nets_.parameters_of(stage()), torch::optim::AdamOptions(stage().learning_rate)
                                          .betas({o.beta1, o.beta2})
                                          .eps(o.eps)
                                          .weight_decay(o.weight_decay));
  }

  double learning_rate() const {
    const auto& s = stage();
    if (s.lr_schedule == "step" && s.lr_step > 0)
      return s.learning_rate * std::pow(s.lr_gamma, static_cast<double>(iter_ / s.lr_step));
    return s.learning_rate;
  }

  void init_from(const std::string& spec) {
    const std::string path = resolve_checkpoint(spec);
    torch::serialize::InputArchive a;
    a.load_from(path);
    nets_.load(a, path, true);
    spdlog::info("stage {}: networks initialised from {}", stage().name, path);
  }

  int run_stage() {
    const auto& s = stage();
    if (!restored_) {
      const std::string init = stage_ == 0 && !opts_.init.empty() ? opts_.init : s.init;
      if (!init.empty()) init_from(init);
      make_optimizer();
    }
    nets_.set_modes(s);
    LoaderOptions lo;
    lo.batch_size = s.batch_size;
    lo.seed = static_cast<uint64_t>(cfg_.run.seed) * 131 + static_cast<uint64_t>(stage_);
    lo.workers = cfg_.data.num_workers;
    lo.skip_bad = cfg_.data.on_bad_sample == "skip";
    lo.augment = cfg_.data.augment;
    BatchLoader loader(data_.train, lo, iter_);
    spdlog::info("stage {} ({}/{}): training [{}] for {} iterations from {}, batch {}, lr {}", s.name,
                 stage_ + 1, cfg_.stages.size(), fmt::join(s.train, ", "), s.iterations, iter_,
                 s.batch_size, s.learning_rate);
    auto t_last = std::chrono::steady_clock::now();
    int64_t last_logged = iter_;
    int bad_in_row = 0;
    while (iter_ < s.iterations) {
      if (opts_.stop_after >= 0 && steps_ >= opts_.stop_after) {
        spdlog::warn("stopping after {} steps without a checkpoint (--stop-after)", steps_);
        return 137;
      }
      Batch batch = loader.next();
      for (auto& pg : optimizer_->param_groups())
        static_cast<torch::optim::AdamOptions&>(pg.options()).lr(learning_rate());
      optimizer_->zero_grad();
      StepOutput out = compute_losses(nets_, batch.tgt.to(device_), batch.srcs.to(device_),
                                      batch.K.to(device_), s, cfg_);
      bool finite = std::isfinite(out.losses.total.item<double>());
      if (finite) {
        out.losses.total.backward();
        double norm = 0;
        auto params = nets_.parameters_of(s);
        if (cfg_.optimizer.grad_clip > 0) {
          norm = torch::nn::utils::clip_grad_norm_(params, cfg_.optimizer.grad_clip);
        } else {
          for (auto& p : params)
            if (p.grad().defined()) norm += p.grad().pow(2).sum().item<double>();
        }
        finite = std::isfinite(norm);
      }
      ++steps_;
      if (!finite) {
        optimizer_->zero_grad();
        ++bad_in_row;
        ++bad_total_;
        spdlog::warn("stage {} iteration {}: NaN/Inf loss or gradient, step skipped ({} in a row, {} in all)",
                     s.name, iter_ + 1, bad_in_row, bad_total_);
        if (bad_in_row >= cfg_.logging.max_bad_steps)
          throw std::runtime_error("stopping: " + std::to_string(bad_in_row) +
                                   " NaN/Inf steps in a row (logging.max_bad_steps) at stage " + s.name +
                                   " iteration " + std::to_string(iter_ + 1) +
                                   "; the last good checkpoint is untouched: " + dir_ + "/checkpoints/" +
                                   read_first_line(dir_ + "/checkpoints/latest") +
                                   " (try a lower learning rate or optimizer.grad_clip)");
        continue;  // the same iteration again with the next batch
      }
      bad_in_row = 0;
      optimizer_->step();
      ++iter_;
      append_metrics(out.losses);
      const bool last = iter_ == s.iterations;
      if (iter_ % cfg_.logging.interval == 0 || last) {
        const auto now = std::chrono::steady_clock::now();
        const double secs = std::chrono::duration<double>(now - t_last).count();
        const double ips = static_cast<double>(iter_ - last_logged) / std::max(secs, 1e-9);
        std::string terms;
        for (const auto& [name, value] : out.losses.values()) terms += fmt::format(" {} {:.4f}", name, value);
        spdlog::info("{} {}/{}{} | {:.2f} it/s, ETA {:.0f} s", s.name, iter_, s.iterations, terms, ips,
                     static_cast<double>(s.iterations - iter_) / std::max(ips, 1e-9));
        t_last = now;
        last_logged = iter_;
      }
      if (cfg_.logging.summary_interval > 0 && (iter_ % cfg_.logging.summary_interval == 0 || last))
        write_summaries(batch, out);
      if (cfg_.logging.val_interval > 0 && (iter_ % cfg_.logging.val_interval == 0 || last)) validate();
      if (iter_ % cfg_.logging.checkpoint_interval == 0 || last) save_checkpoint();
      if (g_signal != 0) {
        if (!(iter_ % cfg_.logging.checkpoint_interval == 0 || last)) save_checkpoint();
        spdlog::warn("signal {} received: checkpoint written at stage {} iteration {}; continue with "
                     "geo_train --resume {}", static_cast<int>(g_signal), s.name, iter_, dir_);
        return 130;
      }
    }
    return 0;
  }

  void append_row(const std::string& file, const std::string& header, const std::string& row) {
    const std::string path = dir_ + "/" + file;
    const bool fresh = !fs::exists(path);
    std::ofstream out(path, std::ios::app);
    if (fresh) out << header << "\n";
    out << row << "\n";
  }

  // Keeps only the rows up to the restored checkpoint (a killed run may have logged further).
  void trim_csv(const std::string& file) {
    const std::string path = dir_ + "/" + file;
    if (!fs::exists(path)) return;
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
      const int64_t si = std::stoll(stage_idx), ii = std::stoll(it);
      if (si < stage_ || (si == stage_ && ii <= iter_)) kept += line + "\n";
    }
    write_file_atomic(path, kept);
  }

  void append_metrics(const LossTerms& l) {
    std::string header = "stage_index,stage,iteration,total", row;
    row = fmt::format("{},{},{},{:.9g}", stage_, stage().name, iter_, l.total.item<double>());
    const torch::Tensor* terms[] = {&l.rigid, &l.disp_smooth, &l.flow, &l.flow_smooth, &l.flow_consistency};
    for (int i = 0; i < 5; ++i) {
      header += std::string(",") + kColumns[i];
      row += terms[i]->defined() ? fmt::format(",{:.9g}", terms[i]->item<double>()) : ",";
    }
    header += ",lr";
    row += fmt::format(",{:.6g}", learning_rate());
    append_row("metrics.csv", header, row);
  }

  // Mean rigid photometric loss (L_br) over the validation list, networks in eval mode.
  void validate() {
    if (!data_.val) return;
    torch::NoGradGuard no_grad;
    nets_.depth->eval();
    nets_.pose->eval();
    LoaderOptions lo;
    lo.batch_size = stage().batch_size;
    lo.workers = 0;
    lo.shuffle = false;
    lo.augment.enabled = false;
    BatchLoader loader(data_.val, lo);
    const int64_t batches = (static_cast<int64_t>(data_.val->size()) + lo.batch_size - 1) / lo.batch_size;
    StageConfig rigid_only = stage();
    rigid_only.train = {"depth", "pose"};
    double sum = 0;
    for (int64_t k = 0; k < batches; ++k) {
      Batch b = loader.next();
      auto out = compute_losses(nets_, b.tgt.to(device_), b.srcs.to(device_), b.K.to(device_), rigid_only, cfg_);
      sum += out.rigid.rigid.item<double>();
    }
    nets_.set_modes(stage());
    const double val = sum / static_cast<double>(batches);
    append_row("val.csv", "stage_index,stage,iteration,photometric", fmt::format("{},{},{},{:.9g}", stage_, stage().name, iter_, val));
    spdlog::info("validation at {} {}: photometric loss {:.5f} over {} snippets{}", stage().name, iter_, val,
                 data_.val->size(), val < best_val_ ? " (best so far)" : "");
    if (val < best_val_) {
      best_val_ = val;
      pending_best_ = true;
    }
  }

  void save_checkpoint() {
    torch::serialize::OutputArchive a;
    nets_.save(a);
    torch::serialize::OutputArchive opt;
    optimizer_->save(opt);
    a.write("optimizer", opt);
    a.write("meta", torch::tensor({static_cast<double>(stage_), static_cast<double>(iter_), best_val_},
                                  torch::kFloat64).to(torch::kFloat64));
    a.write("config", c10::IValue(to_yaml(cfg_)));
    const std::string name = checkpoint_name(stage().name, iter_);
    const std::string path = dir_ + "/checkpoints/" + name, tmp = path + ".tmp";
    a.save_to(tmp);
    fs::rename(tmp, path);
    write_file_atomic(dir_ + "/checkpoints/latest", name + "\n");
    if (pending_best_) {
      fs::copy_file(path, dir_ + "/checkpoints/best.pt.tmp", fs::copy_options::overwrite_existing);
      fs::rename(dir_ + "/checkpoints/best.pt.tmp", dir_ + "/checkpoints/best.pt");
      pending_best_ = false;
    }
    kept_.erase(std::remove(kept_.begin(), kept_.end(), name), kept_.end());
    kept_.push_back(name);
    while (static_cast<int>(kept_.size()) > std::max(1, cfg_.logging.keep_last)) {
      fs::remove(dir_ + "/checkpoints/" + kept_.front());
      kept_.erase(kept_.begin());
    }
    spdlog::info("checkpoint {}", path);
  }

  // PNGs of the first sample: target, disparity, source warped by the rigid flow, and (stage 2)
  // the full flow and the forward visibility mask of eq. 13.
  void write_summaries(const Batch& batch, const StepOutput& out) {
    torch::NoGradGuard no_grad;
    const std::string base = dir_ + "/summaries/" + stage().name + "-" + std::to_string(iter_);
    write_image(base + "-target.png", batch.tgt[0]);
    write_image(base + "-disp.png", colorize_disparity(out.tgt_disp[0][0].cpu()));
    write_image(base + "-warped.png", out.rigid.fwd_warp[0][0][0].cpu());
    if (out.flow) {
      write_image(base + "-flow.png", colorize_flow(out.fwd_full[0][0][0].cpu()));
      write_image(base + "-visible.png", out.flow->fwd_visible[0][0][0].cpu().expand({3, -1, -1}));
    }
  }

  Config cfg_;
  std::string dir_;
  TrainOptions opts_;
  torch::Device device_;
  TrainingData data_;
  Networks nets_;
  std::unique_ptr<torch::optim::Adam> optimizer_;
  int64_t stage_ = 0, iter_ = 0, steps_ = 0, bad_total_ = 0;
  double best_val_ = std::numeric_limits<double>::infinity();
  bool restored_ = false, pending_best_ = false;
  std::vector<std::string> kept_;
};

}  // namespace

std::string resolve_checkpoint(const std::string& path) {
  if (fs::is_regular_file(path)) return path;
  if (fs::is_directory(path)) {
    if (fs::exists(path + "/checkpoints/best.pt")) return path + "/checkpoints/best.pt";
    const std::string latest = read_first_line(path + "/checkpoints/latest");
    if (!latest.empty()) return path + "/checkpoints/" + latest;
    throw std::runtime_error("run folder '" + path + "' has no checkpoint (checkpoints/best.pt or checkpoints/latest)");
  }
  throw std::runtime_error("checkpoint '" + path + "' does not exist");
}

int train(const Config& config, const TrainOptions& options, std::string* run_dir) {
  std::string dir = options.run_dir;
  if (dir.empty()) dir = make_run_dir(config.run.dir, config.run.name);
  else if (fs::exists(dir + "/checkpoints/latest"))
    throw std::runtime_error("run folder '" + dir + "' already holds a run; use --resume " + dir + " or another --run-dir");
  fs::create_directories(dir);
  if (run_dir) *run_dir = dir;
  write_file_atomic(dir + "/config.yaml", to_yaml(config));
  setup_logging(config.logging.level, dir + "/train.log");
  Trainer t(config, dir, options);
  return t.run();
}

int resume(const std::string& run_dir, const TrainOptions& options) {
  const std::string cfg_path = run_dir + "/config.yaml";
  if (!fs::exists(cfg_path))
    throw std::runtime_error("--resume '" + run_dir + "': not a run folder (no config.yaml)");
  const Config config = load_config(cfg_path);
  setup_logging(config.logging.level, run_dir + "/train.log");
  Trainer t(config, run_dir, options);
  t.restore();
  return t.run();
}

}  // namespace geo
