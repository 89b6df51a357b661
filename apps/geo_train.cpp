// geo_train: trains DepthNet, PoseNet and FlowNet without labels (paper Sec. 4.2).
//   geo_train --config configs/stage1.yaml [--run-dir DIR] [--set key=value ...] [--device auto|cpu|cuda]
//   geo_train --config stage2.yaml --init runs/stage1-...      (stage 2 from stage 1's result)
//   geo_train --resume RUN_DIR
//   torchrun --no-python --nproc_per_node=N geo_train --config ...   (N processes, train/distributed.h)
//   srun geo_train --config ... [--master-addr HOST]                  (SLURM)
// A bare config name that is not a file here resolves to the shipped configs/.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "core/config.h"
#include "core/logging.h"
#include "train/trainer.h"

#include "app_options.h"

namespace {

struct TrainCommand {
  std::string config, resume;
  std::vector<std::string> overrides;
  geo::TrainOptions train;
};

void add_options(CLI::App& app, TrainCommand& c) {
  auto* cfg_opt = geo::app::add_config_options(app, c.config, c.overrides,
                                               "YAML config (stage1.yaml, stage2.yaml, smoke.yaml or a path)");
  auto* res_opt = app.add_option("--resume", c.resume, "continue the run in this folder from its latest checkpoint");
  cfg_opt->excludes(res_opt);
  auto* dir_opt =
      app.add_option("--run-dir", c.train.run_dir, "run folder to create (default: <run.dir>/<run.name>-<time>)");
  auto* init_opt = app.add_option("--init", c.train.init, "start the first stage from this checkpoint or run folder");
  res_opt->excludes(dir_opt)->excludes(init_opt);  // a resumed run keeps its folder and its weights
  geo::app::add_device_option(app, c.train.device, "default: run.device");
  app.add_option("--master-addr", c.train.master_addr,
                 "distributed under SLURM: the host of rank 0 when MASTER_ADDR is not set (torchrun sets it)");
  app.footer(
      "Distributed: launched by torchrun (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT) or srun "
      "(SLURM_PROCID, SLURM_NTASKS, SLURM_LOCALID), geo_train is one process of a data-parallel group: "
      "batch_size is per process, gradients are averaged, rank 0 writes the run folder. "
      "run.distributed.{backend,timeout_s,shard_data,verify_interval} configure it.");
}

int train(const TrainCommand& c) {
  if (c.config.empty() && c.resume.empty())
    throw std::runtime_error("give --config FILE (e.g. --config stage1.yaml) or --resume RUN_DIR; see --help");
  if (!c.resume.empty()) {
    if (!c.overrides.empty()) throw std::runtime_error("--set cannot change a run being resumed");
    return geo::resume(c.resume, c.train);
  }
  const auto config = geo::load_config(geo::resolve_config_path(c.config), c.overrides);
  geo::setup_logging(config.logging.level);
  return geo::train(config, c.train);
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<TrainCommand>(
      argc, argv,
      "geo_train: unsupervised training of depth, camera motion and optical flow "
      "(GeoNet with feature refinement) from monocular video",
      add_options, train);
}
