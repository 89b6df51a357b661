// Fine-tuning that does not unlearn: a term holding the depth being trained to the depth of the
// weights the stage started from (a frozen copy, the teacher). Short or hard clips (stop-and-go
// traffic, a camera that hardly moves, a few seconds of footage) explain their photometric loss by
// depth maps that follow texture rather than shape; without this term a few dozen steps on them
// undo what a model learned on forward driving (measured on real KITTI traffic: docs/video.md).
// Scale-free: each depth map is divided by its own mean, so the term keeps the teacher's shape and
// leaves the scale, which no monocular term fixes, free.
#pragma once

#include <torch/torch.h>

namespace geo {

// disp, teacher_disp [B,1,H,W] disparities (1/depth) of the same frames; teacher_disp carries no
// gradient. Returns mean over batch and pixels of
//   | log(d / mean(d)) - log(t / mean(t)) |,  d = 1/disp, t = 1/teacher_disp, means per image:
// 0 for any depth map proportional to the teacher's. Throws on mismatched shapes.
torch::Tensor depth_anchor(const torch::Tensor& disp, const torch::Tensor& teacher_disp);

}  // namespace geo
