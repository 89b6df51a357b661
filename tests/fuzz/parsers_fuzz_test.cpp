// Seeded mutation fuzzing of every reader of outside data: calibration, split and scene lists, pose
// files, Velodyne scans, KITTI image/flow/depth PNGs, the packed cache, .npy predictions and YAML
// configs. Each mutated input must either parse or be rejected with a std::runtime_error whose
// message names the file; a crash, a hang, a raw LibTorch error (c10::Error), a standard-library
// logic error (std::out_of_range from stoll, ...) or any other exception fails the test.
//
// In the normal suite every target runs GEO_FUZZ_ITERATIONS inputs (default 150). CI's sanitizer job
// (scripts/fuzz.sh) builds this file with AddressSanitizer and UBSan and runs each target for
// GEO_FUZZ_SECONDS seconds, so an out-of-bounds read or undefined behaviour aborts the run.
// A failing input is written to GEO_FUZZ_FAILURES (default: fuzz-failures/ in the working folder)
// and is reproduced by the same GEO_FUZZ_SEED and iteration.
#include "core/config.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/packed/packed.h"
#include "data/kitti/splits.h"
#include "data/text_io.h"
#include "data/kitti/velodyne_depth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <random>
#include <typeinfo>

#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

int64_t env_int(const char* name, int64_t fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::strtoll(v, nullptr, 10) : fallback;
}

// Tokens that reach the corners of number and structure parsing.
const std::vector<std::string>& text_dictionary() {
  static const std::vector<std::string> d = {"nan",
                                             "-nan",
                                             "inf",
                                             "-inf",
                                             "1e309",
                                             "-1e309",
                                             "1e-320",
                                             "0",
                                             "-0",
                                             "-1",
                                             "99999999999999999999",
                                             "-9223372036854775808",
                                             "0x1p3",
                                             "1,5",
                                             ".",
                                             "e",
                                             ":",
                                             " ",
                                             "\t",
                                             "\n",
                                             "\r\n",
                                             "#",
                                             "'",
                                             "\"",
                                             "[",
                                             "]",
                                             "{",
                                             "}",
                                             ",",
                                             "&a",
                                             "*a",
                                             "<<: *a",
                                             "!!binary",
                                             "~",
                                             "null",
                                             "- ",
                                             "? ",
                                             "|",
                                             ">",
                                             "%YAML 1.2\n",
                                             "---\n",
                                             "P_rect_02:",
                                             "R_rect_00:",
                                             "S_rect_02:",
                                             "R:",
                                             "T:",
                                             "Tr:",
                                             "P2:",
                                             "calib_time:",
                                             "image_02/data/",
                                             "0000000001.png",
                                             " l",
                                             " r",
                                             "geo-packed 1",
                                             "geo-packed 2",
                                             "height ",
                                             "width ",
                                             "seq_length ",
                                             "count ",
                                             "pack ",
                                             "'descr': '<f4'",
                                             "'descr': '<f8'",
                                             "'fortran_order': True",
                                             "'fortran_order':True",
                                             "'shape': (",
                                             ")",
                                             "stages:",
                                             "iterations: ",
                                             "data:",
                                             "model:",
                                             "encoder_depth: ",
                                             std::string(1, '\0'),
                                             std::string(300, '9'),
                                             std::string(2000, '[')};
  return d;
}

class Mutator {
 public:
  explicit Mutator(uint64_t seed) : rng_(seed) {}

  std::string mutate(const std::vector<std::string>& seeds) {
    std::string s = seeds[pick(seeds.size())];
    const int n = 1 + static_cast<int>(pick(4));
    for (int k = 0; k < n; ++k) step(s, seeds);
    // PNGs: half the time the chunk checksums are made right again, so that mutated headers
    // (size, bit depth, colour type) reach the decoder and geo's checks instead of a CRC error.
    if (s.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0 && pick(2) == 0) fix_png_crcs(s);
    return s;
  }

 private:
  size_t pick(size_t n) { return n == 0 ? 0 : std::uniform_int_distribution<size_t>(0, n - 1)(rng_); }

  void step(std::string& s, const std::vector<std::string>& seeds) {
    static const char interesting[] = {0, 1, '\x7f', '\x80', '\xff', '\n', ' ', '-', '.', 'e', ':', '9'};
    const auto& dict = text_dictionary();
    switch (pick(9)) {
      case 0:  // flip a bit
        if (!s.empty()) s[pick(s.size())] ^= static_cast<char>(1u << pick(8));
        break;
      case 1:  // an interesting byte
        if (!s.empty()) s[pick(s.size())] = interesting[pick(sizeof interesting)];
        break;
      case 2: {  // delete a range
        if (s.empty()) break;
        const size_t at = pick(s.size());
        s.erase(at, 1 + pick(std::min<size_t>(s.size() - at, 64)));
        break;
      }
      case 3: {  // insert random bytes
        std::string r(1 + pick(16), '\0');
        for (auto& c : r) c = static_cast<char>(pick(256));
        s.insert(pick(s.size() + 1), r);
        break;
      }
      case 4: {  // duplicate a range
        if (s.empty()) break;
        const size_t at = pick(s.size());
        const std::string chunk = s.substr(at, 1 + pick(256));
        s.insert(pick(s.size() + 1), chunk);
        break;
      }
      case 5:  // truncate
        s.resize(pick(s.size() + 1));
        break;
      case 6: {  // replace a token (up to the next blank) by a dictionary entry
        if (s.empty()) break;
        const size_t at = pick(s.size());
        const size_t end = s.find_first_of(" \t\n", at);
        s.replace(at, (end == std::string::npos ? s.size() : end) - at, dict[pick(dict.size())]);
        break;
      }
      case 7:  // insert a dictionary entry
        s.insert(pick(s.size() + 1), dict[pick(dict.size())]);
        break;
      default: {  // splice with another seed
        const std::string& other = seeds[pick(seeds.size())];
        const size_t a = pick(s.size() + 1), b = pick(other.size() + 1);
        s = s.substr(0, a) + other.substr(b);
        break;
      }
    }
  }

  static uint32_t crc32(const char* data, size_t n) {
    uint32_t c = 0xffffffffu;
    for (size_t i = 0; i < n; ++i) {
      c ^= static_cast<unsigned char>(data[i]);
      for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return c ^ 0xffffffffu;
  }

  static void fix_png_crcs(std::string& s) {
    size_t at = 8;
    while (at + 12 <= s.size()) {
      uint32_t len = 0;
      for (int k = 0; k < 4; ++k) len = len << 8 | static_cast<unsigned char>(s[at + static_cast<size_t>(k)]);
      if (len > s.size() - at - 12) break;
      const uint32_t crc = crc32(s.data() + at + 4, len + 4);
      for (int k = 0; k < 4; ++k) s[at + 8 + len + static_cast<size_t>(k)] = static_cast<char>(crc >> (24 - 8 * k));
      at += 12 + len;
    }
  }

  std::mt19937_64 rng_;
};

struct FuzzStats {
  int64_t parsed = 0, rejected = 0;
};

// Runs `parse(path)` on mutated inputs written to `path`. `named` is what every error message must
// contain (the file, or for folder readers the folder).
FuzzStats fuzz(const std::string& target, const std::vector<std::string>& seeds, const std::string& path,
               const std::string& named, const std::function<void(const std::string&)>& parse,
               size_t valid_seeds = SIZE_MAX) {
  const uint64_t seed = static_cast<uint64_t>(env_int("GEO_FUZZ_SEED", 20261123));
  const int64_t iterations = env_int("GEO_FUZZ_ITERATIONS", 150);
  const double seconds = static_cast<double>(env_int("GEO_FUZZ_SECONDS", 0));
  const char* failures_env = std::getenv("GEO_FUZZ_FAILURES");
  const std::string failures = fs::absolute(failures_env ? failures_env : "fuzz-failures").string();
  Mutator m(seed ^ std::hash<std::string>{}(target));
  FuzzStats stats;
  const auto start = std::chrono::steady_clock::now();
  int failed = 0;
  for (int64_t i = 0;; ++i) {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (seconds > 0 ? elapsed >= seconds : i >= iterations) break;
    // The unmutated seeds first (the first `valid_seeds` of them): each must parse.
    const bool original = i < static_cast<int64_t>(std::min(seeds.size(), valid_seeds));
    const std::string input = original ? seeds[static_cast<size_t>(i)] : m.mutate(seeds);
    test::write_text(path, input);
    std::string problem;
    try {
      parse(path);
      ++stats.parsed;
    } catch (const c10::Error& e) {
      problem = std::string("raw LibTorch error: ") + e.what_without_backtrace();
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      if (original) problem = "an unmutated seed was rejected: " + msg;
      else if (msg.find(named) == std::string::npos) problem = "the message does not name '" + named + "': " + msg;
      else ++stats.rejected;
    } catch (const std::exception& e) {
      problem = std::string("not a geo error (") + typeid(e).name() + "): " + e.what();
    }
    if (!problem.empty() && failed++ < 5) {
      fs::create_directories(failures);
      const std::string saved = failures + "/" + target + "-" + std::to_string(i) + fs::path(path).extension().string();
      test::write_text(saved, input);
      ADD_FAILURE() << target << " input " << i << " (GEO_FUZZ_SEED " << seed << ", saved as " << saved
                    << "): " << problem.substr(0, 600);
    }
  }
  std::printf("fuzz %-10s %6lld inputs: %lld parsed, %lld rejected with a message naming the file\n", target.c_str(),
              static_cast<long long>(stats.parsed + stats.rejected), static_cast<long long>(stats.parsed),
              static_cast<long long>(stats.rejected));
  if (failed > 5) ADD_FAILURE() << target << ": " << failed << " failing inputs in all (5 shown)";
  return stats;
}

// Seeds: the real file from ../shared/kitti_samples when present, then synthetic ones.
std::vector<std::string> with_sample(const std::string& relative, std::vector<std::string> seeds) {
  const std::string root = test::kitti_samples();
  if (!root.empty() && fs::exists(root + "/" + relative))
    seeds.insert(seeds.begin(), test::read_file(root + "/" + relative));
  return seeds;
}

const char* kCamToCam =
    "calib_time: 09-Jan-2012 13:57:47\n"
    "S_rect_02: 1.242000e+03 3.750000e+02\n"
    "R_rect_00: 1 0 0 0 1 0 0 0 1\n"
    "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 1.728540e+02 "
    "2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n";
const char* kVeloToCam =
    "calib_time: 15-Mar-2012 11:37:16\n"
    "R: 7.533745e-03 -9.999714e-01 -6.166020e-04 1.480249e-02 7.280733e-04 -9.998902e-01 9.998621e-01 "
    "7.523790e-03 1.480755e-02\n"
    "T: -4.069766e-03 -7.631618e-02 -2.717806e-01\n";

TEST(Fuzz, RawCalibration) {
  const auto dir = test::fresh_dir("fuzz_calib");
  const auto cam = with_sample("raw/2011_09_26/calib_cam_to_cam.txt", {kCamToCam});
  const auto velo = with_sample("raw/2011_09_26/calib_velo_to_cam.txt", {kVeloToCam});
  test::write_text(dir + "/calib_velo_to_cam.txt", velo.back());
  fuzz("cam_to_cam", cam, dir + "/calib_cam_to_cam.txt", dir, [&](const std::string&) {
    const auto c = read_raw_calib(dir, 2);
    (void)c.img_from_velo();
  });
  test::write_text(dir + "/calib_cam_to_cam.txt", cam.back());
  fuzz("velo_to_cam", velo, dir + "/calib_velo_to_cam.txt", dir,
       [&](const std::string&) { (void)read_raw_calib(dir, 2).img_from_velo(); });
}

TEST(Fuzz, OdometryCalibration) {
  const auto dir = test::fresh_dir("fuzz_odocalib");
  std::string seed;
  for (int k = 0; k < 4; ++k)
    seed += "P" + std::to_string(k) + ": 7.07e+02 0 6.01e+02 " + std::to_string(-k * 100) +
            " 0 7.07e+02 1.83e+02 0 0 0 1 0\n";
  seed += "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 -0.27\n";
  fuzz("odo_calib", {seed}, dir + "/calib.txt", dir + "/calib.txt",
       [](const std::string& p) { (void)read_odometry_calib(p); });
}

TEST(Fuzz, SplitAndSceneLists) {
  const auto dir = test::fresh_dir("fuzz_splits");
  const auto seeds =
      with_sample("splits/eigen/test_files.txt",
                  {"2011_09_26/2011_09_26_drive_0001_sync 5 l\n2011_09_26/2011_09_26_drive_0001_sync 6 r\n",
                   "2011_09_26/2011_09_26_drive_0002_sync/image_02/data/0000000069.png\n"});
  // The real list is long: its first lines are enough to seed.
  std::vector<std::string> short_seeds;
  for (const auto& s : seeds) short_seeds.push_back(s.substr(0, 2000).substr(0, s.substr(0, 2000).rfind('\n') + 1));
  fuzz("split", short_seeds, dir + "/files.txt", dir + "/files.txt", [](const std::string& p) { (void)read_split(p); });
  fuzz("scenes", {"2011_09_26_drive_0002\n2011_09_26_drive_0009\n"}, dir + "/scenes.txt", dir + "/scenes.txt",
       [](const std::string& p) { (void)read_scene_list(p); });
}

TEST(Fuzz, PoseFiles) {
  const auto dir = test::fresh_dir("fuzz_poses");
  auto seeds = with_sample("odometry/poses/09.txt", {});
  if (!seeds.empty()) seeds[0] = seeds[0].substr(0, seeds[0].find('\n', 3000) + 1);  // 30 poses
  auto poses = torch::eye(4, torch::kFloat64).repeat({3, 1, 1});
  poses[1][0][3] = 1.5;
  write_poses(dir + "/seed.txt", poses);
  seeds.push_back(test::read_file(dir + "/seed.txt"));
  fuzz("poses", seeds, dir + "/poses.txt", dir + "/poses.txt", [](const std::string& p) { (void)read_poses(p); });
}

TEST(Fuzz, VelodyneScans) {
  const auto dir = test::fresh_dir("fuzz_velo");
  const auto pts = torch::tensor({5.f, 1.f, 1.f, 0.1f, 20.f, -3.f, 0.5f, 0.2f, -4.f, 0.f, 0.f, 0.f}).view({3, 4});
  write_velodyne(dir + "/seed.bin", pts);
  const auto P = torch::tensor({0.0, -700.0, 0.0, 600.0, 0.0, 0.0, -700.0, 170.0, 1.0, 0.0, 0.0, 0.0}, torch::kFloat64)
                     .view({3, 4});
  fuzz("velodyne", {test::read_file(dir + "/seed.bin")}, dir + "/scan.bin", dir + "/scan.bin",
       [&](const std::string& p) {
         const auto points = read_velodyne(p);
         (void)count_non_finite_points(points);
         (void)velodyne_depth(points, P, 375, 1242);
       });
}

TEST(Fuzz, KittiPngs) {
  const auto dir = test::fresh_dir("fuzz_png");
  write_flow_png(dir + "/seed_flow.png", torch::randn({2, 5, 7}) * 10, torch::ones({1, 5, 7}));
  write_depth_png(dir + "/seed_depth.png", torch::rand({1, 5, 7}) * 80);
  write_image(dir + "/seed_image.png", torch::rand({3, 5, 7}));
  // Every reader gets every kind (16-bit RGB, 16-bit grey, 8-bit RGB): wrong kinds must be named.
  const std::vector<std::string> kinds = {test::read_file(dir + "/seed_flow.png"),
                                          test::read_file(dir + "/seed_depth.png"),
                                          test::read_file(dir + "/seed_image.png")};
  auto kinds_with = [&](const std::string& first) {
    auto k = kinds;
    std::rotate(k.begin(), k.begin() + static_cast<long>(std::find(k.begin(), k.end(), first) - k.begin()), k.end());
    return k;
  };
  // Only the first seed must be accepted as it is (valid_seeds 1).
  const auto flow = with_sample("flow2012/training/flow_noc/000157_10.png", kinds_with(kinds[0]));
  fuzz(
      "flow_png", flow, dir + "/flow.png", dir + "/flow.png", [](const std::string& p) { (void)read_flow_png(p); }, 1);
  fuzz(
      "depth_png", kinds_with(kinds[1]), dir + "/depth.png", dir + "/depth.png",
      [](const std::string& p) { (void)read_depth_png(p); }, 1);
  fuzz(
      "image_png", kinds_with(kinds[2]), dir + "/image.png", dir + "/image.png",
      [](const std::string& p) { (void)read_image_resized(p, 4, 6); }, 1);
}

TEST(Fuzz, PackedCacheIndex) {
  const auto dir = test::fresh_dir("fuzz_packed") + "/cache";
  PackedWriter w(dir, 4, 6, 3);
  for (int k = 0; k < 2; ++k) {
    Snippet s;
    s.frames = torch::rand({3, 3, 4, 6});
    s.K = torch::tensor({5.f, 0.f, 3.f, 0.f, 5.f, 2.f, 0.f, 0.f, 1.f}).view({3, 3});
    s.id = "drive " + std::to_string(k);
    w.add(s);
  }
  w.finish();
  fuzz("packed", {test::read_file(dir + "/index.txt")}, dir + "/index.txt", dir, [&](const std::string&) {
    PackedSnippets p(dir);
    for (size_t i = 0; i < p.size(); ++i) (void)p.get(i);
  });
}

TEST(Fuzz, NpyPredictions) {
  const auto dir = test::fresh_dir("fuzz_npy");
  auto npy = [](const std::string& descr, const std::string& shape, size_t bytes) {
    return test::npy_bytes("{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + shape + ", }",
                           std::string(bytes, '\x01'));
  };
  fuzz("npy", {npy("<f4", "(2, 3, 4)", 96), npy("<f8", "(3,)", 24)}, dir + "/pred.npy", dir + "/pred.npy",
       [](const std::string& p) { (void)read_npy(p); });
}

TEST(Fuzz, YamlConfigs) {
  const auto dir = test::fresh_dir("fuzz_yaml");
  std::vector<std::string> seeds;
  for (const auto& e : fs::directory_iterator(shipped_config_dir()))
    if (e.path().extension() == ".yaml") {
      // video.yaml leaves the clips to the command line (data.videos=[...]); a seed names one.
      auto text = test::read_file(e.path().string());
      const auto at = text.find("videos: []");
      if (at != std::string::npos) text.replace(at, 10, "videos: [drive.mp4]");
      seeds.push_back(text);
    }
  std::sort(seeds.begin(), seeds.end());
  // Anchors and aliases, as users write them to share values between stages.
  seeds.push_back(
      "stages:\n  - {name: a, iterations: &n 3, batch_size: 1, train: &t [depth, pose]}\n"
      "  - {name: b, iterations: *n, batch_size: 1, train: *t}\n");
  fuzz("yaml", seeds, dir + "/config.yaml", dir + "/config.yaml", [](const std::string& p) { (void)load_config(p); });
}

}  // namespace
}  // namespace geo
