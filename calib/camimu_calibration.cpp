#include "calib/camimu_calibration.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "calib/camimu_init.hpp"
#include "calib/camimu_residuals.hpp"
#include "calib/marginal_covariance.hpp"
#include "core/threads.hpp"

namespace imucal::calib {

Status CamImuOptions::validate() const {
  if (spline_order < 4 || spline_order > 6)
    return make_error(Errc::kInvalidArgument, "spline order must be 4, 5 or 6 (cubic to quintic)");
  if (!(knot_spacing_s >= 0.005 && knot_spacing_s <= 0.5))
    return make_error(Errc::kInvalidArgument, "knot spacing must be within 0.005-0.5 s");
  if (!(bias_knot_spacing_s >= knot_spacing_s && bias_knot_spacing_s <= 60.0))
    return make_error(Errc::kInvalidArgument, "bias knot spacing must be between the knot spacing and 60 s");
  if (!(corner_sigma_px >= 0.0 && corner_sigma_px <= 50.0) || !(reprojection_loss_sigmas > 0.0))
    return make_error(Errc::kInvalidArgument,
                      "the corner sigma must be within 0-50 px (0: estimated) and the loss scale positive");
  if (!(noise.accel_noise_density > 0 && noise.gyro_noise_density > 0 && noise.accel_random_walk > 0 &&
        noise.gyro_random_walk > 0))
    return make_error(Errc::kInvalidArgument, "every IMU noise figure must be positive (imu.yaml)");
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9))
    return make_error(Errc::kInvalidArgument, "gravity must be within 9.7-9.9 m/s^2");
  if (!(max_timeshift_s > 0.0 && max_timeshift_s <= 1.0))
    return make_error(Errc::kInvalidArgument, "the largest time offset searched must be within (0, 1] s");
  if (max_iterations < 1)
    return make_error(Errc::kInvalidArgument, "at least one solver iteration is needed");
  return {};
}

namespace {

using namespace camimu;
using Arr3 = std::array<double, 3>;
/// Below this the corner noise is not believed (quantisation of the stored corners, model error).
constexpr double kMinCornerSigmaPx = 0.005;
constexpr int kPreliminaryIterations = 12;
using Arr4 = std::array<double, 4>;

Arr4 to_quat(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  return {q.x(), q.y(), q.z(), q.w()};
}
Arr3 to_arr(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
Eigen::Map<Eigen::Vector3d> vec(Arr3& a) { return Eigen::Map<Eigen::Vector3d>(a.data()); }
Eigen::Map<const Eigen::Vector3d> vec(const Arr3& a) { return Eigen::Map<const Eigen::Vector3d>(a.data()); }

struct CameraState {
  Arr4 q_ci{0, 0, 0, 1};
  Arr3 t_ci{0, 0, 0};
  double shift = 0.0;
  std::vector<FramePose> poses;
  TimeshiftEstimate xcorr;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  // of the rotation alignment
  double sigma_px = 0.3;                                // corner noise, per coordinate
};

/// Everything the solver moves, at stable addresses.
template <int N>
struct State {
  SplineTiming<N> pose, bias;
  std::vector<Arr4> q;
  std::vector<Arr3> p, ba, bg;
  Arr3 g{0, 0, -9.80665};
  Arr3 Sa{1, 1, 1}, Ma{0, 0, 0}, Sg{1, 1, 1}, Mg{0, 0, 0};
  Arr4 C{0, 0, 0, 1};
  std::array<double, 9> B{};
  std::vector<CameraState> cams;
};

class ProgressCallback final : public ceres::IterationCallback {
 public:
  ProgressCallback(const CamImuProgressFn& fn, std::string stage) : fn_(fn), stage_(std::move(stage)) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (fn_) fn_({stage_, s.iteration, s.cost, s.gradient_max_norm});
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const CamImuProgressFn& fn_;
  std::string stage_;
};

template <int N>
class Estimator {
 public:
  Estimator(const std::vector<CamImuSample>& imu, const std::vector<CamImuCameraInput>& cameras,
            const TargetDescription& target, const CamImuOptions& options, const CamImuProgressFn& progress)
      : imu_(imu), cameras_(cameras), points_(target.points()), opt_(options), progress_(progress) {}

  Result<CamImuCalibrationResult> run();

 private:
  Status initialise();
  Status initialise_camera(std::size_t c, const GyroLookup& gyro);
  void initialise_spline(std::size_t ref);
  void build(ceres::Problem* problem, bool extended);
  Status solve(bool extended, const std::string& stage, ceres::Solver::Summary* summary);
  bool frames_in_window() const;
  /// The corner noise of each camera from the current residuals (1.4826 x median |component|);
  /// true when it moved by more than 10 % for any camera.
  bool reestimate_corner_sigma();
  void covariance(CamImuCalibrationResult* out);
  void fill_result(CamImuCalibrationResult* out);
  /// Measured and predicted IMU signals of the problem as it stands.
  ImuSignalFit signal_fit(const std::string& model) const;
  double t_s(TimeNs t) const { return static_cast<double>(t - t0_ns_) * 1e-9; }

  const std::vector<CamImuSample>& imu_;
  const std::vector<CamImuCameraInput>& cameras_;
  std::vector<Eigen::Vector3d> points_;
  CamImuOptions opt_;
  const CamImuProgressFn& progress_;
  TimeNs t0_ns_ = 0;
  State<N> st_;
  std::vector<const FrameResidual<N>*> frames_;  // of the last build
  std::vector<std::size_t> frame_camera_;
  std::vector<std::vector<double*>> frame_blocks_;
  std::vector<const ImuResidual<N>*> imu_residuals_;
  std::vector<std::vector<double*>> imu_blocks_;
  std::vector<std::size_t> imu_index_;  // imu_ sample of each IMU residual
  CamImuQuality quality_;
  std::vector<std::string> warnings_;
  std::unique_ptr<ceres::Problem> problem_;
};

template <int N>
Status Estimator<N>::initialise_camera(std::size_t c, const GyroLookup& gyro) {
  const auto& cam = cameras_[c];
  CameraState& cs = st_.cams[c];
  const double max_rms_px = opt_.corner_sigma_px > 0 ? 10.0 * opt_.corner_sigma_px + 2.0 : 5.0;
  cs.poses = pnp_poses(cam.camera, cam.observations, points_, t0_ns_, 6, max_rms_px);
  if (cs.poses.size() < 20)
    return make_error(Errc::kInsufficientData,
                      cam.name + ": the target's pose was found in " + std::to_string(cs.poses.size()) +
                          " frames; at least 20 are needed (move the rig in front of the target)");
  if (opt_.corner_sigma_px > 0) {
    cs.sigma_px = opt_.corner_sigma_px;
  } else {
    // Per-coordinate sigma from the PnP residuals: rms^2 = 2 sigma^2 (2n - 6) / (2n) for n corners.
    std::vector<double> rms;
    for (const auto& p : cs.poses) rms.push_back(p.rms_px);
    std::nth_element(rms.begin(), rms.begin() + static_cast<long>(rms.size() / 2), rms.end());
    cs.sigma_px = std::max(kMinCornerSigmaPx, rms[rms.size() / 2] / std::sqrt(2.0) * 1.04);
  }
  std::vector<double> dts;
  for (std::size_t i = 1; i < cs.poses.size(); ++i) dts.push_back(cs.poses[i].t_s - cs.poses[i - 1].t_s);
  std::nth_element(dts.begin(), dts.begin() + static_cast<long>(dts.size() / 2), dts.end());
  const double frame_dt = dts[dts.size() / 2];
  const auto rates = camera_rates(cs.poses, 2.5 * frame_dt);
  const double half = 0.5 * frame_dt;
  if (c < opt_.timeshift_init_s.size() && opt_.timeshift_init_s[c]) {
    cs.shift = *opt_.timeshift_init_s[c];
  } else {
    cs.xcorr = correlate_timeshift(rates, gyro, half, opt_.max_timeshift_s);
    if (cs.xcorr.curve.empty())
      return make_error(Errc::kInsufficientData,
                        cam.name + ": the frames and the IMU samples do not overlap in time");
    cs.shift = cs.xcorr.shift_s;
  }
  const RotationEstimate rot = align_rotation(rates, gyro, cs.shift, half);
  cs.gyro_bias = rot.gyro_bias;
  if (c < opt_.T_cam_imu_init.size() && opt_.T_cam_imu_init[c]) {
    cs.q_ci = to_quat(opt_.T_cam_imu_init[c]->linear());
    cs.t_ci = to_arr(opt_.T_cam_imu_init[c]->translation());
    return {};
  }
  double speed = 0.0;
  for (const auto& r : rates) speed += r.w.squaredNorm();
  speed = std::sqrt(speed / std::max<std::size_t>(1, rates.size()));
  if (rot.pairs < 20 || speed < 0.05)
    return make_error(Errc::kInsufficientData,
                      cam.name + ": too little rotation to align camera and IMU (RMS " +
                          std::to_string(speed) + " rad/s); rotate the rig about all axes");
  cs.q_ci = to_quat(rot.R_cam_imu);
  return {};
}

template <int N>
Status Estimator<N>::initialise() {
  if (imu_.size() < 100)
    return make_error(Errc::kInsufficientData, "fewer than 100 IMU samples in the recording");
  t0_ns_ = imu_.front().t_ns;
  std::vector<double> ts;
  std::vector<Eigen::Vector3d> ws;
  for (const auto& s : imu_) {
    ts.push_back(t_s(s.t_ns));
    ws.push_back(s.gyro);
  }
  const GyroLookup gyro(ts, ws);
  st_.cams.resize(cameras_.size());
  std::size_t ref = 0;
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    if (Status s = initialise_camera(c, gyro); !s.ok()) return s;
    if (st_.cams[c].poses.size() > st_.cams[ref].poses.size()) ref = c;
  }
  if (opt_.imu_init) {
    const KrebsImuModel& m = *opt_.imu_init;
    st_.Sa = to_arr(m.S_a);
    st_.Ma = to_arr(m.M_a);
    st_.Sg = to_arr(m.S_g);
    st_.Mg = to_arr(m.M_g);
    st_.C = to_quat(m.C_bg);
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(st_.B.data()) = m.B_g;
  }
  initialise_spline(ref);
  if (st_.pose.knots < N + 2)
    return make_error(Errc::kInsufficientData, "the frames and the IMU overlap for too short a time (" +
                                                   std::to_string((st_.pose.end_s() - st_.pose.t0_s)) +
                                                   " s)");
  return {};
}

template <int N>
void Estimator<N>::initialise_spline(std::size_t ref) {
  const CameraState& cs = st_.cams[ref];
  const Eigen::Matrix3d R_ci = quat_matrix(cs.q_ci.data());
  const Eigen::Vector3d t_ci = vec(cs.t_ci);
  // Body poses from the camera poses: T_wb = T_wc T_cb with T_cb = T_cam_imu.
  std::vector<double> tb;
  std::vector<Eigen::Matrix3d> Rb;
  std::vector<Eigen::Vector3d> pb;
  for (const auto& fp : cs.poses) {
    tb.push_back(fp.t_s + cs.shift);
    Rb.push_back(fp.R_wc * R_ci);
    pb.push_back(fp.R_wc * t_ci + fp.p_wc);
  }
  const double t_start = std::max(tb.front(), t_s(imu_.front().t_ns));
  const double t_end = std::min(tb.back(), t_s(imu_.back().t_ns));
  const double dt = opt_.knot_spacing_s;
  st_.pose = {t_start, dt, std::max(0, static_cast<int>(std::ceil((t_end - t_start) / dt))) + N};
  const double bdt = opt_.bias_knot_spacing_s;
  st_.bias = {t_start, bdt, std::max(0, static_cast<int>(std::ceil((t_end - t_start) / bdt))) + N};
  // Knot i weighs most at t0 + (i - (N - 2) / 2) dt: take the body pose interpolated there.
  st_.q.resize(static_cast<std::size_t>(st_.pose.knots));
  st_.p.resize(st_.q.size());
  for (int i = 0; i < st_.pose.knots; ++i) {
    const double tau = std::clamp(t_start + (i - 0.5 * (N - 2)) * dt, tb.front(), tb.back());
    const std::size_t j = std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(tb.begin(), tb.end(), tau) - tb.begin()), tb.size() - 1);
    const std::size_t i0 = j == 0 ? 0 : j - 1;
    const double a = tb[j] > tb[i0] ? (tau - tb[i0]) / (tb[j] - tb[i0]) : 0.0;
    const Eigen::Matrix3d R = Rb[i0] * so3::exp(a * so3::log(Rb[i0].transpose() * Rb[j]));
    st_.q[static_cast<std::size_t>(i)] = to_quat(R);
    st_.p[static_cast<std::size_t>(i)] = to_arr((1 - a) * pb[i0] + a * pb[j]);
  }
  // Gravity: the mean of R f over the recording is -g (the mean acceleration is about zero).
  Eigen::Vector3d mean_rf = Eigen::Vector3d::Zero();
  int n = 0;
  So3Spline<N> rot(st_.pose.t0_s, dt, st_.pose.knots);
  for (int i = 0; i < st_.pose.knots; ++i)
    rot.knots()[static_cast<std::size_t>(i)] = quat_matrix(st_.q[i].data());
  for (std::size_t k = 0; k < imu_.size(); ++k) {
    const CamImuSample& s = imu_[k];
    const double t = t_s(s.t_ns);
    if (!st_.pose.covers(t)) continue;
    mean_rf += rot.evaluate(t, So3Derivs::kValue).R * s.accel;
    ++n;
  }
  st_.g = to_arr(-opt_.gravity_mps2 * mean_rf.normalized());
  const Eigen::Vector3d ba0 = opt_.imu_init ? opt_.imu_init->b_a : Eigen::Vector3d::Zero();
  // The gyro bias starts from this recording's rate alignment even with a prior model: a bias
  // changes from one power-up to the next, and a prior given only for B_g carries none.
  const Eigen::Vector3d bg0 = cs.gyro_bias;
  st_.ba.assign(static_cast<std::size_t>(st_.bias.knots), to_arr(ba0));
  st_.bg.assign(static_cast<std::size_t>(st_.bias.knots), to_arr(bg0));
  // Other cameras: the translation from their poses against the body trajectory.
  for (std::size_t c = 0; c < st_.cams.size(); ++c) {
    if (c == ref || (c < opt_.T_cam_imu_init.size() && opt_.T_cam_imu_init[c])) continue;
    RdSpline<N> pos(st_.pose.t0_s, dt, st_.pose.knots);
    for (int i = 0; i < st_.pose.knots; ++i) pos.knots()[static_cast<std::size_t>(i)] = vec(st_.p[i]);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int m = 0;
    const Eigen::Matrix3d Rci = quat_matrix(st_.cams[c].q_ci.data());
    for (const auto& fp : st_.cams[c].poses) {
      const double t = fp.t_s + st_.cams[c].shift;
      if (!st_.pose.covers(t)) continue;
      // t_cb = R_cw (p_wb - p_wc) with R_cw = R_cb R_wb^T.
      const Eigen::Matrix3d R_wb = rot.evaluate(t, So3Derivs::kValue).R;
      sum += Rci * R_wb.transpose() * (pos.evaluate(t) - fp.p_wc);
      ++m;
    }
    if (m > 0) st_.cams[c].t_ci = to_arr(sum / m);
  }
}

template <int N>
void Estimator<N>::build(ceres::Problem* problem, bool extended) {
  static RightQuaternionManifold quat_manifold;
  static ceres::SphereManifold<3> sphere;
  for (auto& q : st_.q) problem->AddParameterBlock(q.data(), 4, &quat_manifold);
  problem->AddParameterBlock(st_.C.data(), 4, &quat_manifold);
  problem->AddParameterBlock(st_.g.data(), 3, &sphere);
  frames_.clear();
  frame_camera_.clear();
  frame_blocks_.clear();
  imu_residuals_.clear();
  imu_blocks_.clear();
  imu_index_.clear();
  std::vector<double> dts;
  for (std::size_t i = 1; i < imu_.size(); ++i) dts.push_back(t_s(imu_[i].t_ns) - t_s(imu_[i - 1].t_ns));
  std::nth_element(dts.begin(), dts.begin() + static_cast<long>(dts.size() / 2), dts.end());
  const double rate = 1.0 / dts[dts.size() / 2];
  quality_.accel_sigma = opt_.noise.accel_noise_density * std::sqrt(rate);
  quality_.gyro_sigma = opt_.noise.gyro_noise_density * std::sqrt(rate);
  for (std::size_t k = 0; k < imu_.size(); ++k) {
    const CamImuSample& s = imu_[k];
    const double t = t_s(s.t_ns);
    if (!st_.pose.covers(t)) continue;
    const SplineSegment seg = st_.pose.segment(t), bseg = st_.bias.segment(t);
    typename ImuResidual<N>::Sample smp{seg.u, bseg.u, st_.pose.dt_s, st_.bias.dt_s, s.accel, s.gyro};
    auto* cost = new ImuResidual<N>(smp, quality_.accel_sigma, quality_.gyro_sigma);
    std::vector<double*> blocks;
    for (int i = 0; i < N; ++i) blocks.push_back(st_.q[seg.first_knot + i].data());
    for (int i = 0; i < N; ++i) blocks.push_back(st_.p[seg.first_knot + i].data());
    for (int i = 0; i < N; ++i) blocks.push_back(st_.ba[bseg.first_knot + i].data());
    for (int i = 0; i < N; ++i) blocks.push_back(st_.bg[bseg.first_knot + i].data());
    for (double* b : {st_.g.data(), st_.Sa.data(), st_.Ma.data(), st_.Sg.data(), st_.Mg.data(), st_.C.data(),
                      st_.B.data()})
      blocks.push_back(b);
    problem->AddResidualBlock(cost, nullptr, blocks);
    imu_residuals_.push_back(cost);
    imu_blocks_.push_back(std::move(blocks));
    imu_index_.push_back(k);
  }
  // Bias random walk: three-point Gauss-Legendre quadrature of |db/dt|^2 per bias segment.
  const double gl_u[3] = {0.5 - 0.5 * std::sqrt(0.6), 0.5, 0.5 + 0.5 * std::sqrt(0.6)};
  const double gl_w[3] = {5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0};
  for (int s = 0; s + N <= st_.bias.knots; ++s) {
    for (int q = 0; q < 3; ++q) {
      for (auto [knots, sigma] : {std::pair{&st_.ba, opt_.noise.accel_random_walk},
                                  std::pair{&st_.bg, opt_.noise.gyro_random_walk}}) {
        const double w = std::sqrt(gl_w[q] * st_.bias.dt_s) / sigma;
        std::vector<double*> blocks;
        for (int i = 0; i < N; ++i) blocks.push_back((*knots)[static_cast<std::size_t>(s + i)].data());
        problem->AddResidualBlock(new BiasWalkResidual<N>(gl_u[q], st_.bias.dt_s, w), nullptr, blocks);
      }
    }
  }
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    CameraState& cs = st_.cams[c];
    problem->AddParameterBlock(cs.q_ci.data(), 4, &quat_manifold);
    for (const auto& obs : cameras_[c].observations) {
      const double t = t_s(obs.t_ns) + cs.shift;
      if (obs.ids.size() < 4 || !st_.pose.covers(t)) continue;
      const int first = std::clamp(st_.pose.segment(t).first_knot - 1, 0, st_.pose.knots - N - 2);
      std::vector<Eigen::Vector3d> pts;
      for (int id : obs.ids) pts.push_back(points_[static_cast<std::size_t>(id)]);
      auto* cost = new FrameResidual<N>(cameras_[c].camera, std::move(pts), obs.px, t_s(obs.t_ns), first,
                                        st_.pose, cs.sigma_px, opt_.reprojection_loss_sigmas * cs.sigma_px);
      std::vector<double*> blocks;
      for (int i = 0; i < FrameResidual<N>::kWindow; ++i) blocks.push_back(st_.q[first + i].data());
      for (int i = 0; i < FrameResidual<N>::kWindow; ++i) blocks.push_back(st_.p[first + i].data());
      blocks.push_back(cs.q_ci.data());
      blocks.push_back(cs.t_ci.data());
      blocks.push_back(&cs.shift);
      problem->AddResidualBlock(cost, nullptr, blocks);
      frames_.push_back(cost);
      frame_camera_.push_back(c);
      frame_blocks_.push_back(std::move(blocks));
    }
    if (opt_.fixed.T_cam_imu) {
      problem->SetParameterBlockConstant(cs.q_ci.data());
      problem->SetParameterBlockConstant(cs.t_ci.data());
    }
    if (opt_.fixed.timeshift) problem->SetParameterBlockConstant(&cs.shift);
  }
  const bool basic = !extended || opt_.model == CamImuModelKind::kBasic;
  const CamImuFixed& f = opt_.fixed;
  for (auto [block, fixed] :
       {std::pair{st_.Sa.data(), basic || f.S_a}, std::pair{st_.Ma.data(), basic || f.M_a},
        std::pair{st_.Sg.data(), basic || f.S_g}, std::pair{st_.Mg.data(), basic || f.M_g},
        std::pair{st_.C.data(), basic || f.C_bg}, std::pair{st_.B.data(), basic || f.B_g}}) {
    if (fixed) problem->SetParameterBlockConstant(block);
  }
}

template <int N>
bool Estimator<N>::frames_in_window() const {
  for (std::size_t k = 0; k < frames_.size(); ++k)
    if (!frames_[k]->in_window(st_.cams[frame_camera_[k]].shift)) return false;
  return true;
}

template <int N>
bool Estimator<N>::reestimate_corner_sigma() {
  if (opt_.corner_sigma_px > 0) return false;
  std::vector<std::vector<double>> comps(st_.cams.size());
  std::vector<Eigen::Vector2d> e;
  bool changed = false;
  for (std::size_t k = 0; k < frames_.size(); ++k) {
    frames_[k]->pixel_residuals(frame_blocks_[k].data(), &e);
    for (const auto& v : e) {
      comps[frame_camera_[k]].push_back(std::abs(v.x()));
      comps[frame_camera_[k]].push_back(std::abs(v.y()));
    }
  }
  for (std::size_t c = 0; c < comps.size(); ++c) {
    auto& v = comps[c];
    if (v.size() < 20) continue;
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    const double sigma = std::max(kMinCornerSigmaPx, 1.4826 * v[v.size() / 2]);
    changed = changed || std::abs(sigma / st_.cams[c].sigma_px - 1.0) > 0.1;
    st_.cams[c].sigma_px = sigma;
  }
  return changed;
}

template <int N>
Status Estimator<N>::solve(bool extended, const std::string& stage, ceres::Solver::Summary* summary) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.num_threads = threads_or_cores(opt_.threads);
  // The first stage only brings the trajectory, biases and extrinsics near the solution for the
  // stage that follows it; a few iterations do (docs/camimu-calibration.md, "Speed").
  const bool preliminary = !extended && opt_.model == CamImuModelKind::kExtended;
  so.max_num_iterations =
      preliminary ? std::min(opt_.max_iterations, kPreliminaryIterations) : opt_.max_iterations;
  so.function_tolerance = 1e-8;
  so.parameter_tolerance = 1e-9;
  ProgressCallback cb(progress_, stage);
  so.callbacks.push_back(&cb);
  // A timeshift that moves frames out of the knot window they were built with: rebuild.
  for (int attempt = 0; attempt < 4; ++attempt) {
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(po);
    build(problem_.get(), extended);
    ceres::Solve(so, problem_.get(), summary);
    if (!summary->IsSolutionUsable())
      return make_error(Errc::kSolverFailed,
                        "the camera-IMU solve failed (" + stage + "): " + summary->message);
    quality_.iterations += static_cast<int>(summary->iterations.size());
    quality_.jacobian_s += summary->jacobian_evaluation_time_in_seconds;
    quality_.linear_solver_s += summary->linear_solver_time_in_seconds;
    if (frames_in_window()) return {};
  }
  return make_error(Errc::kSolverFailed, "the time offset did not settle (" + stage + ")");
}

Eigen::Vector3d sqrt_diag(const Eigen::MatrixXd& C) {
  return C.diagonal().head<3>().cwiseMax(0.0).cwiseSqrt();
}

template <int N>
void Estimator<N>::covariance(CamImuCalibrationResult* out) {
  const auto start = std::chrono::steady_clock::now();
  ceres::Problem& problem = *problem_;
  std::vector<const double*> blocks;
  const auto want = [&](const double* b) {
    if (!problem.IsParameterBlockConstant(b)) blocks.push_back(b);
  };
  for (const double* b :
       {st_.Sa.data(), st_.Ma.data(), st_.Sg.data(), st_.Mg.data(), st_.C.data(), st_.B.data(), st_.g.data()})
    want(b);
  for (auto& cs : st_.cams) {
    want(cs.q_ci.data());
    want(cs.t_ci.data());
    want(&cs.shift);
  }
  for (int i = 0; i < N; ++i) {
    want(st_.ba[static_cast<std::size_t>(i)].data());
    want(st_.bg[static_cast<std::size_t>(i)].data());
  }
  MarginalCovariance cov;
  const int threads = threads_or_cores(opt_.threads);
  if (!cov.compute(problem, blocks, threads)) {
    warnings_.push_back(
        "the covariance could not be computed (a parameter is not observable): sigmas are not given");
    return;
  }
  const auto block = [&](const double* a, const double* b) { return cov.block(a, b); };
  const auto sigma3 = [&](const double* b) {
    return problem.IsParameterBlockConstant(b) ? Eigen::Vector3d::Zero() : sqrt_diag(block(b, b));
  };
  KrebsImuSigma& s = out->imu_sigma;
  s.S_a = sigma3(st_.Sa.data());
  s.M_a = sigma3(st_.Ma.data());
  s.S_g = sigma3(st_.Sg.data());
  s.M_g = sigma3(st_.Mg.data());
  s.C_bg = sigma3(st_.C.data());
  if (!problem.IsParameterBlockConstant(st_.B.data())) {
    const Eigen::VectorXd d = block(st_.B.data(), st_.B.data()).diagonal().cwiseMax(0.0).cwiseSqrt();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) s.B_g(r, c) = d(3 * r + c);
  }
  const Eigen::MatrixXd Cg = block(st_.g.data(), st_.g.data());
  out->gravity_sigma_rad = Cg.diagonal().head<2>().cwiseMax(0.0).cwiseSqrt() / opt_.gravity_mps2;
  // The biases at the start: b(t0) = sum_i w_i knot_i.
  const auto w = RdSpline<N>::weights_at(st_.bias.segment(st_.bias.t0_s).u, 0, st_.bias.dt_s);
  for (auto [knots, sig] : {std::pair{&st_.ba, &s.b_a}, std::pair{&st_.bg, &s.b_g}}) {
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (int i = 0; i < N; ++i)
      for (int j = i; j < N; ++j) {
        const Eigen::Matrix3d Cij =
            block((*knots)[static_cast<std::size_t>(i)].data(), (*knots)[static_cast<std::size_t>(j)].data());
        C += w(i) * w(j) * (i == j ? Cij : Eigen::Matrix3d(Cij + Cij.transpose()));
      }
    *sig = C.diagonal().cwiseMax(0.0).cwiseSqrt();
  }
  for (std::size_t c = 0; c < st_.cams.size(); ++c) {
    CamImuCameraResult& cr = out->cameras[c];
    const CameraState& cs = st_.cams[c];
    if (!problem.IsParameterBlockConstant(cs.q_ci.data())) {
      // Right perturbation -> about the camera axes: R Exp(d) = Exp(R d) R.
      const Eigen::Matrix3d R = quat_matrix(cs.q_ci.data());
      cr.rotation_sigma_rad =
          (R * block(cs.q_ci.data(), cs.q_ci.data()) * R.transpose()).diagonal().cwiseMax(0.0).cwiseSqrt();
      cr.translation_sigma_m = sigma3(cs.t_ci.data());
    }
    if (!problem.IsParameterBlockConstant(&cs.shift))
      cr.timeshift_sigma_s = std::sqrt(block(&cs.shift, &cs.shift)(0, 0));
  }
  quality_.covariance_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

template <int N>
void Estimator<N>::fill_result(CamImuCalibrationResult* out) {
  out->model = opt_.model;
  KrebsImuModel& m = out->imu;
  m.S_a = vec(st_.Sa);
  m.M_a = vec(st_.Ma);
  m.S_g = vec(st_.Sg);
  m.M_g = vec(st_.Mg);
  m.C_bg = quat_matrix(st_.C.data());
  m.B_g = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(st_.B.data());
  RdSpline<N> ba(st_.bias.t0_s, st_.bias.dt_s, st_.bias.knots), bg = ba;
  for (int i = 0; i < st_.bias.knots; ++i) {
    ba.knots()[static_cast<std::size_t>(i)] = vec(st_.ba[static_cast<std::size_t>(i)]);
    bg.knots()[static_cast<std::size_t>(i)] = vec(st_.bg[static_cast<std::size_t>(i)]);
  }
  m.b_a = ba.evaluate(st_.bias.t0_s);
  m.b_g = bg.evaluate(st_.bias.t0_s);
  for (double t = st_.pose.t0_s; t < st_.pose.end_s(); t += 0.5)
    out->biases.push_back(
        {t0_ns_ + static_cast<TimeNs>(std::llround(t * 1e9)), ba.evaluate(t), bg.evaluate(t)});
  if (auto canonical = canonical_from_krebs(m); canonical.ok()) out->canonical = *canonical;
  out->gravity_w = vec(st_.g);
  const bool basic = opt_.model == CamImuModelKind::kBasic;
  const CamImuFixed& f = opt_.fixed;
  for (auto [name, fixed] : {std::pair{"S_a", basic || f.S_a}, std::pair{"M_a", basic || f.M_a},
                             std::pair{"S_g", basic || f.S_g}, std::pair{"M_g", basic || f.M_g},
                             std::pair{"C_bg", basic || f.C_bg}, std::pair{"B_g", basic || f.B_g},
                             std::pair{"T_cam_imu", f.T_cam_imu}, std::pair{"timeshift", f.timeshift}})
    if (fixed) out->fixed.emplace_back(name);
  // Cameras: extrinsics and the reprojection figures.
  std::vector<double> sq(cameras_.size(), 0.0);
  out->cameras.resize(cameras_.size());
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    CamImuCameraResult& cr = out->cameras[c];
    cr.name = cameras_[c].name;
    cr.stream = cameras_[c].stream;
    cr.camera = cameras_[c].camera;
    cr.T_cam_imu.linear() = quat_matrix(st_.cams[c].q_ci.data());
    cr.T_cam_imu.translation() = vec(st_.cams[c].t_ci);
    cr.timeshift_cam_imu_s = st_.cams[c].shift;
    cr.corner_sigma_px = st_.cams[c].sigma_px;
  }
  std::vector<Eigen::Vector2d> e;
  std::vector<std::vector<Eigen::Vector2f>> all(cameras_.size());
  for (std::size_t k = 0; k < frames_.size(); ++k) {
    CamImuCameraResult& cr = out->cameras[frame_camera_[k]];
    const double outlier_px = opt_.reprojection_loss_sigmas * st_.cams[frame_camera_[k]].sigma_px;
    cr.outlier_px = outlier_px;
    frames_[k]->pixel_residuals(frame_blocks_[k].data(), &e);
    cr.frames += 1;
    for (const auto& v : e) {
      cr.corners += 1;
      sq[frame_camera_[k]] += v.squaredNorm();
      if (v.norm() > outlier_px) cr.outlier_corners += 1;
      all[frame_camera_[k]].push_back(v.cast<float>());
    }
  }
  // Every k-th corner when there are more than the result keeps.
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    const std::size_t n = all[c].size(), cap = CamImuCameraResult::kMaxStoredResiduals;
    const std::size_t step = (n + cap - 1) / cap;
    for (std::size_t i = 0; i < n; i += std::max<std::size_t>(step, 1))
      out->cameras[c].residuals_px.push_back(all[c][i]);
  }
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    auto& cr = out->cameras[c];
    cr.reprojection_rms_px = cr.corners > 0 ? std::sqrt(sq[c] / cr.corners) : 0.0;
  }
}

template <int N>
ImuSignalFit Estimator<N>::signal_fit(const std::string& model) const {
  ImuSignalFit fit;
  fit.model = model;
  const std::size_t n = imu_residuals_.size(), cap = ImuSignalFit::kMaxSamples;
  const std::size_t step = std::max<std::size_t>(1, (n + cap - 1) / cap);
  Eigen::Vector3d sa = Eigen::Vector3d::Zero(), sg = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    Eigen::Matrix<double, 6, 1> r;
    imu_residuals_[k]->Evaluate(imu_blocks_[k].data(), r.data(), nullptr);
    // r = (predicted - measured) / sigma.
    const Eigen::Vector3d da = r.head<3>() * quality_.accel_sigma, dg = r.tail<3>() * quality_.gyro_sigma;
    sa += da.cwiseAbs2();
    sg += dg.cwiseAbs2();
    if (k % step != 0) continue;
    const CamImuSample& s = imu_[imu_index_[k]];
    fit.t_ns.push_back(s.t_ns);
    fit.accel_measured.push_back(s.accel.cast<float>());
    fit.accel_predicted.push_back((s.accel + da).cast<float>());
    fit.gyro_measured.push_back(s.gyro.cast<float>());
    fit.gyro_predicted.push_back((s.gyro + dg).cast<float>());
  }
  const double count = std::max<double>(1.0, static_cast<double>(n));
  fit.accel_residual_rms = (sa / count).cwiseSqrt();
  fit.gyro_residual_rms = (sg / count).cwiseSqrt();
  return fit;
}

/// Excitation per body axis and the observability warnings it implies.
void excitation(const std::vector<CamImuSample>& imu, const Eigen::Vector3d& b_g, CamImuQuality* q,
                std::vector<std::string>* warnings) {
  Eigen::Vector3d mean_a = Eigen::Vector3d::Zero(), sw = Eigen::Vector3d::Zero(),
                  sa = Eigen::Vector3d::Zero();
  for (const auto& s : imu) mean_a += s.accel / static_cast<double>(imu.size());
  for (const auto& s : imu) {
    sw += (s.gyro - b_g).cwiseAbs2();
    sa += (s.accel - mean_a).cwiseAbs2();
  }
  q->rotation_excitation_radps = (sw / static_cast<double>(imu.size())).cwiseSqrt();
  q->accel_excitation_mps2 = (sa / static_cast<double>(imu.size())).cwiseSqrt();
  const char* axis[3] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    if (q->rotation_excitation_radps(i) < 0.1)
      warnings->push_back(
          std::string("little rotation about the IMU ") + axis[i] + " axis (RMS " +
          std::to_string(q->rotation_excitation_radps(i)) +
          " rad/s): its gyro scale, misalignment and the camera rotation are weakly observed");
    if (q->accel_excitation_mps2(i) < 0.5)
      warnings->push_back(std::string("little acceleration along the IMU ") + axis[i] + " axis (RMS " +
                          std::to_string(q->accel_excitation_mps2(i)) +
                          " m/s^2): its accelerometer scale and the camera translation are weakly observed");
  }
}

template <int N>
Result<CamImuCalibrationResult> Estimator<N>::run() {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = initialise(); !s.ok()) return s.error();
  const auto init_done = std::chrono::steady_clock::now();
  quality_.init_s = std::chrono::duration<double>(init_done - start).count();
  ceres::Solver::Summary summary;
  // First with the IMU intrinsics at their initial values (the trajectory, biases, gravity and
  // extrinsics settle), then everything the model estimates.
  if (Status s = solve(false, "basic", &summary); !s.ok()) return s.error();
  quality_.initial_cost = summary.initial_cost;
  const bool extended = opt_.model == CamImuModelKind::kExtended;
  std::vector<ImuSignalFit> fits;
  if (extended) fits.push_back(signal_fit("basic"));
  // The next stage weighs the corners by the noise they showed in the one before. The first
  // stage stops early with the IMU intrinsics at their start, so its residuals overstate the
  // noise: the final stage is repeated until the estimate holds (within 10 %).
  for (int round = 0; round < 3; ++round) {
    const bool changed = reestimate_corner_sigma();
    if (round > 0 && !changed) break;
    if (!extended && opt_.corner_sigma_px > 0) break;
    if (Status s = solve(extended, extended ? "extended" : "basic", &summary); !s.ok()) return s.error();
  }
  quality_.final_cost = summary.final_cost;
  quality_.solve_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - init_done).count();
  quality_.parameters = problem_->NumParameters();
  quality_.residuals = problem_->NumResiduals();
  quality_.spline_knots = st_.pose.knots;
  fits.push_back(signal_fit(extended ? "extended" : "basic"));
  quality_.accel_residual_rms = fits.back().accel_residual_rms;  // per axis, SI
  quality_.gyro_residual_rms = fits.back().gyro_residual_rms;
  CamImuCalibrationResult out;
  out.signal_fits = std::move(fits);
  fill_result(&out);
  if (opt_.covariance) covariance(&out);
  for (const auto& cs : st_.cams) {
    quality_.xcorr.push_back(cs.xcorr.curve);
    quality_.xcorr_peak_s.push_back(cs.xcorr.shift_s);
  }
  excitation(imu_, out.imu.b_g, &quality_, &warnings_);
  if (quality_.gyro_residual_rms.maxCoeff() > 3.0 * quality_.gyro_sigma ||
      quality_.accel_residual_rms.maxCoeff() > 3.0 * quality_.accel_sigma)
    warnings_.push_back(
        "IMU residuals exceed three times the assumed noise: the noise figures (imu.yaml) or the "
        "model do not fit this IMU, and the sigmas are too small");
  out.quality = quality_;
  out.warnings = warnings_;
  return out;
}

}  // namespace

Result<CamImuCalibrationResult> calibrate_camimu(const std::vector<CamImuSample>& imu,
                                                 const std::vector<CamImuCameraInput>& cameras,
                                                 const TargetDescription& target,
                                                 const CamImuOptions& options,
                                                 const CamImuProgressFn& progress) {
  if (Status s = options.validate(); !s.ok()) return s.error();
  if (cameras.empty()) return make_error(Errc::kInvalidArgument, "no camera to calibrate against the IMU");
  switch (options.spline_order) {
    case 4:
      return Estimator<4>(imu, cameras, target, options, progress).run();
    case 5:
      return Estimator<5>(imu, cameras, target, options, progress).run();
    default:
      return Estimator<6>(imu, cameras, target, options, progress).run();
  }
}

}  // namespace imucal::calib
