#include "data/synth/synth_snippets.h"

#include <stdexcept>

namespace geo {
namespace {

using Frames = std::vector<std::vector<torch::Tensor>>;  // [drive][frame] -> [3,H,W] float32

class SynthSnippets : public SnippetSource {
 public:
  struct Target {
    int drive;
    int64_t frame;
  };
  SynthSnippets(std::shared_ptr<const Frames> frames, std::vector<Target> targets, torch::Tensor K, int64_t seq_length)
      : frames_(std::move(frames)), targets_(std::move(targets)), K_(std::move(K)), seq_length_(seq_length) {}

  size_t size() const override { return targets_.size(); }
  int64_t seq_length() const override { return seq_length_; }
  std::string id(size_t index) const override {
    const Target& t = at(index);
    return synth_snippet_id(t.drive, t.frame);
  }
  Snippet get(size_t index) const override {
    const Target& t = at(index);
    std::vector<torch::Tensor> frames;
    for (int64_t o = -seq_length_ / 2; o <= seq_length_ / 2; ++o) frames.push_back((*frames_)[t.drive][t.frame + o]);
    return {torch::stack(frames), K_.clone(), id(index)};
  }

 private:
  const Target& at(size_t index) const {
    if (index >= targets_.size())
      throw std::out_of_range("synthetic snippet " + std::to_string(index) + " of " + std::to_string(targets_.size()));
    return targets_[index];
  }
  std::shared_ptr<const Frames> frames_;
  std::vector<Target> targets_;
  torch::Tensor K_;
  int64_t seq_length_;
};

}  // namespace

SynthOptions synth_world_at(const std::string& preset, int64_t height, int64_t width) {
  SynthOptions o = SynthOptions::preset_named(preset);
  const double sx = static_cast<double>(width) / static_cast<double>(o.width);
  const double sy = static_cast<double>(height) / static_cast<double>(o.height);
  o.intrinsics = {o.intrinsics.fx * sx, o.intrinsics.fy * sy, o.intrinsics.cx * sx, o.intrinsics.cy * sy};
  o.height = height;
  o.width = width;
  return o;
}

SynthSnippetSets render_synth_snippets(const SynthOptions& world, int64_t seq_length) {
  if (seq_length < 3 || seq_length % 2 == 0)
    throw std::invalid_argument("synthetic snippets: seq_length " + std::to_string(seq_length) +
                                " must be odd and >= 3");
  if (world.train_drives < 1 || world.frames_per_drive < seq_length)
    throw std::invalid_argument("synthetic snippets: " + std::to_string(world.train_drives) + " drives of " +
                                std::to_string(world.frames_per_drive) + " frames hold no " +
                                std::to_string(seq_length) + "-frame snippet");
  auto frames = std::make_shared<Frames>();
  std::vector<SynthSnippets::Target> train, val;
  const int64_t half = seq_length / 2;
  for (int d = 0; d < world.train_drives; ++d) {
    const SynthScene scene(synth_drive_seed(world.seed, 0, d), world.frames_per_drive, world.turns, world.traffic);
    auto& drive = frames->emplace_back();
    for (int64_t f = 0; f < world.frames_per_drive; ++f) {
      // As a PNG holds it (image_io's write_image, then the 8-bit read scaled by 1/255).
      const auto image = render_frame(scene, f, world).image;
      drive.push_back((image.clamp(0, 1) * 255).round().to(torch::kUInt8).to(torch::kFloat32) * (1.0f / 255.0f));
      // geo_synth lists the targets with both neighbours; longer snippets need more.
      if (f > 0 && f + 1 < world.frames_per_drive && f >= half && f + half < world.frames_per_drive)
        (synth_is_validation_frame(f) ? val : train).push_back({d, f});
    }
  }
  const torch::Tensor K = world.intrinsics.K().to(torch::kFloat32);
  SynthSnippetSets out;
  out.train = std::make_shared<SynthSnippets>(frames, std::move(train), K, seq_length);
  if (!val.empty()) out.val = std::make_shared<SynthSnippets>(frames, std::move(val), K, seq_length);
  return out;
}

}  // namespace geo
