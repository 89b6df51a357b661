// Training snippets: `seq_length` consecutive frames centred on a target, resized to the training
// size, with the intrinsics scaled to match (paper Sec. 4.2). Sources: KITTI raw folders
// (sequence_dataset.h, needs OpenCV) or a packed cache (packed.h, LibTorch only).
#pragma once

#include <torch/torch.h>

#include <cstddef>
#include <memory>
#include <string>

namespace geo {

struct Snippet {
  torch::Tensor frames;  // [L,3,H,W] float32 in [0,1]; frames[L/2] is the target
  torch::Tensor K;       // [3,3] float32 at H x W
  std::string id;        // "folder frame side"
};

class SnippetSource {
 public:
  virtual ~SnippetSource() = default;
  virtual size_t size() const = 0;
  virtual Snippet get(size_t index) const = 0;  // throws naming the file on bad input
  virtual std::string id(size_t index) const = 0;
  virtual int64_t seq_length() const = 0;
};

// Up to `n` (>= 1) of `source`'s snippets spread evenly over it, the first and the last among them,
// in their order: a quick look at a whole dataset. `source` itself when it has no more than n.
std::shared_ptr<const SnippetSource> spread_snippets(std::shared_ptr<const SnippetSource> source, size_t n);

}  // namespace geo
