// geo's convolution: every convolution of the networks goes through conv2d below, which works
// around a oneDNN defect of LibTorch 2.x; the Conv2d module holds that by its type (its forward is
// conv2d), so that no network can call LibTorch's convolution by mistake (the include check
// refuses torch::nn::Conv2d and torch::conv2d in src/models outside this file's source).
#pragma once

#include <torch/torch.h>

namespace geo {

// LibTorch 2.x on the CPU (seen with 2.6 and oneDNN 3.7) gets convolutions wrong whose channel
// counts are not multiples of 16, oneDNN's block: it leaves the padding of the last block
// uninitialised (results hold whatever the heap held: wrong values, or NaN), or computes the tail
// channels wrongly:
//  - an input of 1 channel (bfloat16), or of more than 16 channels and not a multiple of 16: the
//    decoders' iconv layers, whose inputs concatenate a 1- or 2-channel prediction (64 + 64 + 1 =
//    129 channels; float32 outputs 3-16% off, NaN on NaN-filled memory); FR's MLP of hidden width 1;
//  - an output of a number of channels that is not a multiple of 16: in bfloat16 the output itself
//    (the 1- and 2-channel disparity and flow predictions 20-100% off), in both types the input's
//    gradient (FR's spatial 7x7 convolution, PoseNet's 12 pose parameters);
//  - in bfloat16, an input of 2 to 15 channels whose gradient is needed (a third off).
// geo's convolutions go through conv2d below, which appends zero channels up to the next multiple of
// 16 (to the input and the weight's input side; to the weight's and bias's output side, the extra
// outputs cut off): the same convolution exactly, off those paths. Nothing is appended with
// LibTorch 1.x or off the CPU. tests/support/poisoned_alloc.cpp finds reads of uninitialised
// memory: the networks' tests run again with fresh memory filled with NaN.
torch::Tensor conv2d(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                     torch::IntArrayRef stride, torch::IntArrayRef padding);
// m's convolution of x through conv2d above (stride and pixel padding as m was constructed with).
torch::Tensor conv2d(const torch::nn::Conv2dImpl& m, const torch::Tensor& x);
// The number of zero channels conv2d appends to the input x (0 where none).
int64_t onednn_channel_padding(const torch::Tensor& x);
// t with n zero channels appended (dimension 1); t itself when n is 0.
torch::Tensor pad_channels(const torch::Tensor& t, int64_t n);

// Lets go of a float kernel that int8 inference replaced: its data becomes an empty tensor (0
// elements, same type and device), as an int8 model file keeps it.
void release_float_weight(torch::Tensor& weight);

// While one exists on this thread, new geo::Conv2d modules get uninitialised weights (torch::empty,
// no random numbers drawn for them) and init_weights does nothing: for networks whose every weight
// is read from a file next (geo::Model::load, CheckpointFile::networks). Random initialisation was
// about half of opening a model (two draws per weight: LibTorch's and geo's).
class UninitialisedWeights {
 public:
  UninitialisedWeights();
  ~UninitialisedWeights();
  UninitialisedWeights(const UninitialisedWeights&) = delete;
  UninitialisedWeights& operator=(const UninitialisedWeights&) = delete;
  static bool active();

 private:
  bool previous_;
};

// torch::nn::Conv2d whose forward is conv2d above: the same parameters and state-dict keys (and,
// outside UninitialisedWeights, the same initial values from the same random numbers).
struct Conv2dImpl : torch::nn::Conv2dImpl {
  explicit Conv2dImpl(const torch::nn::Conv2dOptions& options);
  Conv2dImpl(int64_t in, int64_t out, torch::ExpandingArray<2> kernel)
      : Conv2dImpl(torch::nn::Conv2dOptions(in, out, kernel)) {}
  torch::Tensor forward(const torch::Tensor& x) { return conv2d(*this, x); }
};
TORCH_MODULE(Conv2d);

}  // namespace geo
