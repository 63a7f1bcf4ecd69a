// SPDX-License-Identifier: BSD-3-Clause
// checkerboard_frames: synthetic checkerboard frames with exact corner truth, a second generator
// written apart from the virtual camera (sim/camera_render.*) to measure the detector on frames
// it was not made with (docs/benchmarks.md, "Target detection on frames from elsewhere").
//
// Self-contained (OpenCV 4, and libapriltag for the AprilGrid's tag codes): none of imucal's
// projection or rendering code. Renders a planar
// checkerboard seen by a pinhole camera with radial-tangential ("radtan", OpenCV plumb-bob k1 k2 p1 p2)
// distortion, EuRoC-like by default.
//
// Rendering model
//   * The image is rendered at S x S supersampling (default S = 4). Supersampled pixel (I, J)
//     (row, column) has its centre at full-resolution pixel coordinates
//         u = (J + 0.5) / S - 0.5,   v = (I + 0.5) / S - 0.5
//     in OpenCV's convention (integer coordinates = pixel centres; pixel (0,0) covers
//     [-0.5, 0.5] x [-0.5, 0.5]). cv::resize(INTER_AREA) by exactly 1/S averages each S x S
//     block, i.e. integrates the supersampled image over the full-resolution pixel's area.
//   * Each supersampled centre is undistorted once (cv::undistortPoints, iterated to 1e-12) to a
//     normalised ray (x, y, 1); the rays do not depend on the pose, so they are computed once.
//     The round trip (ray -> cv::projectPoints -> pixel) is checked and its max error printed.
//   * Per frame: ray-plane intersection with the board plane, colour by square parity
//     (black 30 DN, white 220 DN; white margin one square wide around the 9 x 7 squares),
//     outside the board a textured background (~120 DN, gradient + low-frequency texture);
//     a mild smooth illumination gain multiplies the board. Then INTER_AREA to full size,
//     Gaussian blur (sigma 0.7 px), Gaussian noise (sigma 1.5 DN), rounding to 8 bits.
//   * Truth: cv::projectPoints of each inner corner with the same intrinsics and distortion,
//     which is exactly the model the rays were built from.
//
// Board coordinates: inner corner (r, c) at (c * s, r * s, 0), id = r * cols + c, with
// cols = 8, rows = 6 (OpenCV pattern size cv::Size(8, 6)); the square (i, j) spanning
// [i s, (i+1) s] x [j s, (j+1) s] is black when i + j is even, so the square diagonally outside
// corner 0 (i = j = -1) is black. The board's z axis points away from the camera.
//
// Output (under --out DIR):
//   DIR/board/000.png ...     frames with the board (random poses)
//   DIR/board/truth.csv        frame,corner_id,u,v,fully_in_view
//   DIR/board/poses.csv        frame,rvec(3),tvec(3),fully_in_view
//   DIR/noboard/000.png ...   frames without a board (textures); DIR/noboard/kinds.csv
//   DIR/motion/000.png ...    smooth pose sequence (20 Hz); truth.csv, poses.csv as above
//   DIR/camera.yml            K, D, image size, board geometry
//
// AprilGrid (--aprilgrid SPACING): the page is Kalibr's AprilGrid instead, drawn from the
// definition (kalibr_create_target_pdf's layout) rather than from imucal's test renderer:
// --pattern C R tags of --square metres (the black square), SPACING x square apart, tag t at
// column t % C and row t / C counted from the page's bottom, upright; its black square is 10
// bits, a 2-bit black border around libapriltag's 6 x 6 tag36h11 data bits (its codes and bit
// positions, which sit inside a 1-bit border); a black square of SPACING x square at every
// crossing of the gaps, touching the tags' corners; white for half a tag beyond. Truth: the four
// corners of every tag, in no particular order (detection_folder matches nearest points).
//
// Run: build/dev/tests/checkerboard_frames --out DIR --seed 1

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

namespace {

struct Options {
  std::string out = "data";
  unsigned seed = 1;
  int n_board = 200;
  int n_noboard = 100;
  int n_motion = 200;
  int ss = 4;
  double blur_sigma = 0.7;
  double noise_sigma = 1.5;
  double partial_fraction = 0.15;
  double fps = 20.0;
  // camera
  int width = 752, height = 480;
  double fx = 458.0, fy = 458.0, cx = 367.0, cy = 248.0;
  double k1 = -0.28, k2 = 0.07, p1 = 0.0002, p2 = 0.00002;
  // board
  int cols = 8, rows = 6;  // inner corners (AprilGrid: tags)
  double square = 0.04;    // AprilGrid: the tags' black squares
  double spacing = 0.0;    // > 0: an AprilGrid with gaps of spacing x square
  double dmin = 0.4, dmax = 1.5, max_tilt_deg = 50.0;
};

void usage() {
  std::cout <<
      R"(checkerboard_frames - synthetic checkerboard frames with corner truth

Usage: checkerboard_frames [options]
  --out DIR          output directory (default data)
  --seed N           random seed (default 1); same seed, same frames
  --board N          frames with a board at random poses (default 200)
  --noboard N        frames without a board (default 100)
  --motion N         frames of a smooth pose sequence at --fps (default 200)
  --fps F            frame rate of the motion sequence (default 20)
  --ss S             supersampling factor per axis (default 4)
  --blur SIGMA       Gaussian blur after downsampling, px (default 0.7; 0 = none)
  --noise SIGMA      Gaussian noise, DN (default 1.5; 0 = none)
  --partial F        fraction of board frames with the board partly out of view (default 0.15)
  --size W H         image size (default 752 480)
  --K FX FY CX CY    intrinsics (default 458 458 367 248)
  --D K1 K2 P1 P2    radtan distortion (default -0.28 0.07 0.0002 0.00002)
  --pattern C R      inner corners (default 8 6)
  --square M         square side in metres (default 0.04)
  --dist MIN MAX     board distance range, m (default 0.4 1.5)
  --tilt DEG         max tilt of the board normal from the optical axis (default 50)
  --aprilgrid SPACING  draw Kalibr's AprilGrid instead: --pattern gives its tags (columns,
                     rows), --square the tags' size, SPACING the gaps as a fraction of it
                     (Kalibr's tagSpacing, e.g. 0.3); truth holds the tags' four corners
  --help             this text
Writes DIR/{board,noboard,motion}/NNN.png, truth.csv (frame,corner_id,u,v,fully_in_view),
poses.csv, and DIR/camera.yml. Pixel convention: OpenCV's (integer = pixel centre).
)";
}

bool parse(int argc, char** argv, Options& o) {
  auto need = [&](int i, int n) {
    if (i + n >= argc) {
      std::cerr << "missing value for " << argv[i] << "\n";
      std::exit(2);
    }
  };
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      usage();
      std::exit(0);
    } else if (a == "--out") {
      need(i, 1);
      o.out = argv[++i];
    } else if (a == "--seed") {
      need(i, 1);
      o.seed = static_cast<unsigned>(std::stoul(argv[++i]));
    } else if (a == "--board") {
      need(i, 1);
      o.n_board = std::stoi(argv[++i]);
    } else if (a == "--noboard") {
      need(i, 1);
      o.n_noboard = std::stoi(argv[++i]);
    } else if (a == "--motion") {
      need(i, 1);
      o.n_motion = std::stoi(argv[++i]);
    } else if (a == "--fps") {
      need(i, 1);
      o.fps = std::stod(argv[++i]);
    } else if (a == "--ss") {
      need(i, 1);
      o.ss = std::stoi(argv[++i]);
    } else if (a == "--blur") {
      need(i, 1);
      o.blur_sigma = std::stod(argv[++i]);
    } else if (a == "--noise") {
      need(i, 1);
      o.noise_sigma = std::stod(argv[++i]);
    } else if (a == "--partial") {
      need(i, 1);
      o.partial_fraction = std::stod(argv[++i]);
    } else if (a == "--size") {
      need(i, 2);
      o.width = std::stoi(argv[++i]);
      o.height = std::stoi(argv[++i]);
    } else if (a == "--K") {
      need(i, 4);
      o.fx = std::stod(argv[++i]);
      o.fy = std::stod(argv[++i]);
      o.cx = std::stod(argv[++i]);
      o.cy = std::stod(argv[++i]);
    } else if (a == "--D") {
      need(i, 4);
      o.k1 = std::stod(argv[++i]);
      o.k2 = std::stod(argv[++i]);
      o.p1 = std::stod(argv[++i]);
      o.p2 = std::stod(argv[++i]);
    } else if (a == "--pattern") {
      need(i, 2);
      o.cols = std::stoi(argv[++i]);
      o.rows = std::stoi(argv[++i]);
    } else if (a == "--square") {
      need(i, 1);
      o.square = std::stod(argv[++i]);
    } else if (a == "--dist") {
      need(i, 2);
      o.dmin = std::stod(argv[++i]);
      o.dmax = std::stod(argv[++i]);
    } else if (a == "--aprilgrid") {
      need(i, 1);
      o.spacing = std::stod(argv[++i]);
      if (o.spacing <= 0) {
        std::cerr << "--aprilgrid needs a spacing above 0\n";
        return false;
      }
    } else if (a == "--tilt") {
      need(i, 1);
      o.max_tilt_deg = std::stod(argv[++i]);
    } else {
      std::cerr << "unknown option " << a << " (see --help)\n";
      return false;
    }
  }
  if (o.ss < 1 || o.width < 16 || o.height < 16 || o.cols < 2 || o.rows < 2 || o.square <= 0) {
    std::cerr << "invalid option values\n";
    return false;
  }
  return true;
}

constexpr double kBlack = 30.0, kWhite = 220.0, kMarginWhite = 220.0;

struct Camera {
  cv::Matx33d K;
  cv::Vec4d D;
  cv::Size size;
};

struct Pose {
  cv::Matx33d R;
  cv::Vec3d t;  // X_cam = R X_board + t
};

// Normalised rays of all supersampled pixel centres (CV_32FC2, ss*height x ss*width).
cv::Mat make_rays(const Camera& cam, int ss, double* max_roundtrip) {
  const int W = cam.size.width * ss, H = cam.size.height * ss;
  cv::Mat px(H * W, 1, CV_64FC2);
  for (int I = 0; I < H; ++I)
    for (int J = 0; J < W; ++J)
      px.at<cv::Vec2d>(I * W + J) = cv::Vec2d((J + 0.5) / ss - 0.5, (I + 0.5) / ss - 0.5);
  cv::Mat und;
  cv::undistortPoints(px, und, cam.K, cam.D, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
  // Round trip on a subsample of the rays (every 7th) to check the undistortion converged.
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> ref;
  for (int k = 0; k < H * W; k += 7) {
    const cv::Vec2d n = und.at<cv::Vec2d>(k);
    obj.emplace_back(n[0], n[1], 1.0);
    ref.emplace_back(px.at<cv::Vec2d>(k)[0], px.at<cv::Vec2d>(k)[1]);
  }
  std::vector<cv::Point2d> back;
  cv::projectPoints(obj, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cam.K, cam.D, back);
  double worst = 0;
  for (std::size_t k = 0; k < back.size(); ++k) worst = std::max(worst, cv::norm(back[k] - ref[k]));
  *max_roundtrip = worst;
  cv::Mat rays;
  und.reshape(2, H).convertTo(rays, CV_32FC2);
  return rays;
}

// Smooth random field in [-1, 1]: white noise on a coarse grid, cubic-upsampled.
cv::Mat smooth_field(cv::Size size, int cells, std::mt19937& rng) {
  cv::Mat coarse(std::max(2, cells * size.height / size.width), cells, CV_32F);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (int i = 0; i < coarse.rows; ++i)
    for (int j = 0; j < coarse.cols; ++j) coarse.at<float>(i, j) = u(rng);
  cv::Mat out;
  cv::resize(coarse, out, size, 0, 0, cv::INTER_CUBIC);
  return out;
}

// Background for board frames at supersampled size: ~120 DN, a linear gradient and a
// low-frequency texture (a few tens of DN).
cv::Mat plain_background(cv::Size size, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  cv::Mat bg(size, CV_32F);
  const double gx = 30 * u(rng), gy = 30 * u(rng), base = 120 + 15 * u(rng);
  for (int i = 0; i < size.height; ++i)
    for (int j = 0; j < size.width; ++j)
      bg.at<float>(i, j) = static_cast<float>(base + gx * (j / double(size.width) - 0.5) +
                                              gy * (i / double(size.height) - 0.5));
  bg += 20.0f * smooth_field(size, 6, rng) + 8.0f * smooth_field(size, 20, rng);
  return bg;
}

// Frames without a board. Kinds (cycled): 0 smooth, 1 random rectangles, 2 white noise,
// 3 binary blobs (thresholded smooth noise), 4 random lines and dark/bright bars,
// 5 a different checkerboard (5 x 4 inner corners, plain affine) - not the target.
const char* kNoBoardKinds[] = {"smooth", "rectangles", "noise", "blobs", "lines", "other_board"};
constexpr int kNumNoBoardKinds = 6;

cv::Mat noboard_frame(int kind, cv::Size size, int ss, std::mt19937& rng) {
  const cv::Size big(size.width * ss, size.height * ss);
  std::uniform_real_distribution<double> u(0, 1);
  cv::Mat img = plain_background(big, rng);
  switch (kind) {
    case 0:
      break;
    case 1: {  // rectangles, some rotated, dark and bright
      const int n = 40 + static_cast<int>(160 * u(rng));
      for (int k = 0; k < n; ++k) {
        const cv::Point2f c(static_cast<float>(u(rng) * big.width), static_cast<float>(u(rng) * big.height));
        const cv::Size2f s(static_cast<float>((10 + 150 * u(rng)) * ss),
                           static_cast<float>((10 + 150 * u(rng)) * ss));
        const cv::RotatedRect rr(c, s, static_cast<float>(u(rng) < 0.5 ? 0.0 : 180 * u(rng)));
        cv::Point2f p[4];
        rr.points(p);
        std::vector<cv::Point> poly(p, p + 4);
        cv::fillConvexPoly(img, poly, cv::Scalar(u(rng) < 0.5 ? 20 + 40 * u(rng) : 190 + 50 * u(rng)));
      }
      break;
    }
    case 2: {  // white noise, per full-resolution pixel (drawn at full res, nearest-upsampled)
      cv::Mat small(size, CV_32F);
      cv::randu(small, 0, 255);
      cv::resize(small, img, big, 0, 0, cv::INTER_NEAREST);
      break;
    }
    case 3: {  // binary blobs at a random scale
      const int cells = 20 + static_cast<int>(180 * u(rng));
      cv::Mat f = smooth_field(big, cells, rng);
      for (int i = 0; i < big.height; ++i)
        for (int j = 0; j < big.width; ++j) img.at<float>(i, j) = f.at<float>(i, j) > 0 ? 210.f : 40.f;
      break;
    }
    case 4: {  // lines and bars
      const int n = 30 + static_cast<int>(100 * u(rng));
      for (int k = 0; k < n; ++k) {
        const cv::Point a(static_cast<int>(u(rng) * big.width), static_cast<int>(u(rng) * big.height));
        const cv::Point b(static_cast<int>(u(rng) * big.width), static_cast<int>(u(rng) * big.height));
        cv::line(img, a, b, cv::Scalar(u(rng) < 0.5 ? 25 : 230), static_cast<int>((1 + 12 * u(rng)) * ss));
      }
      break;
    }
    default: {  // another checkerboard (5 x 4 inner corners = 6 x 5 squares), affine, with margin
      const double side = (25 + 30 * u(rng)) * ss, ang = (u(rng) - 0.5) * 1.2;
      const cv::Point2d o(big.width * (0.25 + 0.2 * u(rng)), big.height * (0.25 + 0.2 * u(rng)));
      const double ca = std::cos(ang), sa = std::sin(ang);
      for (int i = 0; i < big.height; ++i)
        for (int j = 0; j < big.width; ++j) {
          const double dx = j - o.x, dy = i - o.y;
          const double bx = (ca * dx + sa * dy) / side, by = (-sa * dx + ca * dy) / side;
          if (bx < -1 || bx >= 7 || by < -1 || by >= 6) continue;
          if (bx < 0 || bx >= 6 || by < 0 || by >= 5) {
            img.at<float>(i, j) = static_cast<float>(kMarginWhite);
            continue;
          }
          const int p = static_cast<int>(std::floor(bx)) + static_cast<int>(std::floor(by));
          img.at<float>(i, j) = static_cast<float>(p % 2 == 0 ? kBlack : kWhite);
        }
      break;
    }
  }
  return img;
}

// The page on the board plane: its extent (background beyond) and its reflectance.
class Page {
 public:
  explicit Page(const Options& o) : o_(o) {
    const double s = o.square;
    if (o.spacing <= 0) {
      x0_ = -2 * s, x1_ = (o.cols + 1) * s, y0_ = -2 * s, y1_ = (o.rows + 1) * s;
      return;
    }
    pitch_ = s * (1 + o.spacing);
    const double gap = o.spacing * s;
    x0_ = -gap - 0.5 * s, x1_ = o.cols * pitch_ + 0.5 * s, y0_ = -gap - 0.5 * s,
    y1_ = o.rows * pitch_ + 0.5 * s;
    apriltag_family_t* family = tag36h11_create();
    // As apriltag_to_image draws a tag (that function's image cannot be freed through the
    // library's exported symbols): code bit i, from the most significant, white when set, at
    // (bit_x[i] + 1, bit_y[i] + 1) of the 10 x 10 square (bit_x, bit_y count from the 8-bit
    // black square, whose border is 1 bit there and 2 bits here: both put the data at 2-7).
    for (int t = 0; t < o.cols * o.rows; ++t) {
      std::array<std::array<bool, 10>, 10> black{};
      for (auto& row : black) row.fill(true);
      const std::uint64_t code = family->codes[t];
      for (std::uint32_t i = 0; i < family->nbits; ++i) {
        if (code & (std::uint64_t{1} << (family->nbits - i - 1)))
          black[family->bit_y[i] + 1][family->bit_x[i] + 1] = false;
      }
      bits_.push_back(black);
    }
    tag36h11_destroy(family);
  }
  double x0() const { return x0_; }
  double x1() const { return x1_; }
  double y0() const { return y0_; }
  double y1() const { return y1_; }
  /// The middle of the pattern (where a pose puts the board's centre).
  cv::Vec3d centre() const {
    if (o_.spacing <= 0) return {(o_.cols - 1) * o_.square / 2, (o_.rows - 1) * o_.square / 2, 0};
    return {((o_.cols - 1) * pitch_ + o_.square) / 2, ((o_.rows - 1) * pitch_ + o_.square) / 2, 0};
  }
  /// Reflectance at (x, y) on the page.
  double value(double x, double y) const {
    const double s = o_.square;
    if (o_.spacing <= 0) {
      if (x < -s || x >= o_.cols * s || y < -s || y >= o_.rows * s) return kMarginWhite;
      const long i = static_cast<long>(std::floor(x / s)), j = static_cast<long>(std::floor(y / s));
      return ((i + j) % 2 == 0) ? kBlack : kWhite;
    }
    // Which column and row of tags or gaps: gap k runs from k * pitch - gap to k * pitch.
    const double gap = o_.spacing * s;
    const long i = static_cast<long>(std::floor((x + gap) / pitch_));
    const long j = static_cast<long>(std::floor((y + gap) / pitch_));
    if (i < 0 || j < 0 || i > o_.cols || j > o_.rows) return kMarginWhite;
    const double u = x - i * pitch_, v = y - j * pitch_;  // in [-gap, s) inside the cell
    const bool in_gap_x = u < 0, in_gap_y = v < 0;
    if (in_gap_x && in_gap_y) return kBlack;  // the square at a crossing of the gaps
    if (in_gap_x || in_gap_y || i == o_.cols || j == o_.rows) return kMarginWhite;
    const int tag =
        (o_.rows - 1 - static_cast<int>(j)) * o_.cols + static_cast<int>(i);  // rows from the bottom
    const int bx = std::min(9, static_cast<int>(u / s * 10)), by = std::min(9, static_cast<int>(v / s * 10));
    return bits_[static_cast<std::size_t>(tag)][by][bx] ? kBlack : kWhite;
  }
  /// The points whose truth is written: inner corners, or the four corners of every tag.
  std::vector<cv::Point3d> points() const {
    std::vector<cv::Point3d> p;
    if (o_.spacing <= 0) {
      for (int r = 0; r < o_.rows; ++r)
        for (int c = 0; c < o_.cols; ++c) p.emplace_back(c * o_.square, r * o_.square, 0.0);
      return p;
    }
    for (int r = 0; r < o_.rows; ++r)
      for (int c = 0; c < o_.cols; ++c)
        for (int k = 0; k < 4; ++k)
          p.emplace_back(c * pitch_ + (k % 2) * o_.square, r * pitch_ + (k / 2) * o_.square, 0.0);
    return p;
  }

 private:
  const Options& o_;
  double x0_ = 0, x1_ = 0, y0_ = 0, y1_ = 0;
  double pitch_ = 0;
  std::vector<std::array<std::array<bool, 10>, 10>> bits_;  // per tag, row by column, from the top
};

// Board rendered over `background` (supersampled, CV_32F) from pose `P`.
void render_board(const cv::Mat& rays, const Pose& P, const Page& page, const cv::Mat& gain, cv::Mat& img) {
  const cv::Vec3d n(P.R(0, 2), P.R(1, 2), P.R(2, 2));  // board normal in the camera frame
  const double nt = n.dot(P.t);
  const cv::Matx33d Rt = P.R.t();
  for (int I = 0; I < rays.rows; ++I) {
    const cv::Vec2f* r = rays.ptr<cv::Vec2f>(I);
    float* out = img.ptr<float>(I);
    const float* g = gain.ptr<float>(I);
    for (int J = 0; J < rays.cols; ++J) {
      const cv::Vec3d d(r[J][0], r[J][1], 1.0);
      const double nd = n.dot(d);
      if (std::abs(nd) < 1e-12) continue;
      const double lambda = nt / nd;
      if (lambda <= 0) continue;
      const cv::Vec3d X = Rt * (lambda * d - P.t);
      if (X[0] < page.x0() || X[0] >= page.x1() || X[1] < page.y0() || X[1] >= page.y1()) continue;
      out[J] = static_cast<float>(page.value(X[0], X[1]) * g[J]);
    }
  }
}

cv::Mat finish(const cv::Mat& big, const Options& o, std::mt19937& rng) {
  cv::Mat small;
  cv::resize(big, small, cv::Size(o.width, o.height), 0, 0, cv::INTER_AREA);
  if (o.blur_sigma > 0)
    cv::GaussianBlur(small, small, cv::Size(0, 0), o.blur_sigma, o.blur_sigma, cv::BORDER_REFLECT);
  if (o.noise_sigma > 0) {
    std::normal_distribution<float> nd(0.f, static_cast<float>(o.noise_sigma));
    for (int i = 0; i < small.rows; ++i)
      for (int j = 0; j < small.cols; ++j) small.at<float>(i, j) += nd(rng);
  }
  cv::Mat out;
  small.convertTo(out, CV_8U);  // rounds and saturates
  return out;
}

// Points along the outline of the page (to test full visibility).
std::vector<cv::Point3d> outline(const Page& page) {
  const double x0 = page.x0(), x1 = page.x1(), y0 = page.y0(), y1 = page.y1();
  std::vector<cv::Point3d> p;
  const int n = 40;
  for (int k = 0; k <= n; ++k) {
    const double a = k / double(n);
    p.emplace_back(x0 + a * (x1 - x0), y0, 0);
    p.emplace_back(x0 + a * (x1 - x0), y1, 0);
    p.emplace_back(x0, y0 + a * (y1 - y0), 0);
    p.emplace_back(x1, y0 + a * (y1 - y0), 0);
  }
  return p;
}

std::vector<cv::Point2d> project(const std::vector<cv::Point3d>& X, const Pose& P, const Camera& cam) {
  cv::Vec3d rvec;
  cv::Rodrigues(P.R, rvec);
  std::vector<cv::Point2d> px;
  cv::projectPoints(X, rvec, P.t, cam.K, cam.D, px);
  return px;
}

bool inside(const cv::Point2d& p, const Camera& cam, double margin) {
  return p.x >= -0.5 + margin && p.y >= -0.5 + margin && p.x <= cam.size.width - 0.5 - margin &&
         p.y <= cam.size.height - 0.5 - margin;
}

// All points in front of the camera and within the field where the distortion model is used
// sensibly (normalised radius below 1.3 keeps us inside the monotonic part of the model).
bool in_front(const std::vector<cv::Point3d>& X, const Pose& P) {
  for (const auto& x : X) {
    const cv::Vec3d c = P.R * cv::Vec3d(x.x, x.y, x.z) + P.t;
    if (c[2] < 0.05) return false;
    if (std::hypot(c[0] / c[2], c[1] / c[2]) > 1.3) return false;
  }
  return true;
}

cv::Matx33d rot(const cv::Vec3d& axis_angle) {
  cv::Matx33d R;
  cv::Rodrigues(axis_angle, R);
  return R;
}

// Pose: board centre on the ray through normalised point (nx, ny) at depth d; the board's
// normal tilted by `tilt` about an in-plane axis at angle `az`; rolled by `roll` about its normal.
Pose make_pose(const Page& page, double nx, double ny, double d, double tilt, double az, double roll) {
  const cv::Matx33d Rroll = rot(cv::Vec3d(0, 0, roll));
  const cv::Matx33d Rtilt = rot(cv::Vec3d(std::cos(az), std::sin(az), 0) * tilt);
  Pose P;
  P.R = Rtilt * Rroll;
  P.t = cv::Vec3d(nx * d, ny * d, d) - P.R * page.centre();
  return P;
}

void write_csv_header(std::ofstream& truth, std::ofstream& poses) {
  truth << "frame,corner_id,u,v,fully_in_view\n";
  poses << "frame,rx,ry,rz,tx,ty,tz,fully_in_view\n";
}

void write_truth(std::ofstream& truth, std::ofstream& poses, int frame, const Pose& P,
                 const std::vector<cv::Point2d>& px, bool full) {
  char buf[160];
  for (std::size_t k = 0; k < px.size(); ++k) {
    std::snprintf(buf, sizeof buf, "%d,%zu,%.6f,%.6f,%d\n", frame, k, px[k].x, px[k].y, full ? 1 : 0);
    truth << buf;
  }
  cv::Vec3d rvec;
  cv::Rodrigues(P.R, rvec);
  std::snprintf(buf, sizeof buf, "%d,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%d\n", frame, rvec[0], rvec[1], rvec[2],
                P.t[0], P.t[1], P.t[2], full ? 1 : 0);
  poses << buf;
}

std::string frame_name(const std::filesystem::path& dir, int k) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%03d.png", k);
  return (dir / buf).string();
}

// Illumination gain on the board: 0.85..1.1, smooth.
cv::Mat make_gain(cv::Size big, std::mt19937& rng) {
  cv::Mat g = smooth_field(big, 3, rng);
  g = 0.975f + 0.125f * g;
  return g;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse(argc, argv, o)) return 2;
  cv::setNumThreads(1);
  namespace fs = std::filesystem;
  const fs::path root(o.out);
  for (const char* sub : {"board", "noboard", "motion"}) fs::create_directories(root / sub);

  Camera cam{cv::Matx33d(o.fx, 0, o.cx, 0, o.fy, o.cy, 0, 0, 1), cv::Vec4d(o.k1, o.k2, o.p1, o.p2),
             cv::Size(o.width, o.height)};
  double roundtrip = 0;
  const cv::Mat rays = make_rays(cam, o.ss, &roundtrip);
  std::cout << "rays: " << rays.cols << "x" << rays.rows << ", undistort round-trip max error " << roundtrip
            << " px\n";
  {
    cv::FileStorage fsw((root / "camera.yml").string(), cv::FileStorage::WRITE);
    fsw << "K" << cv::Mat(cam.K) << "D" << cv::Mat(cam.D) << "width" << o.width << "height" << o.height;
    fsw << "cols" << o.cols << "rows" << o.rows << "square" << o.square << "spacing" << o.spacing << "seed"
        << static_cast<int>(o.seed) << "ss" << o.ss << "blur" << o.blur_sigma << "noise" << o.noise_sigma;
  }
  const Page page(o);
  const std::vector<cv::Point3d> corners = page.points();
  const std::vector<cv::Point3d> edge = outline(page);
  const cv::Size big(o.width * o.ss, o.height * o.ss);
  std::uniform_real_distribution<double> u(0, 1);

  // Normalised-coordinate range of the image (for sampling where the board centre goes).
  std::vector<cv::Point2d> img_corners = {{0, 0}, {double(o.width - 1), double(o.height - 1)}};
  std::vector<cv::Point2d> nimg;
  cv::undistortPoints(img_corners, nimg, cam.K, cam.D, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));

  // ---- board frames
  {
    std::mt19937 rng(o.seed * 7919u + 1u);
    std::ofstream truth(root / "board" / "truth.csv"), poses(root / "board" / "poses.csv");
    write_csv_header(truth, poses);
    int n_full = 0;
    for (int f = 0; f < o.n_board; ++f) {
      const bool want_full = u(rng) >= o.partial_fraction;
      Pose P;
      std::vector<cv::Point2d> px;
      for (int attempt = 0;; ++attempt) {
        const double d = o.dmin + (o.dmax - o.dmin) * u(rng);
        const double tilt = o.max_tilt_deg * CV_PI / 180 * u(rng);
        const double az = 2 * CV_PI * u(rng), roll = 2 * CV_PI * u(rng);
        const double nx = nimg[0].x + (nimg[1].x - nimg[0].x) * u(rng);
        const double ny = nimg[0].y + (nimg[1].y - nimg[0].y) * u(rng);
        P = make_pose(page, nx, ny, d, tilt, az, roll);
        if (!in_front(edge, P) && want_full) continue;
        if (!in_front(corners, P)) continue;
        const auto out = project(edge, P, cam);
        px = project(corners, P, cam);
        bool all_in = true;
        for (const auto& p : out) all_in = all_in && inside(p, cam, 1.0);
        int corners_in = 0;
        for (const auto& p : px) corners_in += inside(p, cam, 0.0) ? 1 : 0;
        if (want_full && all_in) break;
        // partly out of view: between 30 % and 90 % of the inner corners in the image
        if (!want_full && !all_in && corners_in >= 0.3 * px.size() && corners_in <= 0.9 * px.size()) break;
        if (attempt > 100000) {
          std::cerr << "pose sampling failed\n";
          return 1;
        }
      }
      cv::Mat img = plain_background(big, rng);
      render_board(rays, P, page, make_gain(big, rng), img);
      cv::imwrite(frame_name(root / "board", f), finish(img, o, rng));
      write_truth(truth, poses, f, P, px, want_full);
      n_full += want_full ? 1 : 0;
    }
    std::cout << "board: " << o.n_board << " frames (" << n_full << " fully in view)\n";
  }

  // ---- frames without a board
  {
    std::mt19937 rng(o.seed * 7919u + 2u);
    std::ofstream kinds(root / "noboard" / "kinds.csv");
    kinds << "frame,kind\n";
    for (int f = 0; f < o.n_noboard; ++f) {
      const int kind = f % kNumNoBoardKinds;
      cv::Mat img = noboard_frame(kind, cv::Size(o.width, o.height), o.ss, rng);
      cv::imwrite(frame_name(root / "noboard", f), finish(img, o, rng));
      kinds << f << "," << kNoBoardKinds[kind] << "\n";
    }
    std::cout << "noboard: " << o.n_noboard << " frames\n";
  }

  // ---- smooth motion sequence: sums of sinusoids in the pose parameters
  {
    std::mt19937 rng(o.seed * 7919u + 3u);
    std::ofstream truth(root / "motion" / "truth.csv"), poses(root / "motion" / "poses.csv");
    write_csv_header(truth, poses);
    auto wave = [&](double lo, double hi) {
      const double period = lo + (hi - lo) * u(rng), phase = 2 * CV_PI * u(rng);
      return [=](double t) { return std::sin(2 * CV_PI * t / period + phase); };
    };
    const auto wd = wave(6, 9), wx = wave(4, 6), wy = wave(3.5, 5), wt1 = wave(4, 7), wt2 = wave(5, 8),
               wr = wave(7, 11);
    cv::Mat bg = plain_background(big, rng);
    cv::Mat gain = make_gain(big, rng);
    int n_full = 0;
    for (int f = 0; f < o.n_motion; ++f) {
      const double t = f / o.fps;
      // distance over most of [dmin, dmax], tilt up to max_tilt, the board wandering over the image
      const double d = 0.5 * (o.dmin + o.dmax) + 0.45 * (o.dmax - o.dmin) * wd(t);
      const double nx = 0.35 * wx(t), ny = 0.22 * wy(t);
      const double amp = o.max_tilt_deg * CV_PI / 180 * 0.8;
      const double ax = amp * wt1(t), ay = amp * wt2(t);  // tilt components, rad
      const double tilt = std::min(std::hypot(ax, ay), o.max_tilt_deg * CV_PI / 180);
      const double az = std::atan2(ay, ax);
      const double roll = 0.5 * wr(t);
      const Pose P = make_pose(page, nx, ny, d, tilt, az, roll);
      const auto px = project(corners, P, cam);
      const auto out = project(edge, P, cam);
      bool full = in_front(edge, P);
      for (const auto& p : out) full = full && inside(p, cam, 1.0);
      cv::Mat img = bg.clone();
      render_board(rays, P, page, gain, img);
      cv::imwrite(frame_name(root / "motion", f), finish(img, o, rng));
      write_truth(truth, poses, f, P, px, full);
      n_full += full ? 1 : 0;
    }
    std::cout << "motion: " << o.n_motion << " frames (" << n_full << " fully in view)\n";
  }
  return 0;
}
