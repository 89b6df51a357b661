#include "infer/report.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <sstream>

namespace geo::infer {
namespace {

std::string escaped(const std::string& text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// A file beside report.html as a relative URL: every byte outside [A-Za-z0-9._-] percent-encoded,
// so that a frame named "a b#1" or "x?y" still loads.
std::string url(const std::string& file) {
  std::string out;
  for (const unsigned char c : file) {
    if (std::isalnum(c) || c == '.' || c == '_' || c == '-') {
      out += static_cast<char>(c);
    } else {
      char hex[4];
      std::snprintf(hex, sizeof hex, "%%%02X", c);
      out += hex;
    }
  }
  return out;
}

std::string fixed(double v, int digits) {
  char s[64];
  std::snprintf(s, sizeof s, "%.*f", digits, v);
  return s;
}

std::string image(const std::string& file, const std::string& alt) {
  return "<img src=\"" + url(file) + "\" alt=\"" + escaped(alt) + "\">";
}

}  // namespace

std::vector<size_t> report_rows(size_t frames, size_t max_rows) {
  std::vector<size_t> rows;
  if (frames == 0 || max_rows == 0) return rows;
  if (frames <= max_rows || max_rows == 1) {
    for (size_t i = 0; i < std::min(frames, max_rows); ++i) rows.push_back(i);
    return rows;
  }
  for (size_t k = 0; k < max_rows; ++k) {  // k (frames - 1) / (max_rows - 1), rounded
    const size_t i = (k * (frames - 1) + (max_rows - 1) / 2) / (max_rows - 1);
    if (rows.empty() || rows.back() != i) rows.push_back(i);
  }
  return rows;
}

std::string input_image_name(const std::string& frame) { return frame + "-input.jpg"; }

std::string report_html(const Report& r) {
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
    << "<title>geo_infer: " << escaped(r.input) << "</title>\n"
    << "<style>\nbody{font-family:sans-serif;margin:1.5em;color:#222}h1{font-size:1.4em;word-break:break-all}\n"
    << "table{border-collapse:collapse}td,th{padding:.25em .6em;text-align:left;vertical-align:top}\n"
    << ".frames td{border-top:1px solid #ddd}.frames img{width:" << r.width << "px;max-width:30vw}\n"
    << "pre{background:#f4f4f4;padding:.8em}\n</style>\n</head>\n<body>\n"
    << "<h1>geo_infer: " << escaped(r.input) << "</h1>\n<table class=\"facts\">\n"
    << "<tr><th>input</th><td>" << escaped(r.input) << " (" << r.frames << " frame" << (r.frames == 1 ? "" : "s")
    << ", " << r.input_width << "x" << r.input_height << ")</td></tr>\n"
    << "<tr><th>model</th><td>" << escaped(r.checkpoint) << " (" << r.width << "x" << r.height << ", "
    << escaped(r.precision) << ", " << escaped(r.device) << ")</td></tr>\n";
  if (r.camera.size() == 4)
    h << "<tr><th>camera</th><td>fx " << fixed(r.camera[0], 1) << ", fy " << fixed(r.camera[1], 1) << ", cx "
      << fixed(r.camera[2], 1) << ", cy " << fixed(r.camera[3], 1) << " px of the input (" << escaped(r.camera_source)
      << ")</td></tr>\n";
  h << "<tr><th>scale</th><td>"
    << (r.camera_height > 0 ? "metres, from the road plane and the camera height " + fixed(r.camera_height, 2) + " m"
                            : std::string("the network's own (monocular: unknown); --camera-height gives metres"))
    << "</td></tr>\n</table>\n";
  if (r.trajectory)
    h << "<h2>Trajectory</h2>\n<p>Top view"
      << (r.ground_truth ? "; the ground truth in black, the estimate scale-aligned to it" : "")
      << " (trajectory.txt: KITTI pose file).</p>\n"
      << image("trajectory.png", "trajectory") << "\n";
  if (!r.rows.empty()) {
    h << "<h2>Frames</h2>\n";
    if (static_cast<int64_t>(r.rows.size()) < r.frames)
      h << "<p>" << r.rows.size() << " of " << r.frames
        << " frames, spread over the clip; every frame's outputs are in this folder.</p>\n";
    h << "<table class=\"frames\">\n<tr><th>frame</th><th>input</th><th>disparity</th><th>flow to the next</th></tr>\n";
    for (size_t i = 0; i < r.rows.size(); ++i) {
      const std::string& n = r.rows[i];
      h << "<tr><td>" << escaped(n) << "</td><td>" << image(input_image_name(n), n + " input") << "</td><td>"
        << image(n + "-disp.png", n + " disparity") << "</td><td>"
        << (i < r.row_flow.size() && r.row_flow[i] ? image(n + "-flow.png", n + " flow") : std::string("-"))
        << "</td></tr>\n";
    }
    h << "</table>\n";
  }
  if (!r.timing.empty()) h << "<h2>Timing</h2>\n<pre>" << escaped(r.timing) << "</pre>\n";
  h << "</body>\n</html>\n";
  return h.str();
}

}  // namespace geo::infer
