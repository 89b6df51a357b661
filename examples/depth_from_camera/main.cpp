// depth_from_camera: depth statistics and the camera path of a folder of frames, with geo as a
// library. The frames are read by this program (OpenCV here; any RGB buffer works).
//   depth_from_camera MODEL FRAMES_DIR [OUT_DIR [CAMERA_HEIGHT]]
// OUT_DIR: <frame>-depth.png as geo_infer writes them. CAMERA_HEIGHT (metres above the road, KITTI:
// 1.65): also the depth in metres, scaled by the camera's height above the road fitted to it.
#include <geo/geo.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s MODEL FRAMES_DIR [OUT_DIR [CAMERA_HEIGHT]]\n", argv[0]);
    return 2;
  }
  try {
    const geo::Model model = geo::Model::load(argv[1]);
    std::vector<std::filesystem::path> files;
    for (const auto& e : std::filesystem::directory_iterator(argv[2]))
      if (e.path().extension() == ".png" || e.path().extension() == ".jpg") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    torch::Tensor previous, camera_to_world = torch::eye(4);
    for (const auto& f : files) {
      cv::Mat bgr = cv::imread(f.string(), cv::IMREAD_COLOR), rgb;
      if (bgr.empty()) throw std::runtime_error("cannot read " + f.string());
      cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
      const torch::Tensor image = geo::rgb8_image(rgb.data, rgb.rows, rgb.cols, static_cast<int64_t>(rgb.step));
      const torch::Tensor depth = model.depth(image).cpu();  // [H,W], up to scale
      if (previous.defined())  // points in the previous camera -> this one; chained into a path
        camera_to_world = camera_to_world.matmul(torch::inverse(model.relative_pose(previous, image).cpu()));
      const auto median = depth.flatten().median().item<float>();
      std::printf("%s depth min %.3f median %.3f max %.3f camera at (%.3f, %.3f, %.3f)\n", f.filename().c_str(),
                  depth.min().item<float>(), median, depth.max().item<float>(), camera_to_world[0][3].item<float>(),
                  camera_to_world[1][3].item<float>(), camera_to_world[2][3].item<float>());
      if (argc > 4) {  // metres, from the camera's height above the road (no ground truth)
        try {
          std::vector<double> scale;
          const torch::Tensor metres = model.metric_depth(image, std::stod(argv[4]), {}, &scale).cpu();
          std::printf("  in metres: median %.2f m (x %.3f)\n", metres.flatten().median().item<float>(), scale.at(0));
          if (previous.defined()) {  // the step from the previous frame, at the previous frame's scale
            const torch::Tensor step = model.metric_relative_pose(previous, image, std::stod(argv[4])).cpu();
            std::printf("  moved %.2f m since the previous frame\n",
                        step.slice(0, 0, 3).select(1, 3).norm().item<float>());
          }
        } catch (const geo::Error& e) {  // no road in front of the camera: said, not guessed
          std::printf("  in metres: %s\n", e.what());
        }
      }
      previous = image;
      if (argc > 3) {  // 16-bit PNG, depth x 256, as geo_infer's <frame>-depth.png
        const auto q = (depth.clamp(0, 65535.0 / 256.0) * 256).round().to(torch::kInt32).contiguous();
        cv::Mat m(static_cast<int>(q.size(0)), static_cast<int>(q.size(1)), CV_32S, q.data_ptr<int32_t>()), m16;
        m.convertTo(m16, CV_16U);
        cv::imwrite(std::string(argv[3]) + "/" + f.stem().string() + "-depth.png", m16);
      }
    }
    return 0;
  } catch (const std::exception& e) {  // geo::Error and anything else
    std::fprintf(stderr, "depth_from_camera: %s\n", e.what());
    return 1;
  }
}
