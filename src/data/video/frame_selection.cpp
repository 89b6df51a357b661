#include "data/video/frame_selection.h"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace geo {

int64_t frame_rate_stride(double source_fps, double target_fps) {
  if (!(source_fps > 0) || !(target_fps > 0) || target_fps >= source_fps) return 1;
  return std::max<int64_t>(1, std::llround(source_fps / target_fps));
}

torch::Tensor motion_thumbnail(const torch::Tensor& rgb) {
  TORCH_CHECK(rgb.dim() == 3 && rgb.size(0) == 3, "frame must be [3,H,W], got ", rgb.sizes());
  const int64_t h = std::min<int64_t>(32, rgb.size(1));
  const int64_t w = std::max<int64_t>(1, (rgb.size(2) * h + rgb.size(1) / 2) / rgb.size(1));
  auto grey = rgb.to(torch::kFloat32).mean(0, true).unsqueeze(0);  // [1,1,H,W]
  return torch::adaptive_avg_pool2d(grey, {h, w})[0][0].contiguous();
}

double changed_fraction(const torch::Tensor& a, const torch::Tensor& b) {
  TORCH_CHECK(a.sizes() == b.sizes(), "thumbnails differ in size: ", a.sizes(), " vs ", b.sizes());
  return (a - b).abs().gt(kChangedLevel).to(torch::kFloat64).mean().item<double>();
}

FrameSelector::FrameSelector(int64_t stride, double static_threshold)
    : stride_(std::max<int64_t>(1, stride)), threshold_(static_threshold) {}

bool FrameSelector::offer(int64_t index, const torch::Tensor& thumbnail, const std::function<bool()>& camera_moved) {
  ++decoded_;
  if (!wants(index)) {
    ++by_rate_;
    return false;
  }
  if (last_kept_.defined()) {
    const double change = changed_fraction(thumbnail, last_kept_);
    largest_change_ = std::max(largest_change_, change);
    if (change < threshold_) {
      ++static_;
      return false;
    }
    if (camera_moved && !camera_moved()) {
      ++standing_;
      return false;
    }
  }
  last_kept_ = thumbnail;
  kept_.push_back(index);
  return true;
}

double FrameSelector::moving_share() const {
  const int64_t after_first = looked_at() - 1;
  return after_first > 0
             ? static_cast<double>(static_cast<int64_t>(kept_.size()) - 1) / static_cast<double>(after_first)
             : 1.0;
}

ClipRuns split_clip(int64_t n, double val_fraction, int64_t val_block, int64_t seq_length) {
  ClipRuns out;
  const int64_t half = seq_length / 2;
  const int64_t n_val = static_cast<int64_t>(std::llround(val_fraction * static_cast<double>(n)));
  std::vector<char> role(static_cast<size_t>(std::max<int64_t>(n, 0)), 't');  // t train, v val, x left out
  if (n_val >= seq_length && val_block >= seq_length) {
    const int64_t blocks = (n_val + val_block - 1) / val_block;
    const int64_t len = n_val / blocks;
    if (len >= seq_length) {
      for (int64_t j = 0; j < blocks; ++j) {
        const int64_t end = (j + 1) * n / blocks;  // exclusive
        for (int64_t p = end - len; p < end; ++p) role[static_cast<size_t>(p)] = 'v';
      }
      // Leave out `half` training frames on each side of every validation block.
      for (int64_t p = 0; p < n; ++p) {
        if (role[static_cast<size_t>(p)] != 't') continue;
        for (int64_t d = -half; d <= half; ++d) {
          const int64_t q = p + d;
          if (q >= 0 && q < n && role[static_cast<size_t>(q)] == 'v') {
            role[static_cast<size_t>(p)] = 'x';
            ++out.edge_dropped;
            break;
          }
        }
      }
    }
  }
  for (int64_t p = 0; p < n; ++p) {
    const char r = role[static_cast<size_t>(p)];
    if (r == 'x') continue;
    auto& runs = r == 'v' ? out.val : out.train;
    const bool continues = p > 0 && role[static_cast<size_t>(p - 1)] == r && !runs.empty();
    if (!continues) runs.emplace_back();
    runs.back().push_back(p);
  }
  return out;
}

std::vector<std::pair<size_t, int64_t>> snippet_targets(const std::vector<std::vector<int64_t>>& runs,
                                                        int64_t seq_length) {
  std::vector<std::pair<size_t, int64_t>> out;
  const int64_t half = seq_length / 2;
  for (size_t r = 0; r < runs.size(); ++r)
    for (int64_t p = half; p + half < static_cast<int64_t>(runs[r].size()); ++p) out.emplace_back(r, p);
  return out;
}

bool natural_less(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])), db = std::isdigit(static_cast<unsigned char>(b[j]));
    if (da && db) {
      size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      // Compare the digit runs as numbers: skip leading zeros, then length, then digits.
      size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i > je - j;  // equal numbers: more leading zeros first ("01" < "1")
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

}  // namespace geo
