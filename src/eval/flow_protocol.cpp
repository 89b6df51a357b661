// The KITTI 2015 flow protocol (eval/protocols.h): EPE and Fl over flow_occ and flow_noc, the
// background and the moving objects apart, the rigid flow alone for a model with a FlowNet.
#include "eval/protocol_parts.h"

#include "core/files.h"
#include "core/progress.h"
#include "data/image_io.h"
#include "data/kitti/calib.h"
#include "data/text_io.h"
#include "eval/metrics.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <limits>

namespace fs = std::filesystem;

namespace geo {
namespace {

// One flow's scores over the pairs: EPE and Fl on flow_occ ("all") and flow_noc averaged over the
// pairs (GeoNet's protocol), and on flow_occ's background and foreground pixels (obj_map = 0 / > 0)
// pooled over the pixels of all pairs (KITTI's devkit, Fl-bg / Fl-fg).
struct FlowScores {
  double epe_occ = 0, epe_noc = 0, fl_occ = 0, fl_noc = 0;
  FlowErrorSums bg, fg;
  bool with_objects = false;

  // flow: at the ground truth's size; foreground: [H,W] bool or undefined (no object map).
  void add(const FlowMap& occ, const FlowMap& noc, const torch::Tensor& foreground, const torch::Tensor& flow) {
    const auto o = flow_error_sums(occ.flow, occ.valid, flow), n = flow_error_sums(noc.flow, noc.valid, flow);
    epe_occ += o.epe();
    fl_occ += o.fl();
    epe_noc += n.epe();
    fl_noc += n.fl();
    if (!foreground.defined()) return;
    with_objects = true;
    const auto valid = occ.valid[0] > 0.5;
    bg += flow_error_sums(occ.flow, valid & ~foreground, flow);
    fg += flow_error_sums(occ.flow, valid & foreground, flow);
  }
  void put(EvalResult& r, const std::string& prefix, int64_t pairs) const {
    const double n = static_cast<double>(pairs);
    r.metrics.insert(r.metrics.end(), {{prefix + "epe_all", epe_occ / n},
                                       {prefix + "epe_noc", epe_noc / n},
                                       {prefix + "fl_all", fl_occ / n},
                                       {prefix + "fl_noc", fl_noc / n}});
    if (!with_objects) return;
    const double none = std::numeric_limits<double>::quiet_NaN();  // no such pixel: null in the JSON
    r.metrics.insert(r.metrics.end(), {{prefix + "epe_bg", bg.pixels ? bg.epe() : none},
                                       {prefix + "epe_fg", fg.pixels ? fg.epe() : none},
                                       {prefix + "fl_bg", bg.pixels ? bg.fl() : none},
                                       {prefix + "fl_fg", fg.pixels ? fg.fl() : none}});
  }
};

torch::Tensor flow_calib_K(const std::string& root, const std::string& name) {
  for (const auto& dir :
       {root + "/training/calib_cam_to_cam", root + "/../data_scene_flow_calib/training/calib_cam_to_cam"}) {
    const std::string p = dir + "/" + name + ".txt";
    if (fs::exists(p)) return read_key_values(p).projection("P_rect_02").slice(1, 0, 3);
  }
  throw std::runtime_error("calibration for pair " + name + " not found (looked in " + root +
                           "/training/calib_cam_to_cam/" + name + ".txt)");
}

// The pairs to score: the split file's (training/image_2/000123_10.png lines), else every
// <pair>_10.png of training/image_2, in order.
std::vector<std::string> flow_pair_names(const EvalOptions& o, const std::string& root) {
  std::vector<std::string> names;
  if (!o.split_file.empty()) {
    for (const auto& line : read_lines(o.split_file)) {
      const auto base = fs::path(line).filename().string();  // 000123_10.png
      if (base.size() < 10 || base.substr(6) != "_10.png")
        throw std::runtime_error(o.split_file + ": expected lines like training/image_2/000123_10.png, got '" + line +
                                 "'");
      names.push_back(base.substr(0, 6));
    }
  } else {
    const std::string dir = root + "/training/image_2";
    if (!fs::is_directory(dir)) throw std::runtime_error("KITTI 2015 images not found: '" + dir + "' (--data-root)");
    for (const auto& e : fs::directory_iterator(dir)) {
      const auto f = e.path().filename().string();
      if (f.size() == 13 && f.substr(6) == "_10.png") names.push_back(f.substr(0, 6));
    }
    std::sort(names.begin(), names.end());
  }
  if (names.empty()) throw std::runtime_error("no flow pairs to evaluate under " + root);
  return names;
}

// KITTI 2015's obj_map of a pair (> 0: a moving object) where the file exists, checked against the
// ground truth's size; undefined otherwise.
torch::Tensor foreground_of(const std::string& objects, int64_t H, int64_t W) {
  if (!fs::exists(objects)) return {};
  auto foreground = read_object_map(objects) > 0;
  if (foreground.size(0) != H || foreground.size(1) != W)
    throw std::runtime_error("object map '" + objects + "' is " + std::to_string(foreground.size(0)) + "x" +
                             std::to_string(foreground.size(1)) + ", its flow ground truth " + std::to_string(H) + "x" +
                             std::to_string(W));
  return foreground;
}

// What the KITTI 2015 protocol counts over the pairs besides the scores, and the result it makes.
struct FlowTally {
  int64_t with_previous = 0, with_objects = 0, px_occ = 0, px_noc = 0;
  std::vector<std::string> without_gt;  // pairs whose flow_occ or flow_noc has no valid pixel
  int64_t predictions_resized = 0;      // prediction files whose size differs from the ground truth
  std::string resized;                  // the first of them
  bool from_files = false;              // predictions meant at the ground truth's size

  // The scores (rigid ones when `split_stages`) and counts, with a warning for what was left out.
  EvalResult result(const std::vector<std::string>& names, const EvalOptions& o, const std::string& root,
                    const FlowScores& full, const FlowScores& rigid, bool split_stages, bool model) const {
    const int64_t scored = static_cast<int64_t>(names.size() - without_gt.size());
    if (scored == 0) throw std::runtime_error("no flow pair under " + root + " has valid ground-truth pixels");
    if (!without_gt.empty())
      spdlog::warn(
          "{} of {} pairs have no valid ground-truth pixel (flow_occ or flow_noc) and are left out of the "
          "means; first: {}",
          without_gt.size(), names.size(), without_gt.front());
    if (predictions_resized > 0)
      spdlog::warn(
          "{} of {} flow predictions differ in size from their ground truth and were resized ({}, vectors "
          "scaled); first: {}",
          predictions_resized, names.size(), o.flow_resize == FlowResize::kNearest ? "nearest" : "bilinear", resized);
    if (with_objects > 0 && with_objects < scored)
      spdlog::warn(
          "{} of {} pairs have no object map (training/obj_map/<pair>_10.png): background and foreground "
          "errors are over the other {} only",
          scored - with_objects, scored, with_objects);
    EvalResult r;
    full.put(r, "", scored);
    if (split_stages) rigid.put(r, "rigid_", scored);
    r.counts = {{"pairs", scored},
                {"pixels_all", px_occ},
                {"pixels_noc", px_noc},
                {"pairs_without_ground_truth", static_cast<int64_t>(without_gt.size())},
                {"pairs_with_object_map", with_objects}};
    if (with_objects > 0)
      r.counts.insert(r.counts.end(), {{"pixels_bg", full.bg.pixels}, {"pixels_fg", full.fg.pixels}});
    if (from_files) r.counts.emplace_back("predictions_resized", predictions_resized);
    if (model) {
      r.counts.emplace_back("pairs_with_frame_09", with_previous);
      if (with_previous < static_cast<int64_t>(names.size()))
        spdlog::warn(
            "{} of {} pairs have no previous frame (training/image_2/<pair>_09.png, KITTI 2015's multi-view "
            "extension): the PoseNet saw the duplicate-frame snippet (tgt, tgt, src) for them",
            static_cast<int64_t>(names.size()) - with_previous, names.size());
    }
    return r;
  }
};

}  // namespace

EvalResult eval_kitti2015(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  const auto names = flow_pair_names(o, root);
  FlowScores full, rigid;
  FlowTally tally;
  const bool split_stages = source.model() && source.model()->has_flow();  // rigid flow apart from the full flow
  Progress progress("kitti2015", static_cast<int64_t>(names.size()), 0, "pairs");
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string t = root + "/training/image_2/" + names[i] + "_10.png";
    const std::string s = root + "/training/image_2/" + names[i] + "_11.png";
    const std::string gocc = root + "/training/flow_occ/" + names[i] + "_10.png";
    const std::string gnoc = root + "/training/flow_noc/" + names[i] + "_10.png";
    const std::string objects = root + "/training/obj_map/" + names[i] + "_10.png";
    for (const auto* p : {&t, &s, &gocc, &gnoc}) require_file(*p, "pair " + names[i]);
    const FlowAnswer answer = source.flow(FlowQuery{names[i], t, s, root + "/training/image_2/" + names[i] + "_09.png",
                                                    source.model() ? flow_calib_K(root, names[i]) : torch::Tensor()});
    const torch::Tensor& flow = answer.full;
    const torch::Tensor& rigid_flow = answer.rigid;
    const int64_t frame_h = answer.frame_height, frame_w = answer.frame_width;
    tally.with_previous += answer.used_previous;
    tally.from_files = tally.from_files || answer.meant_at_ground_truth_size;
    require_finite(flow, "the flow prediction for pair " + names[i]);
    const auto occ = read_flow_png(gocc), noc = read_flow_png(gnoc);
    require_same_size(gnoc, noc.flow.size(1), noc.flow.size(2), gocc, occ.flow.size(1), occ.flow.size(2));
    if (frame_h > 0) require_same_size(gocc, occ.flow.size(1), occ.flow.size(2), t, frame_h, frame_w);
    // A file-based prediction is meant at the ground truth's size (KITTI's devkit rejects others):
    // geo rescales it like a model's output, loudly.
    if (answer.meant_at_ground_truth_size && (flow.size(1) != occ.flow.size(1) || flow.size(2) != occ.flow.size(2))) {
      if (tally.resized.empty())
        tally.resized = names[i] + " (" + std::to_string(flow.size(1)) + "x" + std::to_string(flow.size(2)) + " vs " +
                        std::to_string(occ.flow.size(1)) + "x" + std::to_string(occ.flow.size(2)) + ")";
      ++tally.predictions_resized;
    }
    const int64_t n_occ = (occ.valid > 0.5).sum().item<int64_t>(), n_noc = (noc.valid > 0.5).sum().item<int64_t>();
    if (n_occ == 0 || n_noc == 0) {  // an all-invalid ground truth would count as EPE 0
      tally.without_gt.push_back(names[i]);
      progress.update(static_cast<int64_t>(i + 1));
      continue;
    }
    const int64_t H = occ.flow.size(1), W = occ.flow.size(2);
    const auto foreground = foreground_of(objects, H, W);  // [H,W] bool, where the pair has an object map
    tally.with_objects += foreground.defined();
    full.add(occ, noc, foreground, resize_flow(flow, H, W, o.flow_resize));
    if (split_stages) {
      require_finite(rigid_flow, "the rigid flow prediction for pair " + names[i]);
      rigid.add(occ, noc, foreground, resize_flow(rigid_flow, H, W, o.flow_resize));
    }
    tally.px_occ += n_occ;
    tally.px_noc += n_noc;
    progress.update(static_cast<int64_t>(i + 1));
  }
  return tally.result(names, o, root, full, rigid, split_stages, source.model() != nullptr);
}

}  // namespace geo
