// geo_infer --report: report.html beside the outputs, to look at in a browser. It opens offline:
// everything it shows is a file in the same folder (the input frames as JPEG, disparity and flow
// PNGs, trajectory.png), named relatively; no script, no style sheet or font fetched.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace geo::infer {

struct Report {
  std::string input, checkpoint, precision, device;
  int64_t frames = 0;
  int64_t width = 0, height = 0;              // the model's size (what the outputs have)
  int64_t input_width = 0, input_height = 0;  // the input's frames
  std::vector<double> camera;                 // fx fy cx cy in pixels of the input
  std::string camera_source;                  // where the camera came from, in words
  double camera_height = 0;                   // metres; 0: depth in the network's unknown scale
  bool trajectory = false, ground_truth = false;
  std::vector<std::string> rows;  // names of the frames shown, in order
  std::vector<bool> row_flow;     // whether <name>-flow.png exists for each row
  std::string timing;             // StepTimes::table text; empty without one
};

// The frames a report shows: all of them up to `max_rows`, else `max_rows` spread evenly over the
// clip, the first and the last included. Indices in order.
std::vector<size_t> report_rows(size_t frames, size_t max_rows = 60);

// The file names a report refers to besides the other outputs: <name>-input.jpg of each row.
std::string input_image_name(const std::string& frame);

// report.html as text.
std::string report_html(const Report& report);

}  // namespace geo::infer
