#include "data/splits.h"

#include "core/config.h"
#include "core/files.h"
#include "data/text_io.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace geo {

std::string SplitEntry::date() const { return folder.substr(0, folder.find('/')); }

std::string SplitEntry::drive() const {
  const auto slash = folder.rfind('/');
  return slash == std::string::npos ? folder : folder.substr(slash + 1);
}

std::string SplitEntry::scene() const {
  const std::string d = drive();
  return d.substr(0, d.rfind("_sync"));
}

std::string SplitEntry::image_path(const std::string& root, int64_t offset) const {
  return root + "/" + folder + "/image_0" + std::to_string(camera()) + "/data/" + zero_padded(frame + offset, 10) + ".png";
}

namespace {

// A frame number: 1 to 10 decimal digits (KITTI names frames with 10).
int64_t parse_frame(const std::string& digits, const std::string& where, const std::string& line) {
  const bool ok = !digits.empty() && digits.size() <= 10 &&
                  std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (!ok) throw std::runtime_error(where + ": frame number '" + digits + "' is not 1 to 10 digits in '" + line + "'");
  return std::stoll(digits);
}

}  // namespace

SplitEntry parse_split_line(const std::string& raw, const std::string& where) {
  SplitEntry e;
  e.line = trim(raw);
  // std::regex recurses per character: a line far longer than any KITTI path is refused first.
  if (e.line.size() > 1024)
    throw std::runtime_error(where + ": line of " + std::to_string(e.line.size()) + " characters is not a split entry");
  static const std::regex path_re(R"((.+)/image_0([23])/data/(\d+)\.(png|jpg))");
  std::smatch m;
  if (std::regex_match(e.line, m, path_re)) {
    e.folder = m[1];
    e.side = m[2] == "3" ? 'r' : 'l';
    e.frame = parse_frame(m[3], where, e.line);
    return e;
  }
  std::istringstream in(e.line);
  std::string frame, side, extra;
  in >> e.folder >> frame >> side;
  const bool numeric = !frame.empty() && std::all_of(frame.begin(), frame.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (e.folder.empty() || !numeric || (side != "l" && side != "r") || (in >> extra))
    throw std::runtime_error(where + ": expected 'folder frame l|r' or '<folder>/image_02/data/"
                             "<frame>.png', got '" + e.line + "'");
  e.frame = parse_frame(frame, where, e.line);
  e.side = side[0];
  return e;
}

std::vector<SplitEntry> read_split(const std::string& path) {
  std::istringstream in(read_text_file(path));
  std::vector<SplitEntry> out;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (trim(line).empty()) continue;
    out.push_back(parse_split_line(line, path + " line " + std::to_string(line_no)));
  }
  if (out.empty()) throw std::runtime_error(path + ": the split list is empty");
  return out;
}

std::set<std::string> read_scene_list(const std::string& path) {
  auto lines = read_lines(path);
  return {lines.begin(), lines.end()};
}

std::string static_key(const std::string& drive_folder, int64_t frame) {
  return drive_folder + " " + std::to_string(frame);
}

std::set<std::string> read_static_frames(const std::string& path) {
  std::set<std::string> keys;
  int line_no = 0;
  for (const auto& line : read_lines(path)) {
    ++line_no;
    std::istringstream in(line);
    std::string date, drive, frame;
    in >> date >> drive >> frame;
    if (frame.empty() || !std::all_of(frame.begin(), frame.end(), ::isdigit))
      throw std::runtime_error(path + " entry " + std::to_string(line_no) +
                               ": expected 'date drive frame', got '" + line + "'");
    keys.insert(static_key(drive, std::stoll(frame)));
  }
  return keys;
}

size_t exclude_entries(std::vector<SplitEntry>& entries, const std::set<std::string>& test_scenes,
                       const std::set<std::string>& static_frames) {
  const size_t before = entries.size();
  entries.erase(std::remove_if(entries.begin(), entries.end(),
                               [&](const SplitEntry& e) {
                                 const std::string drive = e.drive();
                                 return test_scenes.count(e.scene()) > 0 ||
                                        static_frames.count(static_key(drive, e.frame)) > 0;
                               }),
                entries.end());
  return before - entries.size();
}

std::string find_split_file(const std::string& root, const std::string& split, const std::string& file) {
  for (const auto& base : {root + "/splits", shipped_config_dir() + "/splits"}) {
    const std::string p = base + "/" + split + "/" + file;
    if (std::filesystem::exists(p)) return p;
  }
  return "";
}

}  // namespace geo
