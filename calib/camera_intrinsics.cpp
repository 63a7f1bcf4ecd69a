// Camera intrinsic calibration (calib/camera_intrinsics.hpp); method in docs/camera-calibration.md.
//
// 1. Start: the focal length from each view's homography (Zhang's two constraints with the
//    principal point at the centre and square pixels), the median over views, then refined on a
//    small geometric grid by the median reprojection error of per-view poses (solvePnP on the
//    observations undistorted through the candidate camera). The grid also serves a fisheye
//    (equidistant, k = 0), whose homographies are only roughly right, and sets where every
//    homography is degenerate (fronto-parallel views).
// 2. Levenberg-Marquardt over intrinsics, distortion and one pose per view (quaternion x R^3 on
//    a product manifold), with a Cauchy loss.
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

  int kept() const { return static_cast<int>(std::count(keep.begin(), keep.end(), 1)); }
};

template <class T>
void transform_point(const T* pose, const T* p_target, T* p_cam) {
  ceres::QuaternionRotatePoint(pose, p_target, p_cam);
  p_cam[0] += pose[4];
  p_cam[1] += pose[5];
  p_cam[2] += pose[6];
}

/// Reprojection residual of one target point, in pixels.
struct ReprojectionCost {
  ReprojectionCost(const Eigen::Vector3d& p_target, const Vec2& px, DistortionModel model)
      : p_target_(p_target), px_(px), model_(model) {}

  template <class T>
  bool operator()(const T* intrinsics, const T* distortion, const T* pose, T* residual) const {
    const T p[3] = {T(p_target_.x()), T(p_target_.y()), T(p_target_.z())};
    T c[3];
    transform_point(pose, p, c);
    // Behind the camera the projection means nothing: the step is refused.
    if (!(c[2] > T(1e-9))) return false;
    const auto camera = CameraModelT<T>::from_params(model_, intrinsics, distortion, 0, 0);
    const Eigen::Matrix<T, 2, 1> uv =
        camera.to_pixel(camera.distort(Eigen::Matrix<T, 2, 1>(c[0] / c[2], c[1] / c[2])));
    residual[0] = uv.x() - T(px_.x());
    residual[1] = uv.y() - T(px_.y());
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector3d& p_target, const Vec2& px, DistortionModel model) {
    return new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 4, 4, 7>(
        new ReprojectionCost(p_target, px, model));
  }

  Eigen::Vector3d p_target_;
  Vec2 px_;
  DistortionModel model_;
};

/// The residual of corner `i` of `view` under `camera`; NaN when the point is behind the camera.
Vec2 residual_of(const CameraModel& camera, const View& view, std::size_t i) {
  Eigen::Vector3d c;
  transform_point(view.pose.data(), view.target[i].data(), c.data());
  if (!(c.z() > 1e-9)) return Vec2::Constant(std::numeric_limits<double>::quiet_NaN());
  return camera.to_pixel(camera.distort(Vec2(c.x() / c.z(), c.y() / c.z()))) - view.px[i];
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

/// The pose of a view under `camera` from its observations undistorted through the camera
/// (solvePnP, IPPE for planar targets, on normalised coordinates); nullopt when it fails.
std::optional<Pose> pose_from_pnp(const CameraModel& camera, const View& view) {
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (std::size_t i = 0; i < view.px.size(); ++i) {
    if (!view.keep[i]) continue;
    Eigen::Vector3d ray;
    if (!camera.unproject(view.px[i], &ray) || !(ray.z() > 0.05)) continue;
    obj.emplace_back(view.target[i].x(), view.target[i].y(), view.target[i].z());
    img.emplace_back(ray.x() / ray.z(), ray.y() / ray.z());
  }
  if (obj.size() < 4) return std::nullopt;
  cv::Mat rvec, tvec;
  const cv::Mat K = cv::Mat::eye(3, 3, CV_64F);
  bool ok = false;
  try {
    ok = cv::solvePnP(obj, img, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) return std::nullopt;
  const Eigen::Vector3d r(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
  const double angle = r.norm();
  const Eigen::Quaterniond q =
      angle > 0.0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, r / angle)) : Eigen::Quaterniond::Identity();
  Pose pose{q.w(), q.x(), q.y(), q.z(), tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)};
  for (const auto& p : view.target) {
    Eigen::Vector3d c;
    transform_point(pose.data(), p.data(), c.data());
    if (!(c.z() > 0.0)) return std::nullopt;
  }
  if (!std::all_of(pose.begin(), pose.end(), [](double v) { return std::isfinite(v); })) return std::nullopt;
  return pose;
}

CameraModel start_camera(DistortionModel model, int width, int height, double focal) {
  CameraModel camera;
  camera.distortion_model = model;
  camera.width = width;
  camera.height = height;
  camera.intrinsics = {focal, focal, 0.5 * (width - 1), 0.5 * (height - 1)};
  camera.distortion_coeffs.setZero();
  return camera;
}

/// Median RMS of the sample views' PnP poses under a camera with focal length `focal`.
double focal_score(DistortionModel model, int width, int height, double focal, const std::vector<View>& views,
                   const std::vector<std::size_t>& sample) {
  const CameraModel camera = start_camera(model, width, height, focal);
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

/// The starting focal length (docs/camera-calibration.md, "Start").
double start_focal(DistortionModel model, int width, int height, const std::vector<View>& views) {
  std::vector<std::size_t> sample;
  constexpr std::size_t kSample = 40;
  const std::size_t step = std::max<std::size_t>(1, views.size() / kSample);
  for (std::size_t i = 0; i < views.size(); i += step) sample.push_back(i);
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
  // The homography estimate, or the image width when every view was degenerate for it, then a
  // geometric grid around it (quarter octaves) scored by reprojection.
  const bool have = !focals.empty();
  const double base = have ? median(focals) : static_cast<double>(width);
  const int span = have ? 4 : 8;
  double best = base;
  double best_score = std::numeric_limits<double>::infinity();
  for (int k = -span; k <= span; ++k) {
    const double f = base * std::pow(2.0, k / 4.0);
    const double score = focal_score(model, width, height, f, views, sample);
    if (score < best_score) {
      best_score = score;
      best = f;
    }
  }
  return best;
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

/// The least-squares problem over the active views; kept alive for the covariance.
class IntrinsicsProblem {
 public:
  IntrinsicsProblem(Eigen::Vector4d* intrinsics, Eigen::Vector4d* distortion, std::vector<View>* views,
                    DistortionModel model, bool robust, double loss_px)
      : loss_(loss_px) {
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(po);
    for (View& v : *views) {
      if (!v.active) continue;
      for (std::size_t i = 0; i < v.px.size(); ++i) {
        if (!v.keep[i]) continue;
        problem_->AddResidualBlock(ReprojectionCost::create(v.target[i], v.px[i], model),
                                   robust ? &loss_ : nullptr, intrinsics->data(), distortion->data(),
                                   v.pose.data());
        ++residuals_;
      }
      problem_->SetManifold(v.pose.data(), &pose_manifold_);
      poses_.push_back(v.pose.data());
    }
    intrinsics_ = intrinsics->data();
    distortion_ = distortion->data();
  }

  /// Solves; false when the solver gives no usable solution.
  bool solve(int max_iterations, int threads, ProgressCallback* callback, int* iterations, double* cost) {
    ceres::Solver::Options o;
    o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    // Poses first in the elimination: the reduced camera system is 8 x 8.
    o.linear_solver_type = ceres::DENSE_SCHUR;
    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    for (double* p : poses_) ordering->AddElementToGroup(p, 0);
    ordering->AddElementToGroup(intrinsics_, 1);
    ordering->AddElementToGroup(distortion_, 1);
    o.linear_solver_ordering = ordering;
    o.num_threads = threads;
    o.max_num_iterations = max_iterations;
    o.function_tolerance = 1e-12;
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

  /// The 8 x 8 covariance of [intrinsics, distortion] (unscaled: J'J inverse), or nullopt when
  /// the problem is rank deficient.
  std::optional<Eigen::Matrix<double, 8, 8>> covariance(int threads) {
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::SPARSE_QR;
    co.num_threads = threads;
    ceres::Covariance cov(co);
    const std::vector<std::pair<const double*, const double*>> blocks = {
        {intrinsics_, intrinsics_}, {intrinsics_, distortion_}, {distortion_, distortion_}};
    if (!cov.Compute(blocks, problem_.get())) return std::nullopt;
    Eigen::Matrix<double, 4, 4, Eigen::RowMajor> kk, kd, dd;
    if (!cov.GetCovarianceBlock(intrinsics_, intrinsics_, kk.data()) ||
        !cov.GetCovarianceBlock(intrinsics_, distortion_, kd.data()) ||
        !cov.GetCovarianceBlock(distortion_, distortion_, dd.data())) {
      return std::nullopt;
    }
    Eigen::Matrix<double, 8, 8> out;
    out << kk, kd, kd.transpose(), dd;
    if (!out.allFinite()) return std::nullopt;
    return out;
  }

  int residuals() const { return residuals_; }
  int poses() const { return static_cast<int>(poses_.size()); }

 private:
  ceres::CauchyLoss loss_;
  ceres::ProductManifold<ceres::QuaternionManifold, ceres::EuclideanManifold<3>> pose_manifold_;
  std::unique_ptr<ceres::Problem> problem_;
  std::vector<double*> poses_;
  double* intrinsics_ = nullptr;
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
  const double p = 8.0 + 6.0 * problem.poses();
  const double dof = n - p;
  result->residual_sigma_px =
      dof > 0.0 ? std::sqrt(2.0 * cost / dof) : std::numeric_limits<double>::quiet_NaN();
  const auto cov = options.covariance ? problem.covariance(threads) : std::nullopt;
  const double inf = std::numeric_limits<double>::infinity();
  if (cov && dof > 0.0) {
    result->covariance = *cov * (result->residual_sigma_px * result->residual_sigma_px);
    result->covariance_ok = true;
    const Eigen::Matrix<double, 8, 1> sigma = result->covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    result->intrinsics_sigma = sigma.head<4>();
    result->distortion_sigma = sigma.tail<4>();
  } else {
    result->intrinsics_sigma.setConstant(inf);
    result->distortion_sigma.setConstant(inf);
  }
  const auto& k = result->camera.intrinsics;
  const double rel = std::max(result->intrinsics_sigma[0] / k[0], result->intrinsics_sigma[1] / k[1]);
  result->focal_well_determined = result->covariance_ok && rel <= options.max_focal_relative_sigma;
}

}  // namespace

void set_coverage(int width, int height, int cols, std::span<const Eigen::Vector2d> px,
                  CameraIntrinsicsResult* result) {
  result->coverage_cols = cols;
  result->coverage_rows = std::max(1, static_cast<int>(std::lround(cols * double(height) / double(width))));
  result->coverage_counts.assign(static_cast<std::size_t>(result->coverage_cols * result->coverage_rows), 0);
  for (const auto& p : px) {
    const int cx = std::clamp(static_cast<int>((p.x() + 0.5) / width * result->coverage_cols), 0,
                              result->coverage_cols - 1);
    const int cy = std::clamp(static_cast<int>((p.y() + 0.5) / height * result->coverage_rows), 0,
                              result->coverage_rows - 1);
    ++result->coverage_counts[static_cast<std::size_t>(cy * result->coverage_cols + cx)];
  }
  const auto hit = std::count_if(result->coverage_counts.begin(), result->coverage_counts.end(),
                                 [](int c) { return c > 0; });
  result->coverage = static_cast<double>(hit) / static_cast<double>(result->coverage_counts.size());
}

std::vector<std::string> camera_quality_warnings(const CameraIntrinsicsResult& r,
                                                 const CameraIntrinsicsOptions& options) {
  std::vector<std::string> out;
  const auto& k = r.camera.intrinsics;
  const double rel = std::max(r.intrinsics_sigma[0] / k[0], r.intrinsics_sigma[1] / k[1]);
  if (!(r.covariance_ok && rel <= options.max_focal_relative_sigma)) {
    out.push_back(std::string("the focal length is not determined by these views (") +
                  (r.covariance_ok ? "relative sigma " + format_number("%.2g", rel)
                                   : std::string("rank-deficient covariance")) +
                  "): views all facing the camera cannot tell the focal length from the distance; record the "
                  "target tilted by 30-45 degrees in several directions and at several distances");
  }
  if (r.coverage < 0.5) {
    out.push_back("the corners cover only " + format_number("%.0f", 100.0 * r.coverage) +
                  " % of the image (" + std::to_string(r.coverage_cols) + " x " +
                  std::to_string(r.coverage_rows) +
                  " cells): the distortion is extrapolated elsewhere; show the target near the "
                  "edges and corners of the image too");
  }
  const int rejected = r.views_total - r.views_used;
  if (rejected * 5 > r.views_total) {
    out.push_back(std::to_string(rejected) + " of " + std::to_string(r.views_total) +
                  " views were rejected (see the views' reasons): check the detections");
  }
  return out;
}

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
  CameraModel camera =
      start_camera(options.model, width, height, start_focal(options.model, width, height, usable));
  for (View& v : views) {
    if (!v.active) continue;
    const auto pose = pose_from_pnp(camera, v);
    if (pose) {
      v.pose = *pose;
    } else {
      reject_view(v, &result, "no pose found for the start (the detection may be wrong)");
    }
  }
  if (active_count(views) < options.min_views) return too_few_views(views, result, options);
  report_progress(progress, 0.05, 1.0);

  Eigen::Vector4d intrinsics = camera.intrinsics;
  Eigen::Vector4d distortion = camera.distortion_coeffs;
  double cost = 0.0;
  {
    IntrinsicsProblem robust(&intrinsics, &distortion, &views, options.model, true, options.robust_loss_px);
    ProgressCallback cb(progress, 0.05, 0.5, options.max_iterations);
    if (!robust.solve(options.max_iterations, threads, &cb, &result.iterations, &cost)) {
      return make_error(Errc::kSolverFailed,
                        "the camera solve (robust pass) did not converge; check the target "
                        "description against the target that was recorded");
    }
  }
  camera.intrinsics = intrinsics;
  camera.distortion_coeffs = distortion;
  reject_views(camera, views, options, &result);
  result.corners_rejected = reject_corners(camera, views, options, &result);
  if (active_count(views) < options.min_views) return too_few_views(views, result, options);

  IntrinsicsProblem plain(&intrinsics, &distortion, &views, options.model, false, options.robust_loss_px);
  ProgressCallback cb(progress, 0.5, 0.9, options.max_iterations);
  if (!plain.solve(options.max_iterations, threads, &cb, &result.iterations, &cost) ||
      !intrinsics.allFinite() || !distortion.allFinite()) {
    return make_error(Errc::kSolverFailed, "the camera solve (final pass) did not converge");
  }
  result.camera.distortion_model = options.model;
  result.camera.intrinsics = intrinsics;
  result.camera.distortion_coeffs = distortion;
  if (auto valid = validate_camera(result.camera); !valid.ok()) {
    return make_error(Errc::kSolverFailed, "the camera solve gave an unusable camera (" +
                                               valid.error().message +
                                               "); check the target description and the detections");
  }
  fill_figures(result.camera, views, options, &result);
  fill_uncertainty(plain, cost, options, threads, &result);
  result.warnings = camera_quality_warnings(result, options);
  result.solve_cpu_s = cpu_now_s() - cpu0;
  report_progress(progress, 1.0, 1.0);
  return result;
}

}  // namespace imucal::calib
