// SPDX-License-Identifier: BSD-3-Clause
// Camera intrinsic calibration (calib/camera_intrinsics.hpp); method in docs/camera-calibration.md.
//
// 1. Start: the focal length from each view's homography (Zhang's two constraints with the
//    principal point at the centre and square pixels), the median over views, then refined on a
//    small geometric grid by the median reprojection error of per-view poses (solvePnP on the
//    observations undistorted through the candidate camera). The grid also serves a fisheye
//    (equidistant, k = 0), whose homographies are only roughly right, and sets where every
//    homography is degenerate (fronto-parallel views).
// 2. Dogleg over intrinsics, distortion and one pose per view (quaternion x R^3 on a product
//    manifold), with a Cauchy loss.
// 3. Rejection of views whose RMS is far above the median and of corners beyond k robust sigmas.
// 4. A plain least-squares solve of what remains, and the covariance of the camera parameters.

#include "calib/camera_intrinsics.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <time.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <optional>

#include "calib/camera_blocks.hpp"
#include "calib/marginal_covariance.hpp"
#include "calib/ray_pnp.hpp"
#include "calib/reprojection_cost.hpp"
#include "core/text_format.hpp"
#include "core/threads.hpp"

namespace imucal::calib {
namespace {

using Vec2 = Eigen::Vector2d;
using Pose = std::array<double, 7>;  // qw qx qy qz (Ceres order), tx ty tz: p_cam = R p_target + t

double cpu_now_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// One view in the solve.
struct View {
  std::size_t report = 0;  // index into the result's views
  std::vector<Eigen::Vector3d> target;
  std::vector<Vec2> px;
  std::vector<char> keep;  // per corner
  Pose pose{1, 0, 0, 0, 0, 0, 1};
  bool active = true;
  bool no_start_pose = false;  // rejected because the start camera gave it no pose

  int kept() const { return static_cast<int>(std::count(keep.begin(), keep.end(), 1)); }
};

template <class T>
void transform_point(const T* pose, const T* p_target, T* p_cam) {
  ceres::QuaternionRotatePoint(pose, p_target, p_cam);
  p_cam[0] += pose[4];
  p_cam[1] += pose[5];
  p_cam[2] += pose[6];
}

/// The residual of corner `i` of `view` under `camera`; NaN when the point is outside the
/// projection's domain (behind a pinhole camera).
Vec2 residual_of(const CameraModel& camera, const View& view, std::size_t i) {
  Eigen::Vector3d c;
  transform_point(view.pose.data(), view.target[i].data(), c.data());
  Vec2 m;
  bool computed = false;
  if (!camera.normalise(c, &m, &computed)) return Vec2::Constant(std::numeric_limits<double>::quiet_NaN());
  return camera.to_pixel(camera.distort(m)) - view.px[i];
}

/// RMS (per point, Euclidean) of the kept corners of a view.
double view_rms(const CameraModel& camera, const View& view) {
  double sum = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < view.px.size(); ++i) {
    if (!view.keep[i]) continue;
    sum += residual_of(camera, view, i).squaredNorm();
    ++n;
  }
  return n > 0 ? std::sqrt(sum / n) : std::numeric_limits<double>::quiet_NaN();
}

// ---- start ---------------------------------------------------------------------------------

/// Focal length from a target-to-image homography with the principal point at (cx, cy) and
/// square pixels: the image of the absolute conic omega = diag(a, a, 1) with a = 1 / f^2 meets
/// Zhang's constraints h1' w h2 = 0 and h1' w h1 = h2' w h2 in the least-squares sense.
std::optional<double> focal_from_homography(const cv::Mat& H, double cx, double cy) {
  Eigen::Matrix3d h;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) h(r, c) = H.at<double>(r, c);
  Eigen::Matrix3d shift = Eigen::Matrix3d::Identity();
  shift(0, 2) = -cx;
  shift(1, 2) = -cy;
  h = shift * h;
  const Eigen::Vector2d A(h(0, 0) * h(0, 1) + h(1, 0) * h(1, 1),
                          h(0, 0) * h(0, 0) + h(1, 0) * h(1, 0) - h(0, 1) * h(0, 1) - h(1, 1) * h(1, 1));
  const Eigen::Vector2d b(h(2, 0) * h(2, 1), h(2, 0) * h(2, 0) - h(2, 1) * h(2, 1));
  const double a = -A.dot(b) / A.squaredNorm();
  if (!(a > 0.0) || !std::isfinite(a)) return std::nullopt;
  return 1.0 / std::sqrt(a);
}

/// The pose of a view under `camera` from its observations unprojected through the camera
/// (calib/ray_pnp.hpp: also for views beyond 90 degrees off the axis); nullopt when it fails or
/// a target point falls outside the projection's domain.
std::optional<Pose> pose_from_pnp(const CameraModel& camera, const View& view) {
  std::vector<Eigen::Vector3d> rays, points;
  for (std::size_t i = 0; i < view.px.size(); ++i) {
    if (!view.keep[i]) continue;
    Eigen::Vector3d ray;
    if (!camera.unproject(view.px[i], &ray)) continue;
    rays.push_back(ray);
    points.push_back(view.target[i]);
  }
  const auto found = pose_from_rays(points, rays, false);
  if (!found) return std::nullopt;
  const Eigen::Quaterniond q(found->R_cam_target);
  const Eigen::Vector3d& t = found->t_cam_target;
  Pose pose{q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()};
  for (const auto& p : view.target) {
    Eigen::Vector3d c;
    transform_point(pose.data(), p.data(), c.data());
    Vec2 m;
    bool computed = false;
    if (!camera.normalise(c, &m, &computed)) return std::nullopt;
  }
  return pose;
}

/// A shape the start tries for a model: the projection's parameters and distortion, and the
/// ratio of the focal length to the image scale near the centre (omni and ds: 1 + xi).
struct StartShape {
  Eigen::Vector2d projection = Eigen::Vector2d::Zero();
  Eigen::Vector4d distortion = Eigen::Vector4d::Zero();
  double focal_factor = 1.0;
};

/// The start shapes of a model (docs/camera-calibration.md, "Start"): the undistorted pinhole;
/// FOV w of 0.5 and 1 rad; omni xi of 0.5, 1 and 1.5; eucm alpha of 0.5, 0.6 and 0.7 with beta
/// 1; ds xi of -0.3 to 0.3 with alpha of 0.5 and 0.6 (xi 0 and alpha 0.5, as eucm's (0.5, 1),
/// is the stereographic projection, which reaches beyond 180 degrees). Omni's and ds's image
/// scale near the centre is f / (1 + xi).
std::vector<StartShape> start_shapes(CameraModelKind model) {
  const Eigen::Vector4d none = Eigen::Vector4d::Zero();
  std::vector<StartShape> out;
  switch (model.projection) {
    case ProjectionModel::kPinhole:
      if (model.distortion == DistortionModel::kFov) {
        return {{{0, 0}, {0.5, 0, 0, 0}, 1.0}, {{0, 0}, {1.0, 0, 0, 0}, 1.0}};
      }
      return {StartShape{}};
    case ProjectionModel::kOmni:
      for (double xi : {0.5, 1.0, 1.5}) out.push_back({{xi, 0}, none, 1.0 + xi});
      return out;
    case ProjectionModel::kEucm:
      for (double alpha : {0.5, 0.6, 0.7}) out.push_back({{alpha, 1.0}, none, 1.0});
      return out;
    case ProjectionModel::kDs:
      for (double xi : {-0.3, -0.15, 0.0, 0.15, 0.3})
        for (double alpha : {0.5, 0.6}) out.push_back({{xi, alpha}, none, 1.0 + xi});
      return out;
  }
  return {StartShape{}};
}

CameraModel start_camera(CameraModelKind model, int width, int height, double focal,
                         const StartShape& shape) {
  CameraModel camera;
  camera.projection = model.projection;
  camera.distortion_model = model.distortion;
  camera.width = width;
  camera.height = height;
  camera.intrinsics = {focal, focal, 0.5 * (width - 1), 0.5 * (height - 1)};
  camera.projection_params = shape.projection;
  camera.distortion_coeffs = shape.distortion;
  return camera;
}

/// Median RMS of the sample views' PnP poses under `camera`.
double start_score(const CameraModel& camera, const std::vector<View>& views,
                   const std::vector<std::size_t>& sample) {
  std::vector<double> rms;
  for (std::size_t i : sample) {
    View v = views[i];
    const auto pose = pose_from_pnp(camera, v);
    if (!pose) continue;
    v.pose = *pose;
    rms.push_back(view_rms(camera, v));
  }
  // A candidate under which fewer than half the views find a pose is not a start.
  if (rms.size() * 2 < sample.size()) return std::numeric_limits<double>::infinity();
  return median(rms);
}

/// The focal lengths of the views' homographies (principal point at the centre).
std::vector<double> homography_focals(int width, int height, const std::vector<View>& views,
                                      const std::vector<std::size_t>& sample) {
  std::vector<double> focals;
  for (std::size_t i : sample) {
    std::vector<cv::Point2d> src, dst;
    for (std::size_t k = 0; k < views[i].px.size(); ++k) {
      src.emplace_back(views[i].target[k].x(), views[i].target[k].y());
      dst.emplace_back(views[i].px[k].x(), views[i].px[k].y());
    }
    cv::Mat H;
    try {
      H = cv::findHomography(src, dst, 0);
    } catch (const cv::Exception&) {
      continue;
    }
    if (H.empty()) continue;
    const auto f = focal_from_homography(H, 0.5 * (width - 1), 0.5 * (height - 1));
    if (f && *f > 0.05 * width && *f < 50.0 * width) focals.push_back(*f);
  }
  return focals;
}

/// The starting cameras (docs/camera-calibration.md, "Start"), best first: for each of the
/// model's start shapes, the best of a geometric grid of focal lengths around the homographies'
/// (quarter octaves) scored by the reprojection of per-view poses; shapes under which no focal
/// length gives a pose are left out (all of them: the first shape at the homographies' focal).
std::vector<CameraModel> start_cameras_for(CameraModelKind model, int width, int height,
                                           const std::vector<View>& views) {
  std::vector<std::size_t> sample;
  constexpr std::size_t kSample = 40;
  const std::size_t step = std::max<std::size_t>(1, views.size() / kSample);
  for (std::size_t i = 0; i < views.size(); i += step) sample.push_back(i);
  const std::vector<double> focals = homography_focals(width, height, views, sample);
  // The homography estimate, or the image width when every view was degenerate for it.
  const bool have = !focals.empty();
  const double base = have ? median(focals) : static_cast<double>(width);
  const int span = have ? 4 : 8;
  std::vector<std::pair<double, CameraModel>> scored;
  for (const StartShape& shape : start_shapes(model)) {
    CameraModel best = start_camera(model, width, height, base, shape);
    double best_score = std::numeric_limits<double>::infinity();
    for (int k = -span; k <= span; ++k) {
      const CameraModel camera =
          start_camera(model, width, height, base * shape.focal_factor * std::pow(2.0, k / 4.0), shape);
      const double score = start_score(camera, views, sample);
      if (score < best_score) {
        best_score = score;
        best = camera;
      }
    }
    if (std::isfinite(best_score)) scored.emplace_back(best_score, best);
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<CameraModel> out;
  for (auto& [score, camera] : scored) out.push_back(std::move(camera));
  if (out.empty()) out.push_back(start_camera(model, width, height, base, start_shapes(model).front()));
  return out;
}

// ---- solve ---------------------------------------------------------------------------------

/// Reports the solver's iterations as progress within [from, to).
class ProgressCallback final : public ceres::IterationCallback {
 public:
  ProgressCallback(const ProgressFn& progress, double from, double to, int max_iterations)
      : progress_(progress), from_(from), to_(to), max_(max_iterations) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    report_progress(progress_, from_ + (to_ - from_) * std::min(1.0, summary.iteration / double(max_)), 1.0);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const ProgressFn& progress_;
  double from_, to_;
  int max_;
};

/// The camera's parameter blocks: intrinsics fu fv pu pv, the projection's two parameters and
/// four distortion coefficients, of which a model uses the first projection_param_count and
/// distortion_coeff_count; the others stay constant.
struct CameraBlocks {
  Eigen::Vector4d intrinsics = Eigen::Vector4d::Zero();
  Eigen::Vector2d projection = Eigen::Vector2d::Zero();
  Eigen::Vector4d distortion = Eigen::Vector4d::Zero();
};

/// The least-squares problem over the active views; kept alive for the covariance.
class IntrinsicsProblem {
 public:
  IntrinsicsProblem(CameraBlocks* camera, std::vector<View>* views, CameraModelKind model, bool robust,
                    double loss_px)
      : loss_(loss_px), model_(model) {
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(po);
    intrinsics_ = camera->intrinsics.data();
    projection_ = camera->projection.data();
    distortion_ = camera->distortion.data();
    for (View& v : *views) {
      if (!v.active) continue;
      for (std::size_t i = 0; i < v.px.size(); ++i) {
        if (!v.keep[i]) continue;
        problem_->AddResidualBlock(new ReprojectionCost(v.target[i], v.px[i], model),
                                   robust ? &loss_ : nullptr, intrinsics_, projection_, distortion_,
                                   v.pose.data());
        ++residuals_;
      }
      problem_->SetManifold(v.pose.data(), &pose_manifold_);
      poses_.push_back(v.pose.data());
    }
    if (residuals_ == 0) return;
    // The entries a model does not use are held (at the start's 0).
    hold_unused_camera_entries(problem_.get(), model, projection_, distortion_);
  }

  /// Solves; false when the solver gives no usable solution.
  bool solve(int max_iterations, int threads, ProgressCallback* callback, int* iterations, double* cost) {
    ceres::Solver::Options o;
    // Dogleg: a rejected step costs no new factorization (docs/camera-calibration.md, "Method").
    o.trust_region_strategy_type = ceres::DOGLEG;
    // Poses first in the elimination: the reduced camera system is at most 10 x 10.
    o.linear_solver_type = ceres::DENSE_SCHUR;
    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    for (double* p : poses_) ordering->AddElementToGroup(p, 0);
    for (double* p : {intrinsics_, projection_, distortion_}) ordering->AddElementToGroup(p, 1);
    o.linear_solver_ordering = ordering;
    o.num_threads = threads;
    o.max_num_iterations = max_iterations;
    // A relative change of 1e-9 in the cost is a chi-square change far below 0.01 on any
    // recording of more than a few views: the estimate then moves by well under a hundredth of
    // its sigma.
    o.function_tolerance = 1e-9;
    o.gradient_tolerance = 1e-12;
    o.parameter_tolerance = 1e-12;
    o.logging_type = ceres::SILENT;
    if (callback) o.callbacks.push_back(callback);
    ceres::Solver::Summary summary;
    ceres::Solve(o, problem_.get(), &summary);
    *iterations += static_cast<int>(summary.iterations.size());
    *cost = summary.final_cost;
    return summary.IsSolutionUsable();
  }

  /// The 10 x 10 covariance of [intrinsics, projection, distortion] (unscaled: J'J inverse; 0 in
  /// the rows and columns of the entries held), or nullopt when the data do not determine every
  /// used entry. (ceres::Covariance is not used: with the manifold that holds a block's unused
  /// entries, its lifting to the ambient space frees memory it did not allocate in the sanitized
  /// build; MarginalCovariance works in the tangent space, whose coordinates are the used entries.)
  std::optional<Eigen::Matrix<double, 10, 10>> covariance(int threads) {
    std::vector<const double*> wanted;
    for (const double* x : {intrinsics_, projection_, distortion_})
      if (problem_->HasParameterBlock(x) && !problem_->IsParameterBlockConstant(x)) wanted.push_back(x);
    MarginalCovariance cov;
    if (!cov.compute(*problem_, wanted, threads)) return std::nullopt;
    const Eigen::Matrix<double, 10, 10> out = camera_covariance(
        model_, {intrinsics_, projection_, distortion_},
        [&cov](const double* a, const double* b, int rows, int cols) -> Eigen::MatrixXd {
          if (cov.has(a) && cov.has(b)) return cov.block(a, b);
          return Eigen::MatrixXd::Constant(rows, cols, std::numeric_limits<double>::quiet_NaN());
        });
    if (!out.allFinite()) return std::nullopt;
    return out;
  }

  int residuals() const { return residuals_; }
  int poses() const { return static_cast<int>(poses_.size()); }

  /// Holds the projection's first parameter (xi, or eucm's alpha) at its value.
  void hold_first_projection_param() {
    if (projection_param_count(model_.projection) == 1) {
      problem_->SetParameterBlockConstant(projection_);
    } else {
      problem_->SetManifold(projection_, &first_held_);
    }
  }

 private:
  ceres::CauchyLoss loss_;
  CameraModelKind model_;
  ceres::SubsetManifold first_held_{2, {0}};
  ceres::ProductManifold<ceres::QuaternionManifold, ceres::EuclideanManifold<3>> pose_manifold_;
  std::unique_ptr<ceres::Problem> problem_;
  std::vector<double*> poses_;
  double* intrinsics_ = nullptr;
  double* projection_ = nullptr;
  double* distortion_ = nullptr;
  int residuals_ = 0;
};

// ---- views and rejection ------------------------------------------------------------------

/// Builds the views from the observations; rejects those that cannot hold a pose.
Result<std::vector<View>> make_views(const TargetDescription& target, std::span<const TargetObservation> obs,
                                     const CameraIntrinsicsOptions& options, CameraIntrinsicsResult* result) {
  const std::vector<Eigen::Vector3d> points = target.points();
  std::vector<View> views;
  for (const TargetObservation& o : obs) {
    if (o.empty()) continue;
    if (o.ids.size() != o.px.size()) {
      return make_error(Errc::kInvalidArgument, "an observation has " + std::to_string(o.ids.size()) +
                                                    " ids but " + std::to_string(o.px.size()) + " pixels");
    }
    if (result->camera.width == 0) {
      result->camera.width = o.width;
      result->camera.height = o.height;
    }
    if (o.width != result->camera.width || o.height != result->camera.height || o.width <= 0 ||
        o.height <= 0) {
      return make_error(Errc::kInvalidArgument, "the observations come from images of different sizes (" +
                                                    std::to_string(result->camera.width) + "x" +
                                                    std::to_string(result->camera.height) + " and " +
                                                    std::to_string(o.width) + "x" + std::to_string(o.height) +
                                                    "): calibrate one camera at one resolution");
    }
    CameraViewReport report;
    report.t_ns = o.t_ns;
    report.points = static_cast<int>(o.ids.size());
    View v;
    v.report = result->views.size();
    for (std::size_t i = 0; i < o.ids.size(); ++i) {
      if (o.ids[i] < 0 || o.ids[i] >= static_cast<int>(points.size()) || !o.px[i].allFinite()) {
        return make_error(
            Errc::kInvalidArgument,
            "an observation holds point id " + std::to_string(o.ids[i]) + ", which the target does not have");
      }
      v.target.push_back(points[static_cast<std::size_t>(o.ids[i])]);
      v.px.push_back(o.px[i]);
    }
    v.keep.assign(v.px.size(), 1);
    if (report.points < options.min_points_per_view) {
      report.rejected_because = "too few points (" + std::to_string(report.points) + ")";
      v.active = false;
    } else {
      // Points along one line fix no pose: the smaller spread of the target points must be
      // at least a tenth of the larger.
      Eigen::MatrixXd xy(2, static_cast<Eigen::Index>(v.target.size()));
      for (std::size_t i = 0; i < v.target.size(); ++i)
        xy.col(static_cast<Eigen::Index>(i)) = v.target[i].head<2>();
      const Eigen::MatrixXd centred = xy.colwise() - xy.rowwise().mean();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(centred * centred.transpose());
      if (!(es.eigenvalues()[0] > 0.01 * es.eigenvalues()[1])) {
        report.rejected_because = "the points lie nearly on one line";
        v.active = false;
      }
    }
    result->views.push_back(report);
    views.push_back(std::move(v));
  }
  return views;
}

int active_count(const std::vector<View>& views) {
  return static_cast<int>(std::count_if(views.begin(), views.end(), [](const View& v) { return v.active; }));
}

void reject_view(View& v, CameraIntrinsicsResult* result, std::string why) {
  v.active = false;
  result->views[v.report].rejected_because = std::move(why);
}

/// Drops views whose RMS is far above the median of the active views.
void reject_views(const CameraModel& camera, std::vector<View>& views, const CameraIntrinsicsOptions& options,
                  CameraIntrinsicsResult* result) {
  std::vector<double> rms(views.size(), 0.0), active;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!views[i].active) continue;
    rms[i] = view_rms(camera, views[i]);
    active.push_back(rms[i]);
  }
  const double med = median(active);
  const double limit = std::max(options.view_rms_factor * med, options.view_rms_floor_px);
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!views[i].active) continue;
    result->views[views[i].report].rms_px = rms[i];
    if (!(rms[i] <= limit)) {
      reject_view(views[i], result,
                  "reprojection RMS " + format_number("%.3g", rms[i]) + " px, above " +
                      format_number("%.3g", limit) + " px (" + format_number("%g", options.view_rms_factor) +
                      " x the median " + format_number("%.3g", med) + " px)");
    }
  }
}

/// Drops corners beyond corner_sigmas robust sigmas; returns how many were dropped.
int reject_corners(const CameraModel& camera, std::vector<View>& views,
                   const CameraIntrinsicsOptions& options, CameraIntrinsicsResult* result) {
  std::vector<double> abs_res;
  for (const View& v : views) {
    if (!v.active) continue;
    for (std::size_t i = 0; i < v.px.size(); ++i) {
      if (!v.keep[i]) continue;
      const Vec2 r = residual_of(camera, v, i);
      abs_res.push_back(std::abs(r.x()));
      abs_res.push_back(std::abs(r.y()));
    }
  }
  const double sigma = 1.4826 * median(abs_res);
  const double limit = std::max(options.corner_sigmas * sigma, options.corner_floor_px);
  int dropped = 0;
  for (View& v : views) {
    if (!v.active) continue;
    for (std::size_t i = 0; i < v.px.size(); ++i) {
      if (!v.keep[i]) continue;
      if (!(residual_of(camera, v, i).cwiseAbs().maxCoeff() <= limit)) {
        v.keep[i] = 0;
        ++dropped;
      }
    }
    if (v.kept() < options.min_points_per_view) {
      reject_view(v, result,
                  "too few points (" + std::to_string(v.kept()) + ") after rejecting corners beyond " +
                      format_number("%.3g", limit) + " px");
    }
  }
  return dropped;
}

Error too_few_views(const std::vector<View>& views, const CameraIntrinsicsResult& result,
                    const CameraIntrinsicsOptions& options) {
  std::map<std::string, int> reasons;
  for (const auto& r : result.views) {
    if (r.rejected_because.empty()) continue;
    // Group by the reason's first words (the figures differ from view to view).
    const std::string key = r.rejected_because.substr(0, r.rejected_because.find_first_of("(0123456789"));
    ++reasons[key];
  }
  std::string why;
  for (const auto& [reason, n] : reasons) why += "; " + std::to_string(n) + " x " + reason;
  return make_error(Errc::kInsufficientData,
                    std::to_string(active_count(views)) + " usable views of " + std::to_string(views.size()) +
                        " with the target, fewer than the " + std::to_string(options.min_views) + " needed" +
                        why +
                        ": record more views of the whole target, tilted in different directions at several "
                        "distances, across the image");
}

/// Another start's solution and how much more it costs per corner than the kept one.
struct StartSolution {
  CameraBlocks camera;
  double cost_per_corner = 0.0;
};

/// The robust pass (docs/camera-calibration.md, "Start"): from the best start, and for a model
/// with projection parameters (which trade against the focal length, so that one start can end
/// in a local minimum) from each of its kMaxStarts best start shapes, keeping the solve with the
/// lowest cost per corner. The winner's views (poses, rejections) and reports are kept, the
/// others' solutions go to `others`.
Status solve_from_starts(const std::vector<CameraModel>& starts, const CameraIntrinsicsOptions& options,
                         int threads, const ProgressFn& progress, std::vector<View>* views,
                         CameraIntrinsicsResult* result, CameraBlocks* blocks, double* cost,
                         std::vector<StartSolution>* others) {
  constexpr std::size_t kMaxStarts = 3;
  const std::size_t tries =
      projection_param_count(options.model.projection) > 0 ? std::min(kMaxStarts, starts.size()) : 1;
  std::optional<Error> first_error;
  double best = std::numeric_limits<double>::infinity();
  int iterations = result->iterations;
  for (std::size_t s = 0; s < tries; ++s) {
    std::vector<View> v = *views;
    CameraIntrinsicsResult r = *result;
    for (View& view : v) {
      if (!view.active) continue;
      const auto pose = pose_from_pnp(starts[s], view);
      if (pose) {
        view.pose = *pose;
      } else {
        reject_view(view, &r, "no pose found for the start (the detection may be wrong)");
        view.no_start_pose = true;
      }
    }
    if (active_count(v) < options.min_views) {
      if (!first_error) first_error = too_few_views(v, r, options);
      continue;
    }
    CameraBlocks b{starts[s].intrinsics, starts[s].projection_params, starts[s].distortion_coeffs};
    double c = 0.0;
    int corners = 0;
    bool solved = false;
    {
      IntrinsicsProblem robust(&b, &v, options.model, true, options.robust_loss_px);
      const double from = 0.05 + 0.45 * static_cast<double>(s) / static_cast<double>(tries);
      ProgressCallback cb(progress, from, from + 0.45 / static_cast<double>(tries), options.max_iterations);
      solved = robust.solve(options.max_iterations, threads, &cb, &iterations, &c);
      corners = robust.residuals();
    }
    if (!solved || !b.intrinsics.allFinite() || !b.projection.allFinite() || !b.distortion.allFinite()) {
      if (!first_error)
        first_error = make_error(Errc::kSolverFailed,
                                 "the camera solve (robust pass) did not converge; check the target "
                                 "description against the target that was recorded");
      continue;
    }
    const double per_corner = c / std::max(1, corners);
    if (per_corner < best) {
      if (std::isfinite(best)) others->push_back({*blocks, best});
      best = per_corner;
      *views = std::move(v);
      *result = std::move(r);
      *blocks = b;
      *cost = c;
    } else {
      others->push_back({b, per_corner});
    }
  }
  result->iterations = iterations;
  if (!std::isfinite(best)) return *first_error;
  for (StartSolution& o : *others) o.cost_per_corner -= best;
  return {};
}

/// The model's camera with the solved blocks.
CameraModel camera_of(CameraModelKind model, int width, int height, const CameraBlocks& blocks) {
  CameraModel camera;
  camera.projection = model.projection;
  camera.distortion_model = model.distortion;
  camera.width = width;
  camera.height = height;
  camera.intrinsics = blocks.intrinsics;
  camera.projection_params = blocks.projection;
  camera.distortion_coeffs = blocks.distortion;
  return camera;
}

/// solve_from_starts on at most options.start_views views spread evenly over the recording, then
/// every view from that camera (its pose by PnP) in one more robust pass, which starts at the
/// solution and takes a few iterations; the starts' other solutions keep their cost per corner of
/// the subset. With fewer than twice start_views views (or start_views 0) every view is used from
/// the start.
Status solve_starts_on_subset(const std::vector<CameraModel>& starts, const CameraIntrinsicsOptions& options,
                              int threads, const ProgressFn& progress, std::vector<View>* views,
                              CameraIntrinsicsResult* result, CameraBlocks* blocks, double* cost,
                              std::vector<StartSolution>* others) {
  const int active = active_count(*views);
  if (options.start_views == 0 || active < 2 * options.start_views) {
    return solve_from_starts(starts, options, threads, progress, views, result, blocks, cost, others);
  }
  std::vector<View> subset;
  subset.reserve(static_cast<std::size_t>(options.start_views));
  int k = 0;
  for (const View& v : *views) {
    if (!v.active) continue;
    if (opens_slot(k, active, options.start_views)) subset.push_back(v);
    ++k;
  }
  CameraIntrinsicsResult on_subset = *result;
  IMUCAL_TRY(
      solve_from_starts(starts, options, threads, progress, &subset, &on_subset, blocks, cost, others));
  result->iterations = on_subset.iterations;
  const CameraModel camera = camera_of(options.model, result->camera.width, result->camera.height, *blocks);
  for (View& v : *views) {
    if (!v.active) continue;
    const auto pose = pose_from_pnp(camera, v);
    if (pose) {
      v.pose = *pose;
    } else {
      reject_view(v, result,
                  "no pose found under the camera of the first views (the detection may be wrong)");
      v.no_start_pose = true;
    }
  }
  if (active_count(*views) < options.min_views) return too_few_views(*views, *result, options);
  IntrinsicsProblem robust(blocks, views, options.model, true, options.robust_loss_px);
  if (!robust.solve(options.max_iterations, threads, nullptr, &result->iterations, cost) ||
      !blocks->intrinsics.allFinite() || !blocks->projection.allFinite() || !blocks->distortion.allFinite()) {
    return make_error(Errc::kSolverFailed,
                      "the camera solve (robust pass over every view) did not converge; check the target "
                      "description against the target that was recorded");
  }
  return {};
}

/// The views the start camera gave no pose (a wide lens's border beyond the start's field of
/// view) tried again under the robust pass's camera; when any finds its pose now, the robust pass
/// runs again with them.
Status readmit_views(CameraModelKind model, const CameraIntrinsicsOptions& options, int threads,
                     std::vector<View>* views, CameraIntrinsicsResult* result, CameraBlocks* blocks,
                     double* cost) {
  const CameraModel camera = camera_of(model, result->camera.width, result->camera.height, *blocks);
  int readmitted = 0;
  for (View& v : *views) {
    if (v.active || !v.no_start_pose) continue;
    const auto pose = pose_from_pnp(camera, v);
    if (!pose) continue;
    v.pose = *pose;
    v.active = true;
    v.no_start_pose = false;
    result->views[v.report].rejected_because.clear();
    ++readmitted;
  }
  if (readmitted == 0) return {};
  IntrinsicsProblem robust(blocks, views, model, true, options.robust_loss_px);
  if (!robust.solve(options.max_iterations, threads, nullptr, &result->iterations, cost)) {
    return make_error(Errc::kSolverFailed,
                      "the camera solve (robust pass with the views found again) did not converge; check the "
                      "target description against the target that was recorded");
  }
  return {};
}

/// The camera's parameters as the 10-vector of the covariance.
Eigen::Matrix<double, 10, 1> parameter_vector(const CameraBlocks& b) {
  Eigen::Matrix<double, 10, 1> x;
  x << b.intrinsics, b.projection, b.distortion;
  return x;
}

/// Widens the covariance for the other starts' cameras that fit as well (CameraIntrinsicsResult::
/// ambiguity): the chi-square of the difference in cost below 4, the difference beyond 3 sigmas
/// in one of the model's parameters.
void widen_for_equal_fits(const std::vector<StartSolution>& others, int corners,
                          CameraIntrinsicsResult* result) {
  if (!result->covariance_ok || !(result->residual_sigma_px > 0.0)) return;
  const double var = result->residual_sigma_px * result->residual_sigma_px;
  const std::vector<int> used = kalibr_parameter_indices(result->camera.kind());
  const std::vector<std::string> names = kalibr_parameter_names(result->camera.kind());
  CameraBlocks kept{result->camera.intrinsics, result->camera.projection_params,
                    result->camera.distortion_coeffs};
  const Eigen::Matrix<double, 10, 1> x = parameter_vector(kept);
  Eigen::Matrix<double, 10, 10> widened = result->covariance;
  for (const StartSolution& o : others) {
    const double chi2 = 2.0 * o.cost_per_corner * corners / var;
    if (!(chi2 < 4.0)) continue;
    const Eigen::Matrix<double, 10, 1> d = parameter_vector(o.camera) - x;
    bool apart = false;
    for (int i : used) apart = apart || std::abs(d[i]) > 3.0 * std::sqrt(result->covariance(i, i));
    if (!apart) continue;
    widened += d * d.transpose();
    std::string kept_text, other_text;
    for (std::size_t j = 0; j < used.size(); ++j) {
      kept_text += (j ? ", " : "") + names[j] + " " + format_number("%.4g", x[used[j]]);
      other_text += (j ? ", " : "") + names[j] + " " + format_number("%.4g", x[used[j]] + d[used[j]]);
    }
    result->ambiguity = "the views fit two cameras equally well (chi-square of the difference " +
                        format_number("%.2g", chi2) + "): [" + kept_text + "] (kept) and [" + other_text +
                        "]; the sigmas are widened to cover both";
  }
  if (result->ambiguity.empty()) return;
  set_camera_covariance(widened, result);
  result->warnings.push_back(
      result->ambiguity +
      ": the model's parameters are not determined by these views (the image they give "
      "is); show the target nearer the image's edges and at more angles, or choose a model "
      "with fewer parameters");
}

/// The profile check (docs/camera-calibration.md, "Uncertainty"): the omni, eucm and ds models'
/// projection parameters trade against the focal length and the distortion along a curved
/// valley, which the covariance (a quadratic about the solution) makes too narrow. The first
/// projection parameter is held at kProfileSigmas of its sigma on either side and the rest solved
/// again; where the cost rises by less than the quadratic's kProfileSigmas^2 (in chi-square) on
/// the flatter side, the covariance is stretched along the path the solution took there (the
/// other parameters follow the valley's curve, not the quadratic's straight line):
/// C += (k^2 - 1) u u^T, u = (profiled - solved) / kProfileSigmas, k^2 = kProfileSigmas^2 /
/// chi-square (at most 100).
void profile_first_projection_param(const CameraBlocks& solved, const std::vector<View>& views, double cost,
                                    const CameraIntrinsicsOptions& options, int threads,
                                    CameraIntrinsicsResult* result) {
  constexpr double kProfileSigmas = 3.0;
  if (projection_param_count(options.model.projection) == 0 || !result->covariance_ok) return;
  const double var = result->residual_sigma_px * result->residual_sigma_px;
  const double sigma = std::sqrt(result->covariance(4, 4));
  if (!(var > 0.0) || !(sigma > 0.0)) return;
  double least = std::numeric_limits<double>::infinity();
  Eigen::Matrix<double, 10, 1> path = Eigen::Matrix<double, 10, 1>::Zero();  // the flatter side's, per sigma
  for (const double side : {-1.0, 1.0}) {
    CameraBlocks b = solved;
    b.projection[0] += side * kProfileSigmas * sigma;
    std::vector<View> v = views;
    IntrinsicsProblem problem(&b, &v, options.model, false, options.robust_loss_px);
    problem.hold_first_projection_param();
    int iterations = 0;
    double c = 0.0;
    if (!problem.solve(options.max_iterations, threads, nullptr, &iterations, &c)) continue;
    const double chi2 = 2.0 * (c - cost) / var;
    if (chi2 < least) {
      least = chi2;
      path = (parameter_vector(b) - parameter_vector(solved)) / kProfileSigmas;
    }
  }
  result->profile_chi2 = least;
  const double expected = kProfileSigmas * kProfileSigmas;
  if (!(least < expected)) return;
  const double k2 = std::min(100.0, expected / std::max(least, 1e-9));
  set_camera_covariance(result->covariance + (k2 - 1.0) * path * path.transpose(), result);
  result->profile_stretch = std::sqrt(k2);
}

// ---- figures -------------------------------------------------------------------------------

void fill_figures(const CameraModel& camera, const std::vector<View>& views,
                  const CameraIntrinsicsOptions& options, CameraIntrinsicsResult* result) {
  std::vector<Vec2> used;
  for (const View& v : views) {
    if (!v.active) continue;
    for (std::size_t i = 0; i < v.px.size(); ++i)
      if (v.keep[i]) used.push_back(v.px[i]);
  }
  set_coverage(camera.width, camera.height, options.coverage_cols, used, result);
  double sum = 0.0;
  int n = 0;
  std::vector<Eigen::Vector2f> all;
  std::vector<std::uint8_t> rejected;
  for (const View& v : views) {
    CameraViewReport& report = result->views[v.report];
    if (!v.active) continue;
    report.used = true;
    report.points_used = v.kept();
    report.rms_px = view_rms(camera, v);
    report.q_cam_target = Eigen::Quaterniond(v.pose[0], v.pose[1], v.pose[2], v.pose[3]).normalized();
    report.t_cam_target = Eigen::Vector3d(v.pose[4], v.pose[5], v.pose[6]);
    for (std::size_t i = 0; i < v.px.size(); ++i) {
      all.push_back(residual_of(camera, v, i).cast<float>());
      rejected.push_back(v.keep[i] ? 0 : 1);
      if (!v.keep[i]) continue;
      sum += residual_of(camera, v, i).squaredNorm();
      ++n;
    }
  }
  const std::size_t cap = CameraIntrinsicsResult::kMaxStoredResiduals;
  const std::size_t step = std::max<std::size_t>(1, (all.size() + cap - 1) / cap);
  for (std::size_t i = 0; i < all.size(); i += step) {
    result->residuals_px.push_back(all[i]);
    result->residual_rejected.push_back(rejected[i]);
  }
  result->views_used = active_count(views);
  result->points_used = n;
  result->rms_px = n > 0 ? std::sqrt(sum / n) : 0.0;
}

/// Sigmas from the covariance, the degeneracy check and the warnings.
void fill_uncertainty(IntrinsicsProblem& problem, double cost, const CameraIntrinsicsOptions& options,
                      int threads, CameraIntrinsicsResult* result) {
  const double n = 2.0 * problem.residuals();  // coordinates: 2 per corner
  const double p = free_camera_params(result->camera.kind()) + 6.0 * problem.poses();
  const double dof = n - p;
  result->residual_sigma_px =
      dof > 0.0 ? std::sqrt(2.0 * cost / dof) : std::numeric_limits<double>::quiet_NaN();
  const auto cov = options.covariance ? problem.covariance(threads) : std::nullopt;
  if (cov && dof > 0.0) {
    set_camera_covariance(*cov * (result->residual_sigma_px * result->residual_sigma_px), result);
  } else {
    set_camera_covariance(std::nullopt, result);
  }
  const auto& k = result->camera.intrinsics;
  const double rel = std::max(result->intrinsics_sigma[0] / k[0], result->intrinsics_sigma[1] / k[1]);
  result->focal_well_determined = result->covariance_ok && rel <= options.max_focal_relative_sigma;
}

}  // namespace

Result<CameraIntrinsicsResult> calibrate_camera_intrinsics(const TargetDescription& target,
                                                           std::span<const TargetObservation> observations,
                                                           const CameraIntrinsicsOptions& options,
                                                           const ProgressFn& progress) {
  IMUCAL_TRY(options.validate());
  IMUCAL_TRY(target.validate());
  const double cpu0 = cpu_now_s();
  CameraIntrinsicsResult result;
  auto made = make_views(target, observations, options, &result);
  if (!made.ok()) return made.error();
  std::vector<View> views = std::move(*made);
  result.views_total = static_cast<int>(views.size());
  if (active_count(views) < options.min_views) return too_few_views(views, result, options);
  const int width = result.camera.width;
  const int height = result.camera.height;
  const int threads = threads_or_cores(options.threads);

  // Start.
  std::vector<View> usable;
  for (const View& v : views)
    if (v.active) usable.push_back(v);
  if (!camera_model_supported(options.model)) {
    return make_error(Errc::kInvalidArgument,
                      "camera model " + camera_model_name(options.model) + " is not one imucal calibrates");
  }
  const std::vector<CameraModel> starts = start_cameras_for(options.model, width, height, usable);
  report_progress(progress, 0.05, 1.0);
  CameraBlocks blocks;
  double cost = 0.0;
  std::vector<StartSolution> others;
  IMUCAL_TRY(
      solve_starts_on_subset(starts, options, threads, progress, &views, &result, &blocks, &cost, &others));
  IMUCAL_TRY(readmit_views(options.model, options, threads, &views, &result, &blocks, &cost));
  const CameraModel camera = camera_of(options.model, width, height, blocks);
  reject_views(camera, views, options, &result);
  result.corners_rejected = reject_corners(camera, views, options, &result);
  if (active_count(views) < options.min_views) return too_few_views(views, result, options);

  IntrinsicsProblem plain(&blocks, &views, options.model, false, options.robust_loss_px);
  ProgressCallback cb(progress, 0.5, 0.9, options.max_iterations);
  if (!plain.solve(options.max_iterations, threads, &cb, &result.iterations, &cost) ||
      !blocks.intrinsics.allFinite() || !blocks.projection.allFinite() || !blocks.distortion.allFinite()) {
    return make_error(Errc::kSolverFailed, "the camera solve (final pass) did not converge");
  }
  result.camera.projection = options.model.projection;
  result.camera.distortion_model = options.model.distortion;
  result.camera.intrinsics = blocks.intrinsics;
  result.camera.projection_params = blocks.projection;
  result.camera.distortion_coeffs = blocks.distortion;
  if (auto valid = validate_camera(result.camera); !valid.ok()) {
    return make_error(Errc::kSolverFailed, "the camera solve gave an unusable camera (" +
                                               valid.error().message +
                                               "); check the target description and the detections");
  }
  fill_figures(result.camera, views, options, &result);
  fill_uncertainty(plain, cost, options, threads, &result);
  profile_first_projection_param(blocks, views, cost, options, threads, &result);
  result.warnings = camera_quality_warnings(result, options);
  widen_for_equal_fits(others, plain.residuals(), &result);
  result.solve_cpu_s = cpu_now_s() - cpu0;
  report_progress(progress, 1.0, 1.0);
  return result;
}

}  // namespace imucal::calib
