// SPDX-License-Identifier: BSD-3-Clause
// detection_folder: the target detector on a folder of images that imucal did not make (public
// calibration images, frames of tests/bench/checkerboard_frames.cpp), in file-name order as a
// recording's frames: CPU time per frame (this thread's), frames/s per core, frames found, and,
// when the folder has a truth.csv (frame,corner_id,u,v,...), the corner errors against it.
// Frames are searched as `calibrate camera` searches them: in batches of 16 consecutive frames,
// each frame tracking the board from the ones before it in its batch.
//
//   detection_folder DIR --cols C --rows R [--no-history]
//   detection_folder DIR --aprilgrid TAG_COLS TAG_ROWS SPACING [--decimate D]
//   ... [--per-frame FILE]   (a CSV line per frame: file, points, CPU ms, median edge in px)
//
// docs/benchmarks.md ("Target detection on frames from elsewhere") has the figures.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "calib/target_detection.hpp"

namespace {

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

/// truth.csv: frame index -> corners.
std::map<int, std::vector<cv::Point2d>> read_truth(const std::string& path) {
  std::map<int, std::vector<cv::Point2d>> truth;
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::stringstream row(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(row, cell, ',')) v.push_back(std::stod(cell));
    if (v.size() >= 4) truth[static_cast<int>(v[0])].emplace_back(v[2], v[3]);
  }
  return truth;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(
      std::min<double>(static_cast<double>(v.size() - 1), q * static_cast<double>(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir;
  int cols = 0;
  int rows = 0;
  bool history = true;
  int tag_cols = 0;
  int tag_rows = 0;
  double tag_spacing = 0.0;
  imucal::calib::DetectionOptions options;
  std::string per_frame_path;  // --per-frame FILE: file, points, CPU ms, median edge (px), worst corner error
                               // (px) per frame
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--aprilgrid" && i + 3 < argc) {
      tag_cols = std::atoi(argv[++i]);
      tag_rows = std::atoi(argv[++i]);
      tag_spacing = std::atof(argv[++i]);
    } else if (a == "--per-frame" && i + 1 < argc) {
      per_frame_path = argv[++i];
    } else if (a == "--decimate" && i + 1 < argc) {
      options.aprilgrid_decimate = std::atof(argv[++i]);
    } else if (a == "--cols" && i + 1 < argc) {
      cols = std::atoi(argv[++i]);
    } else if (a == "--rows" && i + 1 < argc) {
      rows = std::atoi(argv[++i]);
    } else if (a == "--no-history") {
      history = false;
    } else if (a == "--help" || a == "-h") {
      dir.clear();
      break;
    } else {
      dir = a;
    }
  }
  const bool aprilgrid = tag_cols > 0;
  if (dir.empty() || (!aprilgrid && (cols < 3 || rows < 3)) ||
      (aprilgrid && (tag_rows < 1 || tag_spacing <= 0))) {
    std::fprintf(stderr,
                 "usage: detection_folder DIR --cols C --rows R [--no-history]\n"
                 "       detection_folder DIR --aprilgrid TAG_COLS TAG_ROWS SPACING [--decimate D]\n"
                 "  DIR holds .png/.jpg frames (file-name order) and optionally truth.csv "
                 "(frame,corner_id,u,v,...)\n");
    return 2;
  }
  cv::setNumThreads(1);
  imucal::TargetDescription target;
  if (aprilgrid) {
    target.type = imucal::TargetDescription::Type::kAprilgrid;
    target.tag_cols = tag_cols;
    target.tag_rows = tag_rows;
    target.tag_size_m = 0.03;
    target.tag_spacing = tag_spacing;
  } else {
    target.type = imucal::TargetDescription::Type::kCheckerboard;
    target.cols = cols;
    target.rows = rows;
    target.row_spacing_m = target.col_spacing_m = 0.04;
  }
  auto detector = imucal::calib::TargetDetector::create(target, options);
  if (!detector.ok()) {
    std::fprintf(stderr, "%s\n", detector.error().message.c_str());
    return 2;
  }
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string ext = e.path().extension().string();
    if (ext == ".png" || ext == ".jpg") files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  const auto truth = read_truth(dir + "/truth.csv");

  std::FILE* per_frame = per_frame_path.empty() ? nullptr : std::fopen(per_frame_path.c_str(), "w");
  if (per_frame) std::fprintf(per_frame, "file,points,cpu_ms,median_edge_px,max_error_px\n");
  std::vector<double> ms;
  std::vector<double> errors;
  int found = 0;
  std::size_t points = 0;
  std::vector<imucal::calib::TargetObservation> obs(files.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    const cv::Mat image = cv::imread(files[i], cv::IMREAD_GRAYSCALE);
    if (image.empty()) continue;
    imucal::calib::DetectionHistory h;
    if (history && i % 16 != 0 && !obs[i - 1].empty()) {
      h.last = &obs[i - 1];
      if (i % 16 >= 2 && !obs[i - 2].empty()) h.before_last = &obs[i - 2];
    }
    const double t0 = thread_cpu_ms();
    auto r = (*detector)->detect({image.data, image.cols, image.rows, image.step[0]}, h);
    ms.push_back(thread_cpu_ms() - t0);
    // truth.csv names frames by their file name (000.png is frame 0), else by their order.
    double worst = std::numeric_limits<double>::quiet_NaN();
    if (r.ok() && !r->empty() && !truth.empty()) {
      const std::string stem = std::filesystem::path(files[i]).stem().string();
      const bool numbered =
          !stem.empty() && std::all_of(stem.begin(), stem.end(), [](char c) { return c >= '0' && c <= '9'; });
      const auto t = truth.find(numbered ? std::stoi(stem) : static_cast<int>(i));
      if (t != truth.end()) {
        worst = 0.0;
        for (const Eigen::Vector2d& p : r->px) {
          double best = 1e9;
          for (const cv::Point2d& q : t->second) best = std::min(best, std::hypot(p.x() - q.x, p.y() - q.y));
          errors.push_back(best);
          worst = std::max(worst, best);
        }
      }
    }
    if (per_frame) {
      // Edges between neighbouring points of the grid (ids one apart in a row, next to each other).
      std::vector<double> edges;
      if (r.ok())
        for (std::size_t k = 0; k + 1 < r->ids.size(); ++k)
          if (r->ids[k + 1] == r->ids[k] + 1 &&
              (aprilgrid ? r->ids[k] % 2 == 0 : r->ids[k] % cols != cols - 1))
            edges.push_back((r->px[k + 1] - r->px[k]).norm());
      std::fprintf(per_frame, "%s,%zu,%.3f,%.2f,%.3f\n", std::filesystem::path(files[i]).filename().c_str(),
                   r.ok() ? r->px.size() : 0, ms.back(), percentile(edges, 0.5), worst);
    }
    if (!r.ok() || r->empty()) continue;
    obs[i] = *r;
    ++found;
    points += r->px.size();
  }
  double mean = 0.0;
  for (double v : ms) mean += v;
  mean /= std::max<std::size_t>(1, ms.size());
  double rms = 0.0;
  for (double e : errors) rms += e * e;
  rms = errors.empty() ? 0.0 : std::sqrt(rms / static_cast<double>(errors.size()));
  std::printf(
      "%s: %zu frames, found %d (%zu points); CPU per frame median %.2f ms, p90 %.2f ms, max %.2f ms, "
      "mean %.2f ms (%.0f frames/s a core)",
      dir.c_str(), ms.size(), found, points, percentile(ms, 0.5), percentile(ms, 0.9), percentile(ms, 1.0),
      mean, mean > 0 ? 1e3 / mean : 0.0);
  if (!errors.empty())
    std::printf("; corners against truth: RMS %.3f px, max %.3f px", rms, percentile(errors, 1.0));
  std::printf("\n");
  return 0;
}
