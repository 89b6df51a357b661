// Where the predictions a protocol scores come from (eval/protocols.h): a model (a checkpoint or an
// untrained network), files of predictions, or the trivial baseline. The protocols ask every source
// the same questions; reading images or files and running the network is the source's business.
#pragma once

#include "eval/predictor.h"

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

namespace geo {

// One Eigen test image: line `index` (0-based) of the `count` lines of `list`, and its image file.
struct DepthQuery {
  size_t index = 0, count = 0;
  std::string list, image;
};
struct DepthAnswer {
  torch::Tensor depth;            // [h,w], positive, in any scale (the protocol scales it)
  int64_t height = 0, width = 0;  // the test image's size (the ground truth's)
  bool from_file = false;         // a prediction file: meant at the image's size (a model's is resized by design)
};

// One KITTI 2015 pair: its name (000123), its frames _10 (target) and _11 (source), the frame before
// it (_09, which may not exist), and the frames' intrinsics [3,3].
struct FlowQuery {
  std::string name, tgt, src, prev;
  torch::Tensor K;
};
struct FlowAnswer {
  torch::Tensor full;   // [2,h,w], pixels of its own size
  torch::Tensor rigid;  // the rigid flow alone where the source tells it apart (a model with a FlowNet)
  int64_t frame_height = 0, frame_width = 0;  // the frames' size, where the source read them (0: not read)
  bool used_previous = false;                 // the PoseNet saw the frame before the pair
  bool meant_at_ground_truth_size = false;    // files: a size that differs is resized, loudly
};

// One odometry sequence: its folder (image_2/, calib.txt), name ("09"), its ground-truth pose file
// and frame count. camera_height > 0: also the trajectory in metres from the road plane.
struct SequenceQuery {
  std::string folder, name, gt_path;
  int64_t frames = 0;
  double camera_height = 0;
};
struct TrajectoryAnswer {
  torch::Tensor trajectory;                  // [n,4,4] cam_to_world, float64
  std::vector<torch::Tensor> snippet_poses;  // 5-frame models: [5,4,4] of frames c-2..c+2 in c's frame, per centre c
  torch::Tensor metric;                      // with camera_height: the trajectory in metres
  int64_t frames_with_road = 0;
};

class PredictionSource {
 public:
  virtual ~PredictionSource() = default;
  // What the results name as their source: a checkpoint's path, a file, "trivial baseline".
  virtual std::string name() const = 0;
  // The model behind the predictions, if any (which drives it trained on, its rigid flow).
  virtual Predictor* model() { return nullptr; }
  virtual DepthAnswer depth(const DepthQuery& q) = 0;
  virtual FlowAnswer flow(const FlowQuery& q) = 0;
  virtual TrajectoryAnswer trajectory(const SequenceQuery& q) = 0;
};

// The model's own predictions (borrowed: it must outlive the source). Odometry streams the
// sequence: only the frames of the current snippet are held.
std::unique_ptr<PredictionSource> model_source(Predictor& model);
// Predictions computed elsewhere: eigen, a folder of <line, 6 digits>.png depth maps (uint16,
// depth x 256) or one [N,H,W] .npy; kitti2015, a folder of <pair>_10.png (KITTI flow PNGs);
// odometry, a KITTI pose file (one 3x4 row-major pose per line).
std::unique_ptr<PredictionSource> file_source(const std::string& path);
// The baseline any method must beat: a constant depth, zero flow, no motion.
std::unique_ptr<PredictionSource> trivial_source();

// What geo_eval scores, chosen from its options: an untrained network of a config, the trivial
// baseline, prediction files, or a model (a checkpoint file or run folder; the newest run under
// `runs` when none is given). `need_model` false (--export-gt alone) and nothing given: no source.
// A model runs in `precision` (LoadOptions::precision); int8 calibrated on the first
// `calibration_frames` frames of `calibration` (an image, frame folder or video).
struct SourceChoice {
  std::string checkpoint, runs = "runs", predictions, untrained_config, device = "auto";
  std::string precision = "fp32", calibration;
  int64_t calibration_frames = 8;
  bool trivial = false;
  bool need_model = true;
};
struct ChosenSource {
  std::unique_ptr<Predictor> predictor;  // the model a model source reads (kept alive with it)
  std::unique_ptr<PredictionSource> source;
  std::string reads;  // the file or folder it reads ("" for baselines)
};
ChosenSource choose_source(const SourceChoice& choice);
// Every file and folder an evaluation of `chosen` reads besides the data root: the source's files,
// the model, the untrained network's config, the calibration frames and `split_file`. What its
// outputs must not replace (core/files.h check_outputs).
std::vector<std::string> evaluation_reads(const SourceChoice& choice, const ChosenSource& chosen,
                                          const std::string& split_file);

// geo_eval's data root: `given`, else $GEO_KITTI_ROOT, else ./data/kitti; an error when that is no folder.
std::string eval_data_root(const std::string& given);

// Helpers the protocols share with the sources.
void require_file(const std::string& path, const std::string& what);
// Predictions must be finite: a NaN would otherwise turn into a nan metric (or, through a mask, a
// perfect-looking 0) with exit code 0.
void require_finite(const torch::Tensor& t, const std::string& what);
// Frames of one pair or snippet, and ground truth and its frame, must have one size.
void require_same_size(const std::string& a, int64_t ha, int64_t wa, const std::string& b, int64_t hb, int64_t wb);

}  // namespace geo
