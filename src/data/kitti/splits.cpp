#include "data/kitti/splits.h"

#include "core/config.h"
#include "core/files.h"
#include "data/text_io.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <utility>

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
  return root + "/" + folder + "/image_0" + std::to_string(camera()) + "/data/" + zero_padded(frame_at(offset), 10) +
         ".png";
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
  const bool numeric =
      !frame.empty() && std::all_of(frame.begin(), frame.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (e.folder.empty() || !numeric || (side != "l" && side != "r") || (in >> extra))
    throw std::runtime_error(where +
                             ": expected 'folder frame l|r' or '<folder>/image_02/data/"
                             "<frame>.png', got '" +
                             e.line + "'");
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
      throw std::runtime_error(path + " entry " + std::to_string(line_no) + ": expected 'date drive frame', got '" +
                               line + "'");
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

namespace {

// <root>/<date>/<drive>_sync folders (dates as KITTI names them, YYYY_MM_DD), sorted.
std::vector<std::pair<std::string, std::string>> raw_drive_folders(const std::string& root) {
  namespace fs = std::filesystem;
  static const std::regex date_re(R"(\d{4}_\d{2}_\d{2})");
  std::vector<std::pair<std::string, std::string>> out;  // (date, drive folder name)
  std::error_code ec;
  for (const auto& d : fs::directory_iterator(root, ec)) {
    const std::string date = d.path().filename().string();
    if (!d.is_directory() || !std::regex_match(date, date_re)) continue;
    for (const auto& r : fs::directory_iterator(d.path(), ec)) {
      const std::string drive = r.path().filename().string();
      if (r.is_directory() && drive.size() > 5 && drive.compare(drive.size() - 5, 5, "_sync") == 0)
        out.emplace_back(date, drive);
    }
  }
  if (ec) throw std::runtime_error("cannot list the KITTI raw folder '" + root + "': " + ec.message());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

std::set<std::string> raw_drives_on_disk(const std::string& root, const std::set<std::string>& test_scenes) {
  std::set<std::string> out;
  for (const auto& [date, drive] : raw_drive_folders(root)) {
    const std::string scene = drive.substr(0, drive.size() - 5);
    if (!test_scenes.count(scene)) out.insert(scene);
  }
  return out;
}

std::vector<SplitEntry> raw_drive_snippets(const std::string& root, const std::set<std::string>& test_scenes,
                                           const std::set<std::string>& static_frames, int64_t seq_length) {
  namespace fs = std::filesystem;
  if (seq_length < 3 || seq_length % 2 == 0)
    throw std::invalid_argument("seq_length must be odd and >= 3, got " + std::to_string(seq_length));
  static const std::regex frame_re(R"((\d{1,10})\.png)");
  const int64_t half = seq_length / 2;
  std::vector<SplitEntry> out;
  for (const auto& [date, drive] : raw_drive_folders(root)) {
    if (test_scenes.count(drive.substr(0, drive.size() - 5))) continue;
    for (const char side : {'l', 'r'}) {
      const fs::path dir = fs::path(root) / date / drive / (side == 'l' ? "image_02" : "image_03") / "data";
      std::vector<int64_t> frames;
      std::error_code ec;
      for (const auto& f : fs::directory_iterator(dir, ec)) {
        std::smatch m;
        const std::string name = f.path().filename().string();
        if (!std::regex_match(name, m, frame_re)) continue;
        const int64_t frame = std::stoll(m[1]);
        if (!static_frames.count(static_key(drive, frame))) frames.push_back(frame);
      }
      std::sort(frames.begin(), frames.end());
      for (size_t t = static_cast<size_t>(half); t + static_cast<size_t>(half) < frames.size(); ++t) {
        SplitEntry e;
        e.folder = date + "/" + drive;
        e.frame = frames[t];
        e.side = side;
        e.snippet.assign(frames.begin() + static_cast<std::ptrdiff_t>(t - static_cast<size_t>(half)),
                         frames.begin() + static_cast<std::ptrdiff_t>(t + static_cast<size_t>(half) + 1));
        e.line = e.folder + " " + std::to_string(e.frame) + " " + side;
        out.push_back(std::move(e));
      }
    }
  }
  return out;
}

std::string find_split_file(const std::string& root, const std::string& split, const std::string& file) {
  for (const auto& base : {root + "/splits", shipped_config_dir() + "/splits"}) {
    const std::string p = base + "/" + split + "/" + file;
    if (std::filesystem::exists(p)) return p;
  }
  return "";
}

bool in_geonet_validation(const SplitEntry& e) {
  uint64_t h = 1469598103934665603ull;  // FNV-1a, 64 bits
  const std::string key = e.folder + " " + std::to_string(e.frame) + " " + e.side;
  for (const unsigned char c : key) h = (h ^ c) * 1099511628211ull;
  h ^= h >> 33, h *= 0xff51afd7ed558ccdull, h ^= h >> 33;  // mix the low bits of short keys into the high ones
  return static_cast<double>(h >> 11) * 0x1.0p-53 < 0.1;
}

}  // namespace geo
