// What evaluate() (protocols.cpp) dispatches to: one protocol per file (eigen_protocol.cpp,
// flow_protocol.cpp, odometry_protocol.cpp), each over a split's root (split_root). Internal to the
// evaluation layer.
#pragma once

#include "eval/protocols.h"

#include <string>

namespace geo {

EvalResult eval_eigen(const EvalOptions& options, const std::string& root, PredictionSource& source);
EvalResult eval_kitti2015(const EvalOptions& options, const std::string& root, PredictionSource& source);
EvalResult eval_odometry(const EvalOptions& options, const std::string& root, PredictionSource& source);

// The camera height to scale by: the one asked for, else the data root's record (a geo_synth world's
// camera_height.txt, at the world's root or above the split's), else KITTI's 1.65 m.
double camera_height_of(const EvalOptions& options, const std::string& root);

}  // namespace geo
