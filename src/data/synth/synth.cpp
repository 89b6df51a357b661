#include "data/synth/synth.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <stdexcept>
#include <thread>

namespace geo {
namespace {

Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 operator*(double s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 normalized(Vec3 a) { return (1.0 / std::sqrt(dot(a, a))) * a; }
Vec3 rotate(const std::array<double, 9>& R, Vec3 v) {
  return {R[0] * v.x + R[1] * v.y + R[2] * v.z, R[3] * v.x + R[4] * v.y + R[5] * v.z,
          R[6] * v.x + R[7] * v.y + R[8] * v.z};
}
Vec3 rotate_transposed(const std::array<double, 9>& R, Vec3 v) {
  return {R[0] * v.x + R[3] * v.y + R[6] * v.z, R[1] * v.x + R[4] * v.y + R[7] * v.z,
          R[2] * v.x + R[5] * v.y + R[8] * v.z};
}

// LiDAR mounting (KITTI-like): camera = R_cv * velo + T_cv; the scanner is 8 cm above and 27 cm
// behind the camera, x forward / y left / z up.
const std::array<double, 9> kCamFromVeloR{0, -1, 0, 0, 0, -1, 1, 0, 0};
const Vec3 kCamFromVeloT{0.0, -0.08, -0.27};

uint64_t mix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ULL;
  h ^= h >> 33;
  return h;
}
double lattice(int64_t x, int64_t y, int64_t z, uint64_t seed) {
  const uint64_t h = mix(static_cast<uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^
                         mix(static_cast<uint64_t>(y) * 0xC2B2AE3D27D4EB4FULL ^
                             mix(static_cast<uint64_t>(z) * 0x165667B19E3779F9ULL ^ seed)));
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}
double fade(double t) { return t * t * (3 - 2 * t); }
// Smooth value noise in [0,1].
double value_noise(Vec3 p, uint64_t seed) {
  const double fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
  const int64_t ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy), iz = static_cast<int64_t>(fz);
  const double tx = fade(p.x - fx), ty = fade(p.y - fy), tz = fade(p.z - fz);
  double acc = 0;
  for (int dz = 0; dz < 2; ++dz)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx)
        acc += (dx ? tx : 1 - tx) * (dy ? ty : 1 - ty) * (dz ? tz : 1 - tz) * lattice(ix + dx, iy + dy, iz + dz, seed);
  return acc;
}
// Three octaves, wavelengths 4, 1.6 and 0.64 m times `scale`; result in [0,1].
double fbm(Vec3 p, double scale, uint64_t seed) {
  double freq = 1.0 / (4.0 * scale), amp = 0.5, sum = 0;
  for (int o = 0; o < 3; ++o) {
    sum += amp * value_noise(freq * p, seed + 977 * o);
    freq *= 2.5;
    amp = o == 0 ? 0.3 : 0.2;
  }
  return sum;
}
double frac(double x) { return x - std::floor(x); }

void parallel_rows(int64_t rows, int threads, const std::function<void(int64_t, int64_t)>& fn) {
  int n = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  n = static_cast<int>(std::min<int64_t>(n, rows));
  std::vector<std::thread> pool;
  for (int i = 0; i < n; ++i) pool.emplace_back(fn, rows * i / n, rows * (i + 1) / n);
  for (auto& t : pool) t.join();
}

}  // namespace

std::string synth_drive_folder(int drive) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_drive_%04d_sync", drive);
  return std::string(kSynthDate) + "/" + kSynthDate + buf;
}

uint64_t synth_drive_seed(uint64_t seed, int kind, int64_t index) {
  return seed * 1000003ULL + static_cast<uint64_t>(kind) * 7919ULL + static_cast<uint64_t>(index);
}

std::string synth_snippet_id(int drive_index, int64_t frame) {
  return synth_drive_folder(drive_index + 1) + " " + std::to_string(frame) + " l";
}

torch::Tensor SynthIntrinsics::K() const {
  return torch::tensor({fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0}, torch::kFloat64).reshape({3, 3});
}

SynthOptions SynthOptions::preset_named(const std::string& name) {
  SynthOptions o;
  o.preset = name;
  if (name == "tiny") {
    // KITTI's intrinsics scaled to 64x208 (fx 721.5377 * 208/1242, ...).
    o.height = 64;
    o.width = 208;
    o.intrinsics = {721.5377 * 208 / 1242, 721.5377 * 64 / 375, 609.5593 * 208 / 1242, 172.854 * 64 / 375};
    o.lidar_beams = 32;  // a sparser scan keeps the tiny world small
    o.lidar_azimuth_step_deg = 1.0;
  } else if (name == "kitti") {
    o.height = 375;
    o.width = 1242;
    o.intrinsics = {721.5377, 721.5377, 609.5593, 172.854};  // KITTI 2011_09_26 P_rect_02
    o.supersample = 2;
    o.train_drives = 4;
    o.frames_per_drive = 100;
    o.flow_pairs = 40;
    o.odometry_frames = 200;
  } else {
    throw std::invalid_argument("unknown synthetic preset '" + name + "' (valid: tiny, kitti)");
  }
  return o;
}

torch::Tensor RigidPose::matrix() const {
  auto m = torch::eye(4, torch::kFloat64);
  auto a = m.accessor<double, 2>();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a[r][c] = R[r * 3 + c];
  a[0][3] = c.x;
  a[1][3] = c.y;
  a[2][3] = c.z;
  return m;
}

SynthScene::SynthScene(uint64_t seed, int64_t frames, double turns, bool traffic) : seed_(seed) {
  if (!(turns > 0 && turns <= 10))
    throw std::invalid_argument("synthetic world: turns must be in (0, 10], got " + std::to_string(turns));
  std::mt19937_64 rng(mix(seed + 12345));
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  speed_ = U(0.8, 1.2);  // metres per frame (KITTI: about 1 m at 10 Hz)
  sway_amp_ = U(0.4, 1.0);
  sway_period_ = U(40, 80) / turns;
  sway_phase_ = U(0, 2 * M_PI);
  // Traffic: stretches of 6-14 frames standing and 8-16 moving (the first and last moving frame at
  // half speed), from a random start, a little past the last frame; city lane keeping sways less.
  std::vector<std::pair<int64_t, int64_t>> stands;  // [first, last] frames equal to the frame before
  if (traffic) {
    sway_amp_ *= 0.3;
    bool standing = U(0, 1) < 0.5;
    travel_.push_back(0);
    while (static_cast<int64_t>(travel_.size()) < frames + 64) {
      const auto n = static_cast<int64_t>(std::llround(standing ? U(6, 14) : U(8, 16)));
      if (standing)
        stands.emplace_back(static_cast<int64_t>(travel_.size()), static_cast<int64_t>(travel_.size()) + n - 1);
      for (int64_t i = 0; i < n; ++i)
        travel_.push_back(travel_.back() + (standing ? 0 : (i == 0 || i == n - 1 ? 0.5 : 1.0) * speed_));
      standing = !standing;
    }
  }
  const double h = kCameraHeight;
  const double z_end = travel(frames) + 90;
  auto colour = [&](double lo, double hi) {
    return std::array<float, 3>{float(U(lo, hi)), float(U(lo, hi)), float(U(lo, hi))};
  };
  auto add = [&](Vec3 lo, Vec3 hi, int material, std::array<float, 3> c, Vec3 v = {}) {
    SynthBox b;
    b.lo = lo;
    b.hi = hi;
    b.material = material;
    b.colour = c;
    b.velocity = v;
    b.texture_scale = U(0.7, 1.3);
    boxes_.push_back(b);
  };
  for (int side : {-1, 1}) {
    for (double z = -30; z < z_end;) {  // facades with occasional gaps
      const double len = U(8, 25), setback = U(6.5, 11), height = U(4, 14);
      const double x0 = side > 0 ? setback : -setback - 3, x1 = x0 + 3;
      add({x0, h - height, z}, {x1, h, z + len}, 1, colour(0.35, 0.9));
      z += len + (U(0, 1) < 0.25 ? U(3, 8) : 0.3);
    }
    for (double z = U(0, 10); z < z_end; z += U(8, 18)) {  // poles
      const double x = side * U(4.2, 5.5), height = U(3.5, 6);
      add({x - 0.15, h - height, z - 0.15}, {x + 0.15, h, z + 0.15}, 2, colour(0.2, 0.8));
    }
    for (double z = U(5, 15); z < z_end; z += U(10, 25)) {  // boxes (beyond the overtaking lane in traffic)
      const double s = U(0.8, 2.0), x = side * U(3.5, 5.0) + (traffic && side > 0 ? 1.5 : 0.0), height = U(0.8, 2.5);
      add({x - s / 2, h - height, z - s / 2}, {x + s / 2, h, z + s / 2}, 3, colour(0.15, 0.95));
    }
  }
  if (!traffic) {
    for (double z = U(10, 20); z < z_end - 20; z += U(18, 30)) {  // cars: oncoming left, ahead right
      const bool oncoming = U(0, 1) < 0.5;
      const double x = oncoming ? -3.2 : 3.2, v = oncoming ? -U(0.3, 1.0) : U(0.2, 0.7);
      add({x - 0.9, h - 1.5, z}, {x + 0.9, h, z + 4.2}, 4, colour(0.1, 0.95), {0, 0, v});
    }
  } else {
    // Oncoming cars on the left all along the drive (they keep coming while the camera stands).
    const double reach = z_end + static_cast<double>(frames);
    for (double z = U(5, 15); z < reach; z += U(10, 20))
      add({-4.1, h - 1.5, z}, {-2.3, h, z + 4.2}, 4, colour(0.1, 0.95), {0, 0, -U(0.5, 1.2)});
    // The car ahead in the camera's lane, 7-11 m ahead, moving with the camera.
    const double gap = U(7, 11);
    add({-0.9, h - 1.5, gap}, {0.9, h, gap + 4.2}, 4, colour(0.1, 0.95));
    boxes_.back().follows_camera = true;
    // A truck overtaking on the right in the middle of every stretch the camera stands, its front
    // 2-8 m ahead of the camera then.
    for (const auto& [first, last] : stands) {
      if (first >= frames) break;
      const double mid = 0.5 * static_cast<double>(first + last), v = U(0.7, 1.1), len = U(9, 12);
      const double front = travel(first) + U(2, 8), z0 = front - len - v * mid;
      add({1.5, h - U(3.2, 3.8), z0}, {4.0, h, z0 + len}, 4, colour(0.2, 0.95), {0, 0, v});
    }
  }
  add({-300, h - 80, z_end}, {300, h, z_end + 1}, 5, colour(0.45, 0.75));  // distant backdrop
}

double SynthScene::travel(int64_t frame) const {
  const auto n = static_cast<int64_t>(travel_.size());
  if (frame < 0 || n == 0) return speed_ * static_cast<double>(frame);
  if (frame < n) return travel_[static_cast<size_t>(frame)];
  return travel_.back() + speed_ * static_cast<double>(frame - n + 1);  // past the schedule: driving on
}

bool SynthScene::is_moving(int id) const {
  if (id < 0) return false;
  const auto& b = boxes_[static_cast<size_t>(id)];
  return b.follows_camera || b.velocity.x != 0 || b.velocity.y != 0 || b.velocity.z != 0;
}

Vec3 SynthScene::offset(int id, int64_t frame) const {
  const auto& b = boxes_[static_cast<size_t>(id)];
  Vec3 d = static_cast<double>(frame) * b.velocity;
  if (b.follows_camera) d.z += travel(frame);
  return d;
}

RigidPose SynthScene::camera(int64_t frame) const {
  // The sway is a function of the road driven (frames at the mean speed): a standing camera neither
  // moves nor turns.
  const double t = travel_.empty() ? static_cast<double>(frame) : travel(frame) / speed_;
  const double w = 2 * M_PI / sway_period_;
  const double x = sway_amp_ * std::sin(w * t + sway_phase_);
  const double dx = sway_amp_ * w * std::cos(w * t + sway_phase_);
  const double yaw = std::atan2(dx, speed_);  // heading along the path's tangent
  RigidPose p;
  const double c = std::cos(yaw), s = std::sin(yaw);
  p.R = {c, 0, s, 0, 1, 0, -s, 0, c};
  p.c = {x, 0, travel_.empty() ? speed_ * t : travel(frame)};
  return p;
}

SynthScene::Hit SynthScene::cast(const Vec3& o, const Vec3& d, int64_t frame, double t_max) const {
  Hit best;
  best.t = t_max;
  if (d.y > 1e-12) {  // ground plane y = camera height
    const double t = (kCameraHeight - o.y) / d.y;
    if (t > 1e-6 && t < best.t) {
      best.t = t;
      best.id = -1;
      best.normal = {0, -1, 0};
    }
  }
  for (size_t i = 0; i < boxes_.size(); ++i) {
    const auto& b = boxes_[i];
    const Vec3 shift = offset(static_cast<int>(i), frame), lo = b.lo + shift, hi = b.hi + shift;
    double t0 = 1e-6, t1 = best.t;
    int axis = -1;
    double sign = 0;
    const double os[3] = {o.x, o.y, o.z}, ds[3] = {d.x, d.y, d.z};
    const double los[3] = {lo.x, lo.y, lo.z}, his[3] = {hi.x, hi.y, hi.z};
    bool miss = false;
    for (int a = 0; a < 3 && !miss; ++a) {
      if (std::abs(ds[a]) < 1e-15) {
        miss = os[a] < los[a] || os[a] > his[a];
        continue;
      }
      const double inv = 1.0 / ds[a];
      double ta = (los[a] - os[a]) * inv, tb = (his[a] - os[a]) * inv;
      double s = -1;
      if (ta > tb) {
        std::swap(ta, tb);
        s = 1;
      }
      if (ta > t0) {
        t0 = ta;
        axis = a;
        sign = s;
      }
      t1 = std::min(t1, tb);
      miss = t0 > t1;
    }
    if (miss || axis < 0 || t0 >= best.t) continue;  // axis < 0: origin inside the box
    best.t = t0;
    best.id = static_cast<int>(i);
    best.normal = {axis == 0 ? sign : 0, axis == 1 ? sign : 0, axis == 2 ? sign : 0};
  }
  if (best.id == -2) return best;
  best.point = o + best.t * d;
  return best;
}

Vec3 SynthScene::move(const Vec3& p, int id, int64_t frame, int64_t df) const {
  if (id < 0) return p;
  const auto& b = boxes_[static_cast<size_t>(id)];
  Vec3 q = p + static_cast<double>(df) * b.velocity;
  if (b.follows_camera) q.z += travel(frame + df) - travel(frame);
  return q;
}

std::array<float, 3> SynthScene::shade(const Hit& hit, int64_t frame) const {
  if (hit.id == -2) return {0.62f, 0.75f, 0.92f};  // sky
  const Vec3 light = normalized({-0.3, -1.0, -0.5});
  const double lambert = 0.55 + 0.45 * std::max(0.0, dot(hit.normal, light));
  Vec3 p = hit.point;
  double r, g, b;
  if (hit.id == -1) {  // road: asphalt, dashed lane marks, pavement beyond |x| > 6
    const double n = fbm(p, 0.8, seed_ + 1);
    double v = 0.25 + 0.3 * n;
    const double lane = std::min(std::abs(p.x - 1.8), std::abs(p.x + 1.8));
    if (lane < 0.08 && frac(p.z / 6.0) < 0.5) v = 0.85;
    if (std::abs(p.x) > 6) v = 0.45 + 0.3 * n;
    r = v;
    g = v;
    b = v * (std::abs(p.x) > 6 ? 0.85 : 1.05);
  } else {
    const SynthBox& box = boxes_[hit.id];
    p = p - offset(hit.id, frame);  // texture lives in the object's frame
    const double n = fbm(p, box.texture_scale, seed_ + 31 * hit.id);
    double k = 0.55 + 0.6 * n;
    const double up = kCameraHeight - p.y;  // height above the road
    if (box.material == 1 && std::abs(hit.normal.x) > 0.5 && up > 1.0 && frac(p.z / 3.0) > 0.3 &&
        frac(p.z / 3.0) < 0.8 && frac(up / 3.0) > 0.35 && frac(up / 3.0) < 0.8)
      k *= 0.35;                                               // windows
    if (box.material == 2 && frac(up / 0.6) < 0.5) k *= 0.55;  // striped poles
    if (box.material == 4 && up > 0.9) k *= 0.45;              // car windows
    r = box.colour[0] * k;
    g = box.colour[1] * k;
    b = box.colour[2] * k;
  }
  auto clamp = [](double x) { return static_cast<float>(std::min(1.0, std::max(0.0, x))); };
  return {clamp(r * lambert), clamp(g * lambert), clamp(b * lambert)};
}

SynthFrame render_frame(const SynthScene& scene, int64_t frame, const SynthOptions& o) {
  const int64_t H = o.height, W = o.width;
  const auto& k = o.intrinsics;
  SynthFrame out;
  out.pose = scene.camera(frame);
  out.image = torch::zeros({3, H, W}, torch::kFloat32);
  out.depth = torch::zeros({1, H, W}, torch::kFloat32);
  out.object = torch::full({H, W}, -2, torch::kInt32);
  float* img = out.image.data_ptr<float>();
  float* dep = out.depth.data_ptr<float>();
  int32_t* obj = out.object.data_ptr<int32_t>();
  const int ss = std::max(1, o.supersample);
  parallel_rows(H, o.threads, [&](int64_t y0, int64_t y1) {
    for (int64_t y = y0; y < y1; ++y)
      for (int64_t x = 0; x < W; ++x) {
        double acc[3] = {0, 0, 0};
        for (int sy = 0; sy < ss; ++sy)
          for (int sx = 0; sx < ss; ++sx) {
            const double u = x + (sx + 0.5) / ss - 0.5, v = y + (sy + 0.5) / ss - 0.5;
            const Vec3 d = rotate(out.pose.R, {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0});
            const auto c = scene.shade(scene.cast(out.pose.c, d, frame), frame);
            for (int ch = 0; ch < 3; ++ch) acc[ch] += c[ch];
          }
        for (int ch = 0; ch < 3; ++ch) img[(ch * H + y) * W + x] = static_cast<float>(acc[ch] / (ss * ss));
        const Vec3 d = rotate(out.pose.R, {(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0});
        const auto hit = scene.cast(out.pose.c, d, frame);
        obj[y * W + x] = hit.id;
        dep[y * W + x] = hit.id == -2 ? 0.f : static_cast<float>(hit.t);
      }
  });
  return out;
}

namespace {
// Each box's object-map value: k for the k-th moving object (1-based, in box order; every one past
// the 254th shares 255, a uint8's last value), 0 for static ones.
std::vector<int> object_map_values(const SynthScene& scene) {
  std::vector<int> values(scene.boxes().size(), 0);
  int k = 0;
  for (size_t id = 0; id < values.size(); ++id)
    if (scene.is_moving(static_cast<int>(id))) values[id] = std::min(++k, 255);
  return values;
}
}  // namespace

torch::Tensor synth_object_map(const SynthScene& scene, const torch::Tensor& object) {
  auto map = torch::zeros(object.sizes(), torch::kUInt8);
  const auto values = object_map_values(scene);
  for (size_t id = 0; id < values.size(); ++id)
    if (values[id] > 0) map.masked_fill_(object == static_cast<int64_t>(id), values[id]);
  return map;
}

std::vector<int> synth_with_camera_objects(const SynthScene& scene) {
  const auto values = object_map_values(scene);
  std::vector<int> with_camera;
  for (size_t id = 0; id < values.size(); ++id)  // 255 is shared, so names no one object
    if (scene.boxes()[id].follows_camera && values[id] > 0 && values[id] < 255) with_camera.push_back(values[id]);
  return with_camera;
}

SynthFlow render_flow(const SynthScene& scene, int64_t frame, const SynthOptions& o) {
  const int64_t H = o.height, W = o.width;
  const auto& k = o.intrinsics;
  const RigidPose p0 = scene.camera(frame), p1 = scene.camera(frame + 1);
  SynthFlow out;
  out.flow = torch::zeros({2, H, W}, torch::kFloat32);
  out.valid_occ = torch::zeros({1, H, W}, torch::kFloat32);
  out.valid_noc = torch::zeros({1, H, W}, torch::kFloat32);
  float* fl = out.flow.data_ptr<float>();
  float* vo = out.valid_occ.data_ptr<float>();
  float* vn = out.valid_noc.data_ptr<float>();
  parallel_rows(H, o.threads, [&](int64_t y0, int64_t y1) {
    for (int64_t y = y0; y < y1; ++y)
      for (int64_t x = 0; x < W; ++x) {
        const Vec3 d = rotate(p0.R, {(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0});
        const auto hit = scene.cast(p0.c, d, frame);
        if (hit.id == -2) continue;
        const Vec3 cam1 = rotate_transposed(p1.R, scene.move(hit.point, hit.id, frame, 1) - p1.c);
        if (cam1.z < 1e-3) continue;
        const double u = k.fx * cam1.x / cam1.z + k.cx, v = k.fy * cam1.y / cam1.z + k.cy;
        if (u < 0 || v < 0 || u > W - 1 || v > H - 1) continue;
        fl[y * W + x] = static_cast<float>(u - x);
        fl[(H + y) * W + x] = static_cast<float>(v - y);
        vo[y * W + x] = 1.f;
        const Vec3 d1 = rotate(p1.R, {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0});
        const auto seen = scene.cast(p1.c, d1, frame + 1);
        if (seen.id == hit.id && std::abs(seen.t - cam1.z) < 1e-3 * cam1.z + 1e-4) vn[y * W + x] = 1.f;
      }
  });
  return out;
}

torch::Tensor synth_cam_from_velo() {
  RigidPose p;
  p.R = kCamFromVeloR;
  p.c = kCamFromVeloT;
  return p.matrix();
}

torch::Tensor render_lidar(const SynthScene& scene, int64_t frame, const SynthOptions& o) {
  const RigidPose cam = scene.camera(frame);
  const Vec3 origin = cam.c + rotate(cam.R, kCamFromVeloT);
  const int beams = std::max(1, o.lidar_beams);
  const int steps = static_cast<int>(std::round(360.0 / o.lidar_azimuth_step_deg));
  std::vector<std::vector<float>> rows(beams);
  parallel_rows(beams, o.threads, [&](int64_t b0, int64_t b1) {
    for (int64_t b = b0; b < b1; ++b) {
      const double el = (-24.8 + 26.8 * b / std::max(1, beams - 1)) * M_PI / 180;
      for (int s = 0; s < steps; ++s) {
        const double az = (-180.0 + s * o.lidar_azimuth_step_deg) * M_PI / 180;
        const Vec3 dv{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
        const Vec3 dw = rotate(cam.R, rotate(kCamFromVeloR, dv));
        const auto hit = scene.cast(origin, dw, frame, 120.0);
        if (hit.id == -2) continue;
        const auto c = scene.shade(hit, frame);
        const float t = static_cast<float>(hit.t);
        rows[b].insert(rows[b].end(), {float(dv.x) * t, float(dv.y) * t, float(dv.z) * t,
                                       0.299f * c[0] + 0.587f * c[1] + 0.114f * c[2]});
      }
    }
  });
  std::vector<float> all;
  for (auto& r : rows) all.insert(all.end(), r.begin(), r.end());
  return torch::tensor(all, torch::kFloat32).reshape({-1, 4});
}

}  // namespace geo
