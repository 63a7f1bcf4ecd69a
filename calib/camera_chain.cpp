// SPDX-License-Identifier: BSD-3-Clause
// The camera chain solve (calib/camera_chain.hpp); method in docs/camera-calibration.md,
// "Several cameras".
//
// 1. Start: each camera alone (calib/camera_intrinsics.hpp), which also rejects its bad views,
//    gives its intrinsics and the target's pose in every used view.
// 2. Links: for each pair of cameras, the time offset that makes the relative pose of the two
//    cameras most constant over the views they share (one camera's poses interpolated at the
//    other's stamps, shifted), searched on a 1 ms grid and refined by a parabola; the chain is
//    the spanning tree from cam0 that keeps the links with the most shared views.
// 3. The joint solve: a cubic B-spline T_target_cam0(t), every camera's intrinsics, pose
//    relative to cam0 and time offset (calib/camera_chain_residuals.hpp); a robust pass, corners
//    beyond reject_sigmas robust sigmas dropped, plain passes with each camera's corner noise
//    estimated from its residuals, and the marginal covariance of the calibration by a Schur
//    complement over the trajectory (calib/marginal_covariance.hpp).

#include "calib/camera_chain.hpp"

#include <ceres/ceres.h>
#include <time.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <queue>

#include "calib/camera_blocks.hpp"
#include "calib/camera_chain_links.hpp"
#include "calib/camera_chain_residuals.hpp"
#include "calib/camimu_init.hpp"
#include "calib/marginal_covariance.hpp"
#include "calib/observation_check.hpp"
#include "calib/so3.hpp"
#include "core/option_words.hpp"
#include "core/text_format.hpp"
#include "core/threads.hpp"

namespace imucal::calib {
namespace {

using chain::find_link;
using chain::Link;
using chain::PoseSample;
using chain::relative_jacobian;

constexpr int kOrder = 4;  // cubic B-spline
using Residual = chain::ChainFrameResidual<kOrder>;
using Arr4 = std::array<double, 4>;
using Arr3 = std::array<double, 3>;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Weak priors on the knots (rad, m): they hold knots that no view reaches (a gap in the views,
// the margins) and weigh nothing beside a view's corners.
constexpr double kKnotPriorRad = 1.0;
constexpr double kKnotPriorM = 1.0;
// The single-camera start of each camera uses at most this many views, spread over the
// recording; every view then gets its pose under that start by PnP.
constexpr std::size_t kStartViews = 100;

double cpu_now_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Arr4 to_quat(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  return {q.x(), q.y(), q.z(), q.w()};
}

double median_interval_s(const std::vector<PoseSample>& track) {
  std::vector<double> d;
  for (std::size_t i = 1; i < track.size(); ++i) d.push_back(track[i].t - track[i - 1].t);
  return d.empty() ? kNaN : median(d);
}

/// What the solver moves, at stable addresses.
struct CameraBlocks {
  Arr4 q{0, 0, 0, 1};  // R_cam_cam0
  Arr3 t{0, 0, 0};
  double shift = 0.0;
  std::array<double, 4> intrinsics{}, distortion{};
  std::array<double, 2> projection{};  // the model's parameters first, the rest held at 0
  double sigma_px = 0.3;
  // The shutter: rolling views have a line delay block (held when line_delay_fixed); `test`:
  // freed after the global solution, kept by request (keep_rolling) or by the evidence.
  bool rolling = false;
  bool line_delay_fixed = true;
  double line_delay = 0.0;  // s per row
  bool test = false;
  bool keep_rolling = false;
  std::string shutter_choice;
};

/// One view in the solve: the camera, its corners (target points and pixels) and which are kept.
struct ViewData {
  std::size_t camera = 0;
  std::size_t report = 0;  // index into the camera's start views
  double t = 0.0;          // stamp, s from t0
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> px;
  std::vector<char> keep;
};

class ChainSolver {
 public:
  ChainSolver(std::span<const CameraChainInput> cameras, const CameraChainOptions& options)
      : inputs_(cameras), opt_(options), blocks_(cameras.size()) {}

  Result<CameraChainResult> run(const TargetDescription& target, const ProgressFn& progress);

 private:
  Status start_cameras(const TargetDescription& target, const ProgressFn& progress);
  Status link_cameras();
  void initialise_spline();
  /// The poses of cam0 for cameras triggered together: views within the shared-view tolerance of
  /// each other, one per camera, share a pose.
  void initialise_poses();
  /// Views within shared_view_fraction of the shortest frame interval of each other on cam0's
  /// time, one per camera, form a group (a stereo pair's two views of one instant): the index of
  /// each view's group, and their number.
  std::vector<std::size_t> group_views(std::size_t* groups) const;
  /// Builds the problem at the current values (c2: the loss scale in sigmas, 0 = none).
  void build(double loss_sigmas);
  Status solve(double loss_sigmas, const std::string& stage);
  /// Each camera's shutter plan from the options and its input (CameraBlocks' fields).
  Status plan_shutters();
  /// After the global solution: the line delays to test freed and solved; rolling kept where
  /// asked for or where the evidence shows it (BIC), else the global solution restored. Kept, the
  /// corners the global model rejected are taken back and judged by the rolling one (`dropped`:
  /// the corners left out, updated).
  Status choose_shutter(int* dropped);
  bool views_in_window() const;
  /// Residuals per camera in pixels at the current values (kept corners).
  std::vector<std::vector<Eigen::Vector2d>> residuals_by_camera() const;
  int reject_corners();
  /// Re-estimates each camera's corner sigma from its residuals (robust: 1.4826 x the median
  /// |component|, or the RMS); true when one moved by more than 10 %.
  bool reestimate_sigmas(bool robust);
  /// A block of the solution's covariance (cluster-robust where it could be computed; NaN where
  /// not determined), rows x cols.
  using BlockCovariance = std::function<Eigen::MatrixXd(const double*, const double*, int, int)>;
  BlockCovariance solution_covariance(MarginalCovariance* cov);
  /// Camera c's result: its camera and sigmas, residual figures, pose and offset.
  void fill_camera(std::size_t c, const BlockCovariance& block, const std::vector<Eigen::Vector2d>& res,
                   CameraChainCameraResult* r) const;
  /// Camera c's pose relative to camera c - 1 and its covariance, and the baseline's sigma.
  void fill_relative(std::size_t c, const BlockCovariance& block, CameraChainCameraResult* r) const;
  /// Stamps that say the cameras are synchronized, against the offsets the data show.
  void check_synchronization(CameraChainResult* out);
  Status fill(CameraChainResult* out);
  void fill_pairs(CameraChainResult* out) const;

  std::span<const CameraChainInput> inputs_;
  CameraChainOptions opt_;
  std::vector<CameraIntrinsicsResult> starts_;
  std::vector<std::vector<PoseSample>> tracks_;
  std::vector<double> intervals_;
  std::vector<int> parent_;
  std::vector<Link> links_;
  TimeNs t0_ns_ = 0;
  std::vector<CameraBlocks> blocks_;
  std::vector<ViewData> views_;
  SplineTiming<kOrder> timing_;
  std::vector<Arr4> q_;
  std::vector<Arr3> p_;
  // Cameras triggered together (offsets held): one pose of cam0 per group of views with the same
  // stamp, instead of the trajectory.
  bool discrete_ = false;
  std::vector<std::size_t> group_of_view_;  // views_ index -> its pose
  std::unique_ptr<ceres::Problem> problem_;
  struct ResidualRef {
    const Residual* spline = nullptr;
    const chain::ChainPoseResidual* pose = nullptr;
    void pixels(double const* const* p, std::vector<Eigen::Vector2d>* out) const {
      if (spline) {
        spline->pixel_residuals(p, out);
      } else {
        pose->pixel_residuals(p, out);
      }
    }
  };
  std::vector<ResidualRef> residuals_;  // of the last build, one per view in views_ order
  std::vector<ceres::ResidualBlockId> residual_ids_;
  std::vector<std::vector<double*>> residual_blocks_;
  int iterations_ = 0;
  double last_cost_ = 0.0;  // of the last solve
  std::vector<std::string> warnings_;
};

/// Every observation's ids index the target's points, with as many finite pixels.
Status check_observations(std::span<const CameraChainInput> cameras, std::size_t points) {
  for (const auto& cam : cameras) {
    for (const auto& o : cam.observations) {
      if (Status s = check_observation(o, static_cast<int>(points)); !s.ok()) {
        return make_error(Errc::kInvalidArgument, cam.name + ": " + s.error().message);
      }
    }
  }
  return {};
}

Status ChainSolver::start_cameras(const TargetDescription& target, const ProgressFn& progress) {
  const std::vector<Eigen::Vector3d> points = target.points();
  IMUCAL_TRY(check_observations(inputs_, points.size()));
  t0_ns_ = std::numeric_limits<TimeNs>::max();
  for (const auto& cam : inputs_)
    for (const auto& o : cam.observations)
      if (!o.empty()) t0_ns_ = std::min(t0_ns_, o.t_ns);
  for (std::size_t c = 0; c < inputs_.size(); ++c) {
    std::vector<TargetObservation> with;
    for (const auto& o : inputs_[c].observations)
      if (!o.empty()) with.push_back(o);
    // The start: the camera alone on at most kStartViews views spread over the recording.
    std::vector<TargetObservation> sample;
    const std::size_t step = std::max<std::size_t>(1, (with.size() + kStartViews - 1) / kStartViews);
    for (std::size_t i = 0; i < with.size(); i += step) sample.push_back(with[i]);
    CameraIntrinsicsOptions o = opt_.intrinsics;
    o.model = inputs_[c].model;
    o.covariance = false;  // the joint solve gives the sigmas
    auto r = calibrate_camera_intrinsics(target, sample, o, {});
    if (!r.ok()) return r.error().context(inputs_[c].name);
    CameraIntrinsicsResult s = std::move(*r);
    // Every view's pose under that camera; views far worse than the others are left out.
    const auto poses = camimu::pnp_poses(s.camera, with, points, t0_ns_, o.min_points_per_view,
                                         std::numeric_limits<double>::max());
    std::vector<double> rms;
    for (const auto& p : poses) rms.push_back(p.rms_px);
    const double limit = std::max(o.view_rms_factor * median(rms), o.view_rms_floor_px);
    std::map<TimeNs, const camimu::FramePose*> pose_at;
    for (const auto& p : poses) pose_at[p.t_ns] = &p;
    CameraBlocks& b = blocks_[c];
    std::copy(s.camera.intrinsics.data(), s.camera.intrinsics.data() + 4, b.intrinsics.begin());
    std::copy(s.camera.distortion_coeffs.data(), s.camera.distortion_coeffs.data() + 4, b.distortion.begin());
    std::copy(s.camera.projection_params.data(), s.camera.projection_params.data() + 2, b.projection.begin());
    b.sigma_px = std::max(0.01, std::isfinite(s.residual_sigma_px) ? s.residual_sigma_px : 0.3);
    s.views.clear();
    std::vector<PoseSample> track;
    std::vector<Eigen::Vector2d> used_px;
    for (const TargetObservation& obs : with) {
      CameraViewReport v;
      v.t_ns = obs.t_ns;
      v.points = static_cast<int>(obs.ids.size());
      const auto it = pose_at.find(obs.t_ns);
      if (v.points < o.min_points_per_view) {
        v.rejected_because = "too few points (" + std::to_string(v.points) + ")";
      } else if (it == pose_at.end()) {
        v.rejected_because = "no pose found for the start (the detection may be wrong)";
      } else if (!(it->second->rms_px <= limit)) {
        v.rms_px = it->second->rms_px;
        v.rejected_because = "reprojection RMS " + format_number("%.3g", v.rms_px) +
                             " px at the start, above " + format_number("%.3g", limit) + " px";
      } else {
        const camimu::FramePose& fp = *it->second;
        v.used = true;
        v.points_used = v.points;
        v.rms_px = fp.rms_px;
        v.q_cam_target = Eigen::Quaterniond(fp.R_wc.transpose());
        v.t_cam_target = -fp.R_wc.transpose() * fp.p_wc;
        PoseSample ps;
        ps.t = fp.t_s;
        ps.R_wc = fp.R_wc;
        ps.p_wc = fp.p_wc;
        track.push_back(ps);
        ViewData vd;
        vd.camera = c;
        vd.report = s.views.size();
        vd.t = ps.t;
        for (std::size_t i = 0; i < obs.ids.size(); ++i) {
          vd.points.push_back(points[static_cast<std::size_t>(obs.ids[i])]);
          vd.px.push_back(obs.px[i]);
        }
        used_px.insert(used_px.end(), obs.px.begin(), obs.px.end());
        vd.keep.assign(vd.px.size(), 1);
        views_.push_back(std::move(vd));
      }
      s.views.push_back(std::move(v));
    }
    s.views_total = static_cast<int>(with.size());
    s.views_used = static_cast<int>(track.size());
    if (s.views_used < o.min_views) {
      return make_error(Errc::kInsufficientData,
                        inputs_[c].name + ": " + std::to_string(s.views_used) + " usable views of " +
                            std::to_string(with.size()) + " with the target, fewer than the " +
                            std::to_string(o.min_views) +
                            " needed: record more views of the whole target in this camera");
    }
    set_coverage(s.camera.width, s.camera.height, o.coverage_cols, used_px, &s);
    starts_.push_back(std::move(s));
    std::sort(track.begin(), track.end(), [](const PoseSample& a, const PoseSample& b) { return a.t < b.t; });
    intervals_.push_back(median_interval_s(track));
    tracks_.push_back(std::move(track));
    report_progress(progress, 0.4 * static_cast<double>(c + 1) / static_cast<double>(inputs_.size()), 1.0);
  }
  return {};
}

Status ChainSolver::link_cameras() {
  const std::size_t n = inputs_.size();
  // Every pair, both ways round the tree is built from: link[a][b] places b against a.
  std::vector<std::vector<Link>> link(n, std::vector<Link>(n));
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t b = 0; b < n; ++b) {
      if (a == b) continue;
      const double gap = 2.5 * intervals_[a];
      link[a][b] =
          find_link(tracks_[a], tracks_[b], opt_.estimate_time_offsets ? opt_.max_time_offset_s : 0.0,
                    std::isfinite(gap) ? gap : 0.0, opt_.min_shared_views);
    }
  }
  // The spanning tree from cam0 with the most shared views (Prim's on the largest links).
  parent_.assign(n, -2);
  links_.assign(n, Link{});
  parent_[0] = -1;
  for (std::size_t added = 1; added < n; ++added) {
    int best_a = -1, best_b = -1;
    for (std::size_t a = 0; a < n; ++a) {
      if (parent_[a] == -2) continue;
      for (std::size_t b = 0; b < n; ++b) {
        if (parent_[b] != -2 || link[a][b].shared < opt_.min_shared_views) continue;
        if (best_a < 0 || link[a][b].shared > link[best_a][best_b].shared) {
          best_a = static_cast<int>(a);
          best_b = static_cast<int>(b);
        }
      }
    }
    if (best_a < 0) {
      std::string missing, linked;
      for (std::size_t c = 0; c < n; ++c) {
        std::string& s = parent_[c] == -2 ? missing : linked;
        s += (s.empty() ? "" : ", ") + inputs_[c].name;
      }
      return make_error(Errc::kInsufficientData,
                        missing + " never saw the target at the same time as " + linked + " (fewer than " +
                            std::to_string(opt_.min_shared_views) +
                            " shared views): the chain cannot place it; record the target where " + missing +
                            " and a camera next to it both see it, for a few seconds of slow motion");
    }
    parent_[static_cast<std::size_t>(best_b)] = best_a;
    links_[static_cast<std::size_t>(best_b)] =
        link[static_cast<std::size_t>(best_a)][static_cast<std::size_t>(best_b)];
  }
  // Compose along the tree, in the order cameras were added (a parent before its children).
  std::vector<bool> done(n, false);
  done[0] = true;
  for (std::size_t pass = 0; pass < n; ++pass) {
    for (std::size_t c = 1; c < n; ++c) {
      const int a = parent_[c];
      if (done[c] || !done[static_cast<std::size_t>(a)]) continue;
      const CameraBlocks& pa = blocks_[static_cast<std::size_t>(a)];
      const Eigen::Matrix3d R_a0 = camimu::quat_matrix(pa.q.data());
      const Eigen::Vector3d t_a0(pa.t[0], pa.t[1], pa.t[2]);
      const Link& l = links_[c];
      const Eigen::Matrix3d R_c0 = l.R_ba * R_a0;
      const Eigen::Vector3d t_c0 = l.R_ba * t_a0 + l.t_ba;
      blocks_[c].q = to_quat(R_c0);
      blocks_[c].t = {t_c0.x(), t_c0.y(), t_c0.z()};
      // t_a = t_c + l.shift and t_0 = t_a + shift_a.
      blocks_[c].shift = opt_.estimate_time_offsets ? pa.shift + l.shift : 0.0;
      done[c] = true;
    }
  }
  return {};
}

void ChainSolver::initialise_spline() {
  // cam0's pose from every view of every camera: T_w0 = T_wc T_c0 at cam0's time t + shift.
  std::vector<PoseSample> body;
  for (std::size_t c = 0; c < tracks_.size(); ++c) {
    const Eigen::Matrix3d R_c0 = camimu::quat_matrix(blocks_[c].q.data());
    const Eigen::Vector3d t_c0(blocks_[c].t[0], blocks_[c].t[1], blocks_[c].t[2]);
    for (const PoseSample& s : tracks_[c]) {
      PoseSample b;
      b.t = s.t + blocks_[c].shift;
      b.R_wc = s.R_wc * R_c0;
      b.p_wc = s.R_wc * t_c0 + s.p_wc;
      body.push_back(b);
    }
  }
  std::sort(body.begin(), body.end(), [](const PoseSample& a, const PoseSample& b) { return a.t < b.t; });
  double dt = opt_.knot_spacing_s;
  if (!(dt > 0.0)) {
    dt = std::numeric_limits<double>::infinity();
    for (double i : intervals_)
      if (std::isfinite(i) && i > 0.0) dt = std::min(dt, i);
    if (!std::isfinite(dt)) dt = 0.05;
  }
  // Margins of two knot spacings, for offsets that move while solving.
  const double t_start = body.front().t - 2.0 * dt;
  const double t_end = body.back().t + 2.0 * dt;
  timing_ = {t_start, dt, static_cast<int>(std::ceil((t_end - t_start) / dt)) + kOrder};
  q_.resize(static_cast<std::size_t>(timing_.knots));
  p_.resize(q_.size());
  std::vector<double> tb;
  for (const auto& b : body) tb.push_back(b.t);
  for (int i = 0; i < timing_.knots; ++i) {
    // Knot i weighs most at t0 + (i - (N - 2) / 2) dt.
    const double tau = std::clamp(t_start + (i - 0.5 * (kOrder - 2)) * dt, tb.front(), tb.back());
    const std::size_t j = std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(tb.begin(), tb.end(), tau) - tb.begin()), tb.size() - 1);
    const std::size_t i0 = j == 0 ? 0 : j - 1;
    const double a = tb[j] > tb[i0] ? (tau - tb[i0]) / (tb[j] - tb[i0]) : 0.0;
    const Eigen::Matrix3d R =
        body[i0].R_wc * so3::exp(a * so3::log(body[i0].R_wc.transpose() * body[j].R_wc));
    const Eigen::Vector3d p = (1 - a) * body[i0].p_wc + a * body[j].p_wc;
    q_[static_cast<std::size_t>(i)] = to_quat(R);
    p_[static_cast<std::size_t>(i)] = {p.x(), p.y(), p.z()};
  }
}

std::vector<std::size_t> ChainSolver::group_views(std::size_t* groups) const {
  double interval = std::numeric_limits<double>::infinity();
  for (double i : intervals_)
    if (std::isfinite(i) && i > 0.0) interval = std::min(interval, i);
  const double tol = std::isfinite(interval) ? opt_.shared_view_fraction * interval : 1e-3;
  const auto t_of = [&](std::size_t k) { return views_[k].t + blocks_[views_[k].camera].shift; };
  std::vector<std::size_t> order(views_.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return t_of(a) < t_of(b); });
  std::vector<std::size_t> group(views_.size(), 0);
  *groups = 0;
  double group_t = -std::numeric_limits<double>::infinity();
  std::vector<bool> has(inputs_.size(), false);
  for (std::size_t i : order) {
    const std::size_t camera = views_[i].camera;
    if (!(t_of(i) - group_t <= tol) || has[camera]) {
      ++*groups;
      group_t = t_of(i);
      has.assign(inputs_.size(), false);
    }
    has[camera] = true;
    group[i] = *groups - 1;
  }
  return group;
}

void ChainSolver::initialise_poses() {
  discrete_ = true;
  std::size_t groups = 0;
  group_of_view_ = group_views(&groups);
  q_.assign(groups, Arr4{0, 0, 0, 0});
  p_.assign(groups, Arr3{0, 0, 0});
  std::vector<bool> set(groups, false);
  for (std::size_t i = 0; i < views_.size(); ++i) {
    const std::size_t g = group_of_view_[i];
    if (set[g]) continue;
    set[g] = true;
    // The pose from the group's first view: T_w0 = T_wc T_c0.
    const ViewData& v = views_[i];
    const CameraViewReport& rep = starts_[v.camera].views[v.report];
    const Eigen::Matrix3d R_wc = rep.q_cam_target.toRotationMatrix().transpose();
    const Eigen::Vector3d p_wc = -R_wc * rep.t_cam_target;
    const Eigen::Matrix3d R_c0 = camimu::quat_matrix(blocks_[v.camera].q.data());
    const Eigen::Vector3d t_c0(blocks_[v.camera].t[0], blocks_[v.camera].t[1], blocks_[v.camera].t[2]);
    const Eigen::Vector3d p = R_wc * t_c0 + p_wc;
    q_[g] = to_quat(R_wc * R_c0);
    p_[g] = {p.x(), p.y(), p.z()};
  }
}

void ChainSolver::build(double loss_sigmas) {
  static camimu::RightQuaternionManifold quat_manifold;
  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_ = std::make_unique<ceres::Problem>(po);
  residuals_.clear();
  residual_blocks_.clear();
  residual_ids_.clear();
  for (std::size_t i = 0; i < q_.size(); ++i) {
    problem_->AddParameterBlock(q_[i].data(), 4, &quat_manifold);
    if (discrete_) continue;  // every pose is a view's
    problem_->AddResidualBlock(new camimu::RotationPrior(camimu::quat_matrix(q_[i].data()), kKnotPriorRad),
                               nullptr, q_[i].data());
    problem_->AddResidualBlock(new camimu::VectorPrior(Eigen::Vector3d(p_[i][0], p_[i][1], p_[i][2]),
                                                       Eigen::Vector3d::Constant(kKnotPriorM)),
                               nullptr, p_[i].data());
  }
  for (CameraBlocks& b : blocks_) problem_->AddParameterBlock(b.q.data(), 4, &quat_manifold);
  for (std::size_t k = 0; k < views_.size(); ++k) {
    const ViewData& v = views_[k];
    CameraBlocks& b = blocks_[v.camera];
    std::vector<Eigen::Vector3d> pts;
    std::vector<Eigen::Vector2d> px;
    for (std::size_t i = 0; i < v.px.size(); ++i) {
      if (!v.keep[i]) continue;
      pts.push_back(v.points[i]);
      px.push_back(v.px[i]);
    }
    const double loss_px = loss_sigmas > 0.0 ? loss_sigmas * b.sigma_px : 0.0;
    const int width = starts_[v.camera].camera.width, height = starts_[v.camera].camera.height;
    std::vector<double*> blocks;
    if (discrete_) {
      const std::size_t g = group_of_view_[k];
      auto* cost = new chain::ChainPoseResidual(chain::ViewCorners(
          inputs_[v.camera].model, width, height, std::move(pts), std::move(px), b.sigma_px, loss_px));
      blocks = {q_[g].data(),        p_[g].data(),        b.q.data(),         b.t.data(),
                b.intrinsics.data(), b.projection.data(), b.distortion.data()};
      residual_ids_.push_back(problem_->AddResidualBlock(cost, nullptr, blocks));
      residuals_.push_back({nullptr, cost});
    } else {
      const double t = v.t + b.shift;
      const int first = std::clamp(timing_.segment(t).first_knot - 1, 0, timing_.knots - kOrder - 2);
      auto* cost = new Residual(inputs_[v.camera].model, width, height, std::move(pts), std::move(px), v.t,
                                first, timing_, b.sigma_px, loss_px, /*compressed=*/true,
                                b.rolling ? &inputs_[v.camera].shutter : nullptr);
      for (int i = 0; i < Residual::kWindow; ++i)
        blocks.push_back(q_[static_cast<std::size_t>(first + i)].data());
      for (int i = 0; i < Residual::kWindow; ++i)
        blocks.push_back(p_[static_cast<std::size_t>(first + i)].data());
      for (double* x :
           {b.q.data(), b.t.data(), &b.shift, b.intrinsics.data(), b.projection.data(), b.distortion.data()})
        blocks.push_back(x);
      if (b.rolling) blocks.push_back(&b.line_delay);
      residual_ids_.push_back(problem_->AddResidualBlock(cost, nullptr, blocks));
      residuals_.push_back({cost, nullptr});
    }
    residual_blocks_.push_back(std::move(blocks));
  }
  for (std::size_t c = 0; c < blocks_.size(); ++c)
    hold_unused_camera_entries(problem_.get(), inputs_[c].model, blocks_[c].projection.data(),
                               blocks_[c].distortion.data());
  // cam0 is the reference: its pose and offset are not estimated.
  problem_->SetParameterBlockConstant(blocks_[0].q.data());
  problem_->SetParameterBlockConstant(blocks_[0].t.data());
  if (!discrete_) {
    problem_->SetParameterBlockConstant(&blocks_[0].shift);
    if (!opt_.estimate_time_offsets)
      for (CameraBlocks& cb : blocks_) problem_->SetParameterBlockConstant(&cb.shift);
    for (CameraBlocks& cb : blocks_)
      if (cb.rolling && cb.line_delay_fixed && problem_->HasParameterBlock(&cb.line_delay))
        problem_->SetParameterBlockConstant(&cb.line_delay);
  }
}

bool ChainSolver::views_in_window() const {
  for (std::size_t k = 0; k < residuals_.size(); ++k)
    if (residuals_[k].spline) {
      const CameraBlocks& b = blocks_[views_[k].camera];
      if (!residuals_[k].spline->in_window(b.shift, b.rolling ? b.line_delay : 0.0)) return false;
    }
  return true;
}

Status ChainSolver::solve(double loss_sigmas, const std::string& stage) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.trust_region_strategy_type = ceres::DOGLEG;
  so.num_threads = threads_or_cores(opt_.threads);
  so.max_num_iterations = opt_.max_iterations;
  so.function_tolerance = 1e-9;
  so.parameter_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  // An offset that moves views out of the knot window they were built with: the problem is
  // built again at the new offset and solved on.
  constexpr int kAttempts = 8;
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    build(loss_sigmas);
    ceres::Solver::Summary summary;
    ceres::Solve(so, problem_.get(), &summary);
    iterations_ += static_cast<int>(summary.iterations.size());
    if (!summary.IsSolutionUsable())
      return make_error(Errc::kSolverFailed,
                        "the camera chain solve failed (" + stage + "): " + summary.message);
    last_cost_ = summary.final_cost;
    if (views_in_window()) return {};
  }
  return make_error(Errc::kSolverFailed, "the cameras' time offsets did not settle (" + stage + ")");
}

std::vector<std::vector<Eigen::Vector2d>> ChainSolver::residuals_by_camera() const {
  std::vector<std::vector<Eigen::Vector2d>> out(inputs_.size());
  std::vector<Eigen::Vector2d> r;
  for (std::size_t k = 0; k < residuals_.size(); ++k) {
    residuals_[k].pixels(residual_blocks_[k].data(), &r);
    out[views_[k].camera].insert(out[views_[k].camera].end(), r.begin(), r.end());
  }
  return out;
}

bool ChainSolver::reestimate_sigmas(bool robust) {
  const auto res = residuals_by_camera();
  bool moved = false;
  for (std::size_t c = 0; c < res.size(); ++c) {
    if (res[c].empty()) continue;
    double sigma = 0.0;
    if (robust) {
      std::vector<double> a;
      for (const auto& r : res[c]) {
        a.push_back(std::abs(r.x()));
        a.push_back(std::abs(r.y()));
      }
      sigma = 1.4826 * median(a);
    } else {
      double sum = 0.0;
      for (const auto& r : res[c]) sum += r.squaredNorm();
      sigma = std::sqrt(sum / (2.0 * static_cast<double>(res[c].size())));
    }
    sigma = std::max(sigma, 0.005);
    if (std::abs(sigma / blocks_[c].sigma_px - 1.0) > 0.1) moved = true;
    blocks_[c].sigma_px = sigma;
  }
  return moved;
}

int ChainSolver::reject_corners() {
  int dropped = 0;
  std::vector<Eigen::Vector2d> r;
  for (std::size_t k = 0; k < residuals_.size(); ++k) {
    ViewData& v = views_[k];
    residuals_[k].pixels(residual_blocks_[k].data(), &r);
    const double limit =
        std::max(opt_.reject_sigmas * blocks_[v.camera].sigma_px, opt_.intrinsics.corner_floor_px);
    std::size_t j = 0;
    for (std::size_t i = 0; i < v.px.size(); ++i) {
      if (!v.keep[i]) continue;
      if (!(r[j].cwiseAbs().maxCoeff() <= limit)) {
        v.keep[i] = 0;
        ++dropped;
      }
      ++j;
    }
  }
  return dropped;
}

Eigen::Isometry3d pose_of(const CameraBlocks& b) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = camimu::quat_matrix(b.q.data());
  T.translation() = Eigen::Vector3d(b.t[0], b.t[1], b.t[2]);
  return T;
}

void ChainSolver::fill_pairs(CameraChainResult* out) const {
  const std::size_t n = inputs_.size();
  for (std::size_t a = 0; a < n; ++a) {
    auto& shared = out->cameras[a].shared_views;
    shared.assign(n, 0);
    for (std::size_t b = 0; b < n; ++b) {
      if (a == b) continue;
      // b's views with a view of a within the tolerance, both on cam0's time.
      const double tol = opt_.shared_view_fraction * std::max(intervals_[a], intervals_[b]);
      std::vector<double> ta;
      for (const auto& s : tracks_[a]) ta.push_back(s.t + blocks_[a].shift);
      for (const auto& s : tracks_[b]) {
        const double t = s.t + blocks_[b].shift;
        const auto it = std::lower_bound(ta.begin(), ta.end(), t - tol);
        if (it != ta.end() && *it <= t + tol) ++shared[b];
      }
    }
  }
}

ChainSolver::BlockCovariance ChainSolver::solution_covariance(MarginalCovariance* cov) {
  std::vector<const double*> wanted;
  for (std::size_t c = 0; c < blocks_.size(); ++c) {
    for (const double* x :
         {blocks_[c].intrinsics.data(), blocks_[c].projection.data(), blocks_[c].distortion.data()})
      if (problem_->HasParameterBlock(x) && !problem_->IsParameterBlockConstant(x)) wanted.push_back(x);
    if (blocks_[c].rolling && !blocks_[c].line_delay_fixed) wanted.push_back(&blocks_[c].line_delay);
    if (c == 0) continue;
    wanted.push_back(blocks_[c].q.data());
    wanted.push_back(blocks_[c].t.data());
    if (opt_.estimate_time_offsets) wanted.push_back(&blocks_[c].shift);
  }
  // The views of one instant (every camera's) form a cluster of the robust covariance: their
  // corners share the errors of the detector, the lens model and the trajectory there.
  std::size_t groups = 0;
  const std::vector<std::size_t> group = group_views(&groups);
  std::vector<std::vector<ceres::ResidualBlockId>> clusters(groups);
  for (std::size_t k = 0; k < residual_ids_.size(); ++k) clusters[group[k]].push_back(residual_ids_[k]);
  const bool have = cov->compute(*problem_, wanted, threads_or_cores(opt_.threads), clusters);
  if (!have) warnings_.push_back("the covariance could not be computed: every sigma is not determined");
  return [cov, have](const double* a, const double* b, int ra, int cb) -> Eigen::MatrixXd {
    if (have && cov->has(a) && cov->has(b))
      return cov->has_robust() ? cov->robust_block(a, b) : cov->block(a, b);
    return Eigen::MatrixXd::Constant(ra, cb, kNaN);
  };
}

void ChainSolver::fill_camera(std::size_t c, const BlockCovariance& block,
                              const std::vector<Eigen::Vector2d>& res, CameraChainCameraResult* r) const {
  const CameraBlocks& b = blocks_[c];
  r->name = inputs_[c].name;
  r->intrinsics = starts_[c];
  CameraIntrinsicsResult& k = r->intrinsics;
  k.camera.intrinsics = Eigen::Vector4d(b.intrinsics.data());
  k.camera.projection_params = Eigen::Vector2d(b.projection.data());
  k.camera.distortion_coeffs = Eigen::Vector4d(b.distortion.data());
  k.camera.shutter = inputs_[c].shutter;
  k.camera.shutter.kind = b.rolling ? Shutter::Kind::kRolling : Shutter::Kind::kGlobal;
  k.camera.shutter.line_delay_s = b.rolling ? b.line_delay : 0.0;
  r->shutter_choice = b.shutter_choice;
  if (b.rolling && !b.line_delay_fixed) {
    const double var = block(&b.line_delay, &b.line_delay, 1, 1)(0, 0);
    r->line_delay_sigma_s = std::isfinite(var) ? std::sqrt(std::max(var, 0.0)) : kNaN;
  }
  const Eigen::Matrix<double, 10, 10> C = camera_covariance(
      inputs_[c].model, {b.intrinsics.data(), b.projection.data(), b.distortion.data()}, block);
  set_camera_covariance(C.allFinite() ? std::optional(C) : std::nullopt, &k);
  if (!k.covariance_ok) {
    // Keep the sigmas of the parameters that were determined (NaN: not determined).
    k.covariance = C;
    const Eigen::VectorXd s = sigma_of(C);
    for (int i = 0; i < 4; ++i) k.intrinsics_sigma[i] = s[i];
    for (int i = 0; i < projection_param_count(k.camera.projection); ++i) k.projection_sigma[i] = s[4 + i];
    for (int i = 0; i < distortion_coeff_count(k.camera.distortion_model); ++i)
      k.distortion_sigma[i] = s[6 + i];
  }
  const double rel = std::max(k.intrinsics_sigma[0] / k.camera.intrinsics[0],
                              k.intrinsics_sigma[1] / k.camera.intrinsics[1]);
  k.focal_well_determined = k.covariance_ok && rel <= opt_.intrinsics.max_focal_relative_sigma;
  double sum = 0.0;
  k.residuals_px.clear();
  k.residual_rejected.clear();
  const std::size_t step =
      std::max<std::size_t>(1, (res.size() + CameraIntrinsicsResult::kMaxStoredResiduals - 1) /
                                   CameraIntrinsicsResult::kMaxStoredResiduals);
  for (std::size_t i = 0; i < res.size(); ++i) {
    sum += res[i].squaredNorm();
    if (i % step == 0) {
      k.residuals_px.push_back(res[i].cast<float>());
      k.residual_rejected.push_back(0);
    }
  }
  r->rms_px = res.empty() ? kNaN : std::sqrt(sum / static_cast<double>(res.size()));
  k.rms_px = r->rms_px;
  k.residual_sigma_px = b.sigma_px;
  k.points_used = static_cast<int>(res.size());
  k.corners_rejected = 0;
  r->views_used = 0;
  for (const ViewData& v : views_) {
    if (v.camera != c) continue;
    k.corners_rejected += static_cast<int>(std::count(v.keep.begin(), v.keep.end(), 0));
    ++r->views_used;
  }
  k.warnings = camera_quality_warnings(k, opt_.intrinsics);
  r->T_cam_cam0 = pose_of(b);
  r->linked_to = parent_[c];
  r->timeshift_cam0_s = b.shift;
  r->timeshift_estimated = c > 0 && opt_.estimate_time_offsets;
  r->timeshift_sigma_s = r->timeshift_estimated ? std::sqrt(block(&b.shift, &b.shift, 1, 1)(0, 0)) : 0.0;
  if (c > 0) {
    Eigen::Matrix<double, 6, 6> P;
    P << block(b.q.data(), b.q.data(), 3, 3), block(b.q.data(), b.t.data(), 3, 3),
        block(b.t.data(), b.q.data(), 3, 3), block(b.t.data(), b.t.data(), 3, 3);
    r->T_cam_cam0_covariance = P;
    fill_relative(c, block, r);
  }
}

void ChainSolver::fill_relative(std::size_t c, const BlockCovariance& block,
                                CameraChainCameraResult* r) const {
  // Relative to the camera before it: T_n_m = T_n_0 T_m_0^-1, its covariance propagated through
  // the joint covariance of both poses (cam0's is the reference, not an estimate).
  const CameraBlocks& b = blocks_[c];
  const CameraBlocks& m = blocks_[c - 1];
  const Eigen::Isometry3d T_n0 = pose_of(b), T_m0 = pose_of(m);
  r->T_cn_cnm1 = T_n0 * T_m0.inverse();
  Eigen::Matrix<double, 12, 12> P12 = Eigen::Matrix<double, 12, 12>::Zero();
  const double* nb[2] = {b.q.data(), b.t.data()};
  const double* mb[2] = {m.q.data(), m.t.data()};
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) {
      P12.block<3, 3>(3 * i, 3 * j) = block(nb[i], nb[j], 3, 3);
      if (c - 1 == 0) continue;
      P12.block<3, 3>(6 + 3 * i, 6 + 3 * j) = block(mb[i], mb[j], 3, 3);
      P12.block<3, 3>(3 * i, 6 + 3 * j) = block(nb[i], mb[j], 3, 3);
      P12.block<3, 3>(6 + 3 * i, 3 * j) = block(mb[i], nb[j], 3, 3);
    }
  }
  const Eigen::Matrix<double, 6, 12> J = relative_jacobian(T_n0, T_m0);
  const Eigen::Matrix<double, 6, 6> Crel = J * P12 * J.transpose();
  r->T_cn_cnm1_covariance = Crel;
  const Eigen::VectorXd sr = sigma_of(Crel);
  r->T_cn_cnm1_rotation_sigma_rad = sr.head<3>();
  r->T_cn_cnm1_translation_sigma_m = sr.tail<3>();
  const Eigen::Vector3d t = r->T_cn_cnm1.translation();
  r->baseline_m = t.norm();
  const Eigen::Vector3d g = t / std::max(r->baseline_m, 1e-12);
  const double var = g.transpose() * Crel.bottomRightCorner<3, 3>() * g;
  r->baseline_sigma_m = std::isnan(var) ? kNaN : std::sqrt(std::max(0.0, var));
}

void ChainSolver::check_synchronization(CameraChainResult* out) {
  std::vector<double> t0;
  for (const auto& s : tracks_[0]) t0.push_back(s.t);
  for (std::size_t c = 1; c < out->cameras.size(); ++c) {
    CameraChainCameraResult& r = out->cameras[c];
    for (const auto& s : tracks_[c])
      if (std::binary_search(t0.begin(), t0.end(), s.t)) ++r.views_stamped_with_cam0;
    if (!r.timeshift_estimated) continue;
    const double z = std::abs(r.timeshift_cam0_s) / r.timeshift_sigma_s;
    const bool same_stamps = 2 * r.views_stamped_with_cam0 > static_cast<int>(tracks_[c].size());
    if (same_stamps && z > 3.0) {
      warnings_.push_back(
          r.name + "'s frames carry the same stamps as " + out->cameras[0].name + "'s, but show the scene " +
          format_number("%.3f", 1e3 * std::abs(r.timeshift_cam0_s)) + " +- " +
          format_number("%.2g", 1e3 * r.timeshift_sigma_s) + " ms " +
          (r.timeshift_cam0_s > 0 ? "later" : "earlier") +
          ": the cameras are not synchronized (or their stamps are not their exposure times); "
          "the offset is estimated and used here, and any tool that trusts the stamps will be "
          "off by it");
    }
  }
}

Status ChainSolver::fill(CameraChainResult* out) {
  MarginalCovariance cov;
  const BlockCovariance block = solution_covariance(&cov);
  const auto res = residuals_by_camera();
  double sum_all = 0.0;
  std::size_t n_all = 0;
  out->cameras.resize(inputs_.size());
  for (std::size_t c = 0; c < inputs_.size(); ++c) {
    fill_camera(c, block, res[c], &out->cameras[c]);
    for (const auto& e : res[c]) sum_all += e.squaredNorm();
    n_all += res[c].size();
  }
  out->rms_px = n_all > 0 ? std::sqrt(sum_all / static_cast<double>(n_all)) : kNaN;
  fill_pairs(out);
  check_synchronization(out);
  for (std::size_t c = 0; c < inputs_.size(); ++c) {
    for (const auto& w : out->cameras[c].intrinsics.warnings) warnings_.push_back(inputs_[c].name + ": " + w);
  }
  return {};
}

Status ChainSolver::plan_shutters() {
  using Mode = ShutterSolveOptions::Mode;
  const ShutterSolveOptions& o = opt_.shutter;
  for (std::size_t c = 0; c < inputs_.size(); ++c) {
    CameraBlocks& b = blocks_[c];
    const Shutter& in = inputs_[c].shutter;
    b.line_delay = in.rolling() ? in.line_delay_s : 0.0;
    if (o.mode == Mode::kGlobal && !o.line_delay_s) {
      b.shutter_choice = global_as_requested(in.rolling() ? "the camera is known to be rolling" : "");
      continue;
    }
    if (!opt_.estimate_time_offsets) {
      if (o.mode == Mode::kRolling || o.line_delay_s)
        return make_error(Errc::kInvalidArgument,
                          "a rolling shutter needs the cameras' trajectory: calibrate with the time offsets "
                          "estimated, not held (" +
                              option_words(CalibOption::kHoldTimeOffsets) + ")");
      b.shutter_choice = "global: with one pose per instant (" + option_words(CalibOption::kHoldTimeOffsets) +
                         ") a rolling shutter is not modelled";
      continue;
    }
    if (o.line_delay_s) {
      b.rolling = true;
      b.line_delay = *o.line_delay_s;
      b.shutter_choice = line_delay_as_given();
      continue;
    }
    b.test = true;
    b.keep_rolling = o.mode == Mode::kRolling;
  }
  return {};
}

Status ChainSolver::choose_shutter(int* dropped) {
  bool any = false, choose = false;
  for (const CameraBlocks& b : blocks_) {
    any = any || b.test;
    choose = choose || (b.test && !b.keep_rolling);
  }
  if (!any) return {};
  // The global solution and its cost at the current weights (the last re-estimate of the corner
  // sigmas may have moved them a little without a solve); the rolling one at the same weights
  // (both plain least squares) gives the likelihood ratio.
  const std::vector<CameraBlocks> global_blocks = blocks_;
  const std::vector<Arr4> global_q = q_;
  const std::vector<Arr3> global_p = p_;
  build(0.0);
  double global_cost = 0.0;
  problem_->Evaluate(ceres::Problem::EvaluateOptions(), &global_cost, nullptr, nullptr, nullptr);
  double k = 0.0;
  for (CameraBlocks& b : blocks_) {
    if (!b.test) continue;
    b.rolling = true;
    b.line_delay_fixed = false;
    k += 1.0;
  }
  IMUCAL_TRY(solve(0.0, "rolling shutter"));
  const double lr = 2.0 * (global_cost - last_cost_);
  double n = 0.0;
  for (std::size_t v = 0; v < views_.size(); ++v)
    if (blocks_[views_[v].camera].test)
      n += 2.0 * static_cast<double>(std::count(views_[v].keep.begin(), views_[v].keep.end(), 1));
  double readout = 0.0;  // the longest of the freed cameras, s
  for (std::size_t c = 0; c < blocks_.size(); ++c)
    if (blocks_[c].test)
      readout = std::max(readout, std::abs(blocks_[c].line_delay) * (starts_[c].camera.height - 1));
  const ShutterVerdict verdict = judge_shutter(choose, lr, k, n, readout);
  if (!verdict.rolling) {
    blocks_ = global_blocks;
    q_ = global_q;
    p_ = global_p;
    for (CameraBlocks& b : blocks_)
      if (b.test) b.shutter_choice = verdict.text;
    build(0.0);
    last_cost_ = global_cost;
    return {};
  }
  for (CameraBlocks& b : blocks_)
    if (b.test) b.shutter_choice = verdict.text;
  // The corners the global model's misfit had rejected (the views moving fastest) are taken back
  // and judged again: the robust pass, the rejection and the plain passes of run(), rolling.
  for (ViewData& v : views_) std::fill(v.keep.begin(), v.keep.end(), 1);
  IMUCAL_TRY(solve(opt_.loss_sigmas, "rolling shutter"));
  reestimate_sigmas(true);
  *dropped = reject_corners();
  IMUCAL_TRY(solve(0.0, "rolling shutter"));
  // Weighted anew by the corner noise the rolling model leaves (the global one's overstated it).
  for (int round = 0; round < 3 && reestimate_sigmas(false); ++round)
    IMUCAL_TRY(solve(0.0, "rolling shutter"));
  for (std::size_t c = 0; c < blocks_.size(); ++c) {
    if (!blocks_[c].test || !(blocks_[c].line_delay < 0.0)) continue;
    warnings_.push_back(
        inputs_[c].name + ": the line delay came out negative (" +
        format_number("%.2f", 1e6 * blocks_[c].line_delay) +
        " us per row): the rows are read out the other way round; calibrate again with the other readout (" +
        other_readout_words(inputs_[c].shutter.readout) + ")");
  }
  return {};
}

Result<CameraChainResult> ChainSolver::run(const TargetDescription& target, const ProgressFn& progress) {
  const double cpu0 = cpu_now_s();
  IMUCAL_TRY(plan_shutters());
  IMUCAL_TRY(start_cameras(target, progress));
  IMUCAL_TRY(link_cameras());
  if (opt_.estimate_time_offsets) {
    initialise_spline();
  } else {
    initialise_poses();
  }
  report_progress(progress, 0.45, 1.0);
  IMUCAL_TRY(solve(opt_.loss_sigmas, "robust pass"));
  reestimate_sigmas(true);
  int dropped = reject_corners();
  report_progress(progress, 0.65, 1.0);
  IMUCAL_TRY(solve(0.0, "final pass"));
  // The corner noise from the plain residuals; solved again while it moves.
  for (int k = 0; k < 3 && reestimate_sigmas(false); ++k) IMUCAL_TRY(solve(0.0, "final pass"));
  IMUCAL_TRY(choose_shutter(&dropped));
  report_progress(progress, 0.9, 1.0);
  CameraChainResult out;
  out.knot_spacing_s = discrete_ ? 0.0 : timing_.dt_s;
  IMUCAL_TRY(fill(&out));
  if (dropped > 0) {
    std::size_t total = 0;
    for (const ViewData& v : views_) total += v.px.size();
    std::string why = std::to_string(dropped) + " corners beyond " + format_number("%g", opt_.reject_sigmas) +
                      " robust sigmas of their camera were left out";
    if (20 * static_cast<std::size_t>(dropped) > total) {
      why += " (" + format_number("%.0f", 100.0 * dropped / static_cast<double>(total)) +
             " % of them): the model does not fit these views" +
             (opt_.estimate_time_offsets
                  ? std::string("; check the detections and the camera models (still pairs taken seconds "
                                "apart, which no smooth motion joins, are calibrated with the offsets held)")
                  : std::string("; cameras that are not triggered together do this with the offsets held: "
                                "calibrate again without holding them"));
    }
    warnings_.push_back(why);
  }
  out.warnings = std::move(warnings_);
  out.iterations = iterations_;
  out.solve_cpu_s = cpu_now_s() - cpu0;
  report_progress(progress, 1.0, 1.0);
  return out;
}

}  // namespace

Result<CameraChainResult> calibrate_camera_chain(const TargetDescription& target,
                                                 std::span<const CameraChainInput> cameras,
                                                 const CameraChainOptions& options,
                                                 const ProgressFn& progress) {
  IMUCAL_TRY(options.validate());
  IMUCAL_TRY(target.validate());
  if (cameras.empty()) return make_error(Errc::kInvalidArgument, "no camera to calibrate");
  ChainSolver solver(cameras, options);
  return solver.run(target, progress);
}

}  // namespace imucal::calib
