// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camimu_calibration.hpp"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iomanip>
#include <memory>
#include <sstream>

#include "calib/camimu_estimator.hpp"
#include "calib/camimu_imu_prep.hpp"
#include "calib/camimu_init.hpp"
#include "calib/camimu_residuals.hpp"
#include "calib/marginal_covariance.hpp"
#include "calib/observation_check.hpp"
#include "core/option_words.hpp"
#include "core/text_format.hpp"
#include "core/threads.hpp"

namespace imucal::calib {

namespace camimu {

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
  const double half = 0.5 * frame_dt;
  // Frames whose pose contradicts the gyro (a detection in the wrong order) would dominate the
  // rate alignment and start the spline on a wrong attitude: left out of the whole problem.
  // First against any time offset within reach, then, once it is known, more tightly.
  auto drop_against_gyro = [&](double shift, double uncertainty) {
    const auto bad = poses_against_gyro(cs.poses, gyro, shift, uncertainty, kPoseCheckWindowS);
    for (auto k = bad.rbegin(); k != bad.rend(); ++k) {
      cs.rejected.push_back(cs.poses[*k].t_ns);
      cs.poses.erase(cs.poses.begin() + static_cast<long>(*k));
    }
  };
  const bool shift_given = c < opt_.timeshift_init_s.size() && opt_.timeshift_init_s[c];
  if (shift_given) {
    cs.shift = *opt_.timeshift_init_s[c];
  } else {
    drop_against_gyro(0.0, opt_.max_timeshift_s);
    cs.xcorr = correlate_timeshift(camera_rates(cs.poses, 2.5 * frame_dt), gyro, half, opt_.max_timeshift_s);
    if (cs.xcorr.curve.empty())
      return make_error(Errc::kInsufficientData,
                        cam.name + ": the frames and the IMU samples do not overlap in time");
    cs.shift = cs.xcorr.shift_s;
  }
  drop_against_gyro(cs.shift, std::max(0.01, half));
  std::sort(cs.rejected.begin(), cs.rejected.end());
  if (cs.poses.size() < 20)
    return make_error(
        Errc::kInsufficientData,
        cam.name + ": the target's pose agrees with the gyro in " + std::to_string(cs.poses.size()) +
            " frames (" + std::to_string(cs.rejected.size()) +
            " contradict it); at least 20 are needed: check the target file and the IMU stream");
  const auto rates = camera_rates(cs.poses, 2.5 * frame_dt);
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
  plan_shutters();
  model_ = opt_.model;
  if (opt_.imu_init) prior0_ = *opt_.imu_init;
  {
    const double rate = 1e9 / static_cast<double>(std::max<TimeNs>(imu_median_interval_ns(imu_), 1));
    quality_.accel_sigma_given = opt_.noise.accel_noise_density * std::sqrt(rate);
    quality_.gyro_sigma_given = opt_.noise.gyro_noise_density * std::sqrt(rate);
    quality_.accel_sigma = quality_.accel_sigma_given;
    quality_.gyro_sigma = quality_.gyro_sigma_given;
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
BuiltProblem<N> Estimator<N>::build(ceres::Problem* problem, bool extended, int imu_stride) {
  static RightQuaternionManifold quat_manifold;
  static ceres::SphereManifold<3> sphere;
  for (auto& q : st_.q) problem->AddParameterBlock(q.data(), 4, &quat_manifold);
  problem->AddParameterBlock(st_.C.data(), 4, &quat_manifold);
  problem->AddParameterBlock(st_.g.data(), 3, &sphere);
  BuiltProblem<N> built;
  for (std::size_t k = 0; k < imu_.size(); k += static_cast<std::size_t>(imu_stride)) {
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
    built.timed_residuals.push_back({problem->AddResidualBlock(cost, nullptr, blocks), t});
    built.imu_residuals.push_back(cost);
    built.imu_blocks.push_back(std::move(blocks));
    built.imu_index.push_back(k);
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
      if (std::binary_search(cs.rejected.begin(), cs.rejected.end(), obs.t_ns)) continue;
      const int first = std::clamp(st_.pose.segment(t).first_knot - 1, 0, st_.pose.knots - N - 2);
      const bool rolling =
          cs.rolling && (cs.rolling_frames.empty() ||
                         std::binary_search(cs.rolling_frames.begin(), cs.rolling_frames.end(), obs.t_ns));
      std::vector<Eigen::Vector3d> pts;
      for (int id : obs.ids) pts.push_back(points_[static_cast<std::size_t>(id)]);
      auto* cost = new FrameResidual<N>(cameras_[c].camera, std::move(pts), obs.px, t_s(obs.t_ns), first,
                                        st_.pose, cs.sigma_px, opt_.reprojection_loss_sigmas * cs.sigma_px,
                                        /*compressed=*/true, rolling);
      std::vector<double*> blocks;
      for (int i = 0; i < FrameResidual<N>::kWindow; ++i) blocks.push_back(st_.q[first + i].data());
      for (int i = 0; i < FrameResidual<N>::kWindow; ++i) blocks.push_back(st_.p[first + i].data());
      blocks.push_back(cs.q_ci.data());
      blocks.push_back(cs.t_ci.data());
      blocks.push_back(&cs.shift);
      if (rolling) blocks.push_back(&cs.line_delay);
      built.timed_residuals.push_back({problem->AddResidualBlock(cost, nullptr, blocks), t});
      built.frames.push_back(cost);
      built.frame_camera.push_back(c);
      built.frame_t_ns.push_back(obs.t_ns);
      built.frame_blocks.push_back(std::move(blocks));
    }
    if (opt_.fixed.T_cam_imu) {
      problem->SetParameterBlockConstant(cs.q_ci.data());
      problem->SetParameterBlockConstant(cs.t_ci.data());
    }
    if (opt_.fixed.timeshift && problem->HasParameterBlock(&cs.shift))
      problem->SetParameterBlockConstant(&cs.shift);
    if (cs.rolling && cs.line_delay_fixed && problem->HasParameterBlock(&cs.line_delay))
      problem->SetParameterBlockConstant(&cs.line_delay);
  }
  for (const CamImuChainPrior& cp : opt_.chain_priors) {
    CameraState& n = st_.cams[static_cast<std::size_t>(cp.camera)];
    CameraState& m = st_.cams[static_cast<std::size_t>(cp.camera - 1)];
    problem->AddResidualBlock(
        new RelativePosePrior(cp.T_cn_cnm1.linear(), cp.T_cn_cnm1.translation(), cp.covariance), nullptr,
        {n.q_ci.data(), n.t_ci.data(), m.q_ci.data(), m.t_ci.data()});
  }
  const bool basic = !extended || model_ == CamImuModelKind::kBasic;
  const CamImuFixed& f = opt_.fixed;
  for (auto [block, fixed] :
       {std::pair{st_.Sa.data(), basic || f.S_a}, std::pair{st_.Ma.data(), basic || f.M_a},
        std::pair{st_.Sg.data(), basic || f.S_g}, std::pair{st_.Mg.data(), basic || f.M_g},
        std::pair{st_.C.data(), basic || f.C_bg}, std::pair{st_.B.data(), basic || f.B_g}}) {
    if (fixed) problem->SetParameterBlockConstant(block);
  }
  if (!basic && opt_.prior.enabled) add_priors(problem, &built.priors);
  return built;
}

template <int N>
KrebsImuSigma Estimator<N>::prior_sigmas() const {
  const CamImuIntrinsicsPrior& pr = opt_.prior;
  KrebsImuSigma s;
  s.S_a = pr.scale * prior0_.S_a.cwiseAbs();
  s.S_g = pr.scale * prior0_.S_g.cwiseAbs();
  s.M_a.setConstant(pr.misalignment);
  s.M_g.setConstant(pr.misalignment);
  s.C_bg.setConstant(pr.gyro_axes);
  s.B_g.setConstant(pr.gsens);
  return s;
}

template <int N>
void Estimator<N>::add_priors(ceres::Problem* problem, std::vector<typename BuiltProblem<N>::Prior>* priors) {
  const KrebsImuSigma ps = prior_sigmas();
  const auto add = [&](double* block, ceres::CostFunction* cost) {
    if (problem->IsParameterBlockConstant(block)) {
      delete cost;
      return;
    }
    problem->AddResidualBlock(cost, nullptr, block);
    priors->push_back({cost, block});
  };
  add(st_.Sa.data(), new VectorPrior(prior0_.S_a, ps.S_a));
  add(st_.Sg.data(), new VectorPrior(prior0_.S_g, ps.S_g));
  add(st_.Ma.data(), new VectorPrior(prior0_.M_a, ps.M_a));
  add(st_.Mg.data(), new VectorPrior(prior0_.M_g, ps.M_g));
  add(st_.B.data(), new VectorPrior(row_major(prior0_.B_g), row_major(ps.B_g)));
  add(st_.C.data(), new RotationPrior(prior0_.C_bg, opt_.prior.gyro_axes));
}

template <int N>
double Estimator<N>::prior_cost() const {
  double cost = 0.0;
  std::vector<double> r;
  for (const auto& p : built_.priors) {
    r.resize(static_cast<std::size_t>(p.cost->num_residuals()));
    const double* params[] = {p.block};
    p.cost->Evaluate(params, r.data(), nullptr);
    for (double v : r) cost += 0.5 * v * v;
  }
  return cost;
}

template <int N>
void Estimator<N>::rebuild(bool extended, int imu_stride) {
  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_ = std::make_unique<ceres::Problem>(po);
  covariance_.reset();
  covariance_failed_ = false;
  built_ = build(problem_.get(), extended, imu_stride);
}

template <int N>
const MarginalCovariance* Estimator<N>::solution_covariance() {
  if (covariance_ || covariance_failed_) return covariance_.get();
  std::vector<const double*> blocks;
  const auto want = [&](const double* b) {
    if (problem_->HasParameterBlock(b) && !problem_->IsParameterBlockConstant(b)) blocks.push_back(b);
  };
  for (const double* b :
       {st_.Sa.data(), st_.Ma.data(), st_.Sg.data(), st_.Mg.data(), st_.C.data(), st_.B.data(), st_.g.data()})
    want(b);
  for (auto& cs : st_.cams) {
    want(cs.q_ci.data());
    want(cs.t_ci.data());
    want(&cs.shift);
    if (cs.rolling) want(&cs.line_delay);
  }
  for (int i = 0; i < N; ++i) {
    want(st_.ba[static_cast<std::size_t>(i)].data());
    want(st_.bg[static_cast<std::size_t>(i)].data());
  }
  // The clusters of the robust covariance: the frames and IMU samples of one time block share
  // their errors (detector bias, blur, lens misfit, unmodelled IMU behaviour over the block).
  std::vector<std::vector<ceres::ResidualBlockId>> clusters;
  if (opt_.covariance_cluster_s > 0.0 && !built_.timed_residuals.empty()) {
    double first = built_.timed_residuals.front().second;
    for (const auto& [id, t] : built_.timed_residuals) first = std::min(first, t);
    for (const auto& [id, t] : built_.timed_residuals) {
      const auto c = static_cast<std::size_t>(std::floor((t - first) / opt_.covariance_cluster_s));
      if (c >= clusters.size()) clusters.resize(c + 1);
      clusters[c].push_back(id);
    }
    std::erase_if(clusters, [](const auto& c) { return c.empty(); });
  }
  const auto start = std::chrono::steady_clock::now();
  auto cov = std::make_unique<MarginalCovariance>();
  const bool ok =
      cov->compute(*problem_, blocks, threads_or_cores(opt_.threads), clusters, held_intrinsics());
  covariance_compute_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!ok) {
    covariance_failed_ = true;
    return nullptr;
  }
  covariance_ = std::move(cov);
  return covariance_.get();
}

template <int N>
bool Estimator<N>::frames_in_window() const {
  for (std::size_t k = 0; k < built_.frames.size(); ++k) {
    const CameraState& cs = st_.cams[built_.frame_camera[k]];
    if (!built_.frames[k]->in_window(cs.shift, cs.rolling ? cs.line_delay : 0.0)) return false;
  }
  return true;
}

template <int N>
bool Estimator<N>::reestimate_corner_sigma() {
  if (opt_.corner_sigma_px > 0) return false;
  std::vector<std::vector<double>> comps(st_.cams.size());
  std::vector<Eigen::Vector2d> e;
  bool changed = false;
  for (std::size_t k = 0; k < built_.frames.size(); ++k) {
    built_.frames[k]->pixel_residuals(built_.frame_blocks[k].data(), &e);
    for (const auto& v : e) {
      comps[built_.frame_camera[k]].push_back(std::abs(v.x()));
      comps[built_.frame_camera[k]].push_back(std::abs(v.y()));
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
bool Estimator<N>::reestimate_imu_noise() {
  if (!opt_.imu_noise_from_residuals || built_.imu_residuals.empty()) return false;
  double sa = 0.0, sg = 0.0;
  Eigen::Matrix<double, 6, 1> r;
  for (std::size_t k = 0; k < built_.imu_residuals.size(); ++k) {
    built_.imu_residuals[k]->Evaluate(built_.imu_blocks[k].data(), r.data(), nullptr);
    sa += (r.head<3>() * quality_.accel_sigma).squaredNorm();
    sg += (r.tail<3>() * quality_.gyro_sigma).squaredNorm();
  }
  const double n = 3.0 * static_cast<double>(built_.imu_residuals.size());
  bool changed = false;
  for (auto [rms, sigma, given, flag] :
       {std::tuple{std::sqrt(sa / n), &quality_.accel_sigma, quality_.accel_sigma_given,
                   &quality_.accel_noise_from_residuals},
        std::tuple{std::sqrt(sg / n), &quality_.gyro_sigma, quality_.gyro_sigma_given,
                   &quality_.gyro_noise_from_residuals}}) {
    // The residuals were whitened with *sigma: it changes only with a rebuild (a new solve).
    const bool disagree = rms > 2.0 * given || rms < 0.5 * given;
    const double next = disagree ? rms : given;
    if (std::abs(next / *sigma - 1.0) <= 0.1) continue;
    changed = true;
    *sigma = next;
    *flag = disagree;
  }
  return changed;
}

template <int N>
double Estimator<N>::wald_statistic(int* k_out) {
  const KrebsImuSigma ps = prior_sigmas();
  std::vector<const double*> blocks;
  std::vector<double> d, prior_info;
  const auto add = [&](const double* b, const Eigen::VectorXd& offset, const Eigen::VectorXd& prior_sigma) {
    if (problem_->IsParameterBlockConstant(b)) return;
    blocks.push_back(b);
    for (Eigen::Index i = 0; i < offset.size(); ++i) {
      d.push_back(offset(i));
      prior_info.push_back(opt_.prior.enabled ? 1.0 / (prior_sigma(i) * prior_sigma(i)) : 0.0);
    }
  };
  add(st_.Sa.data(), vec(st_.Sa) - prior0_.S_a, ps.S_a);
  add(st_.Ma.data(), vec(st_.Ma) - prior0_.M_a, ps.M_a);
  add(st_.Sg.data(), vec(st_.Sg) - prior0_.S_g, ps.S_g);
  add(st_.Mg.data(), vec(st_.Mg) - prior0_.M_g, ps.M_g);
  add(st_.C.data(), so3::log(prior0_.C_bg.transpose() * quat_matrix(st_.C.data())), ps.C_bg);
  add(st_.B.data(), Eigen::Map<const Eigen::Matrix<double, 9, 1>>(st_.B.data()) - row_major(prior0_.B_g),
      row_major(ps.B_g));
  const int k = static_cast<int>(d.size());
  *k_out = k;
  if (k == 0) return std::nan("");
  const MarginalCovariance* cov = solution_covariance();
  if (cov == nullptr) return std::nan("");
  Eigen::MatrixXd C(k, k);
  int row = 0;
  for (const double* a : blocks) {
    int col = 0;
    const int na = problem_->ParameterBlockTangentSize(a);
    for (const double* b : blocks) {
      const int nb = problem_->ParameterBlockTangentSize(b);
      C.block(row, col, na, nb) = cov->block(a, b);
      col += nb;
    }
    row += na;
  }
  const Eigen::Map<const Eigen::VectorXd> dv(d.data(), k);
  // An undetermined coordinate among them (NaN) leaves the test to the likelihood ratio.
  if (!C.allFinite()) return std::nan("");
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(C);
  if (ldlt.info() != Eigen::Success) return std::nan("");
  double W = dv.dot(ldlt.solve(dv));
  for (int i = 0; i < k; ++i) W -= prior_info[static_cast<std::size_t>(i)] * dv(i) * dv(i);
  return W;
}

template <int N>
Status Estimator<N>::choose_model(ceres::Solver::Summary* summary) {
  // The extended model is solved from the first stage. Its intrinsics are then tested against the
  // basic model's values (their start) by the Wald statistic with the data's information alone
  // (the prior's taken out): W = d^T (Cov^-1 - P) d, a chi-square with k degrees of freedom under
  // the basic model; for a linear model it is the drop of the chi-square that freeing them buys.
  // The Bayesian information criterion keeps the extended model when W exceeds k ln(n) (n: IMU
  // residuals): a real scale or misalignment error of an excited axis passes it by orders of
  // magnitude, noise does not. Where the covariance leaves a direction undetermined, both models
  // are solved and their costs compared instead (the likelihood ratio).
  const State<N> first_stage = st_;
  model_ = CamImuModelKind::kExtended;
  if (Status s = solve(true, "extended", summary, kIntermediateTolerance); !s.ok()) return s;
  // Weighted by the noise the best-fitting model's residuals show (the first stage's overstate it).
  // The last stage converges fully whether or not the weights moved.
  for (int round = 0; round < 3; ++round) {
    bool changed = reestimate_corner_sigma();
    changed = reestimate_imu_noise() || changed;
    if (!changed && round > 0) break;
    if (Status s = solve(true, "extended", summary); !s.ok()) return s;
    if (!changed) break;
  }
  int k = 0;
  double W = wald_statistic(&k);
  const double n = static_cast<double>(std::max<std::size_t>(built_.imu_residuals.size(), 2));
  const double threshold = k * std::log(n);
  char text[640];
  if (!std::isfinite(W)) {
    // The likelihood ratio: the basic model solved to convergence from the first stage too.
    const double extended_cost = summary->final_cost - prior_cost();
    const State<N> extended_state = st_;
    st_ = first_stage;
    model_ = CamImuModelKind::kBasic;
    if (Status s = solve(false, "basic", summary); !s.ok()) return s;
    W = 2.0 * (summary->final_cost - extended_cost);
    if (k > 0 && W > threshold) {
      st_ = extended_state;
      model_ = CamImuModelKind::kExtended;
      rebuild(true);
    }
  } else if (!(k > 0 && W > threshold)) {
    st_ = first_stage;
    model_ = CamImuModelKind::kBasic;
    if (Status s = solve(false, "basic", summary); !s.ok()) return s;
  }
  if (model_ == CamImuModelKind::kExtended) {
    std::snprintf(
        text, sizeof text,
        "extended, chosen by the evidence: freeing its %d intrinsics lowers the chi-square by %.1f, "
        "more than the %.1f they cost (BIC: k ln n, n = %.0f IMU residuals)",
        k, W, threshold, n);
  } else {
    std::snprintf(
        text, sizeof text,
        "basic, chosen by the evidence: freeing the extended model's %d intrinsics lowers the "
        "chi-square by only %.1f, less than the %.1f they cost (BIC: k ln n, n = %.0f IMU residuals); "
        "asking for the extended model (%s) estimates them anyway",
        k, W, threshold, n, option_words(CalibOption::kCamImuModel, "extended").c_str());
  }
  model_choice_ = text;
  return {};
}

template <int N>
Status Estimator<N>::solve(bool extended, const std::string& stage, ceres::Solver::Summary* summary,
                           double tolerance) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  // Dogleg: a third to two thirds of Levenberg-Marquardt's iterations on these problems, at the
  // same solution (docs/camimu-calibration.md, "Speed").
  so.trust_region_strategy_type = ceres::DOGLEG;
  so.num_threads = threads_or_cores(opt_.threads);
  // The first stage only brings the trajectory, biases and extrinsics near the solution for the
  // stage that follows it; a few iterations do (docs/camimu-calibration.md, "Speed").
  const bool preliminary = !extended && model_ == CamImuModelKind::kExtended;
  so.max_num_iterations =
      preliminary ? std::min(opt_.max_iterations, kPreliminaryIterations) : opt_.max_iterations;
  so.function_tolerance = tolerance;
  so.parameter_tolerance = 1e-9;
  ProgressCallback cb(progress_, stage);
  so.callbacks.push_back(&cb);
  // A timeshift that moves frames out of the knot window they were built with: the attempt ends
  // there and the problem is built again at the new offset (a final stage only; the last attempt
  // runs to convergence and fails if the offset still moves).
  constexpr int kAttempts = 8;
  bool window_check = !preliminary;
  StopWhen window_left([&] { return window_check && !frames_in_window(); });
  if (!preliminary) {
    so.update_state_every_iteration = true;
    so.callbacks.push_back(&window_left);
  }
  int imu_stride = 1;
  if (preliminary && imu_.size() >= 2) {
    const double rate = 1e9 / static_cast<double>(std::max<TimeNs>(imu_median_interval_ns(imu_), 1));
    const auto by_rate = std::lround(rate / kPreliminaryImuRateHz);
    const auto by_knots = static_cast<long>(std::floor(rate * st_.pose.dt_s / kPreliminaryImuPerKnot));
    imu_stride = static_cast<int>(std::max(1L, std::min(by_rate, by_knots)));
  }
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    window_check = attempt + 1 < kAttempts;
    rebuild(extended, imu_stride);
    ceres::Solve(so, problem_.get(), summary);
    if (!summary->IsSolutionUsable())
      return make_error(Errc::kSolverFailed,
                        "the camera-IMU solve failed (" + stage + "): " + summary->message);
    quality_.iterations += static_cast<int>(summary->iterations.size());
    quality_.jacobian_s += summary->jacobian_evaluation_time_in_seconds;
    quality_.linear_solver_s += summary->linear_solver_time_in_seconds;
    // The next stage builds the problem again at the new offset: the first stage need not.
    if (preliminary || (frames_in_window() && summary->termination_type != ceres::USER_SUCCESS)) return {};
  }
  return make_error(Errc::kSolverFailed, "the time offset did not settle (" + stage + ")");
}

template <int N>
void Estimator<N>::plan_shutters() {
  using Mode = CamImuShutterOptions::Mode;
  using Plan = CameraState::ShutterPlan;
  const CamImuShutterOptions& o = opt_.shutter;
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    CameraState& cs = st_.cams[c];
    const Shutter& file = cameras_[c].camera.shutter;
    cs.rolling = false;
    cs.line_delay_fixed = true;
    cs.line_delay = file.rolling() ? file.line_delay_s : 0.0;
    if (o.line_delay_s) {
      cs.shutter_plan = Plan::kHeld;
      cs.rolling = true;
      cs.line_delay = *o.line_delay_s;
      cs.shutter_choice = line_delay_as_given();
    } else if (o.mode == Mode::kGlobal) {
      cs.shutter_plan = Plan::kGlobal;
      cs.line_delay = 0.0;
      cs.shutter_choice = global_as_requested(file.rolling() ? "the camera file says rolling" : "");
    } else {
      cs.shutter_plan = o.mode == Mode::kRolling ? Plan::kEstimate : Plan::kChoose;
    }
  }
}

template <int N>
Status Estimator<N>::choose_shutter(bool extended, ceres::Solver::Summary* summary) {
  using Plan = CameraState::ShutterPlan;
  std::vector<std::size_t> tested;
  for (std::size_t c = 0; c < st_.cams.size(); ++c) {
    const Plan plan = st_.cams[c].shutter_plan;
    if (plan == Plan::kEstimate || plan == Plan::kChoose) tested.push_back(c);
  }
  if (tested.empty()) return {};
  // The global solution with its weights; its cost against the rolling one at the same weights is
  // the likelihood ratio (the loss is the same Cauchy on both). The cost is evaluated anew: the
  // last re-estimate of the noise may have moved the weights a little without a solve.
  const State<N> global_state = st_;
  const ceres::Solver::Summary global_summary = *summary;
  rebuild(extended);
  double global_cost = 0.0;
  problem_->Evaluate(ceres::Problem::EvaluateOptions(), &global_cost, nullptr, nullptr, nullptr);
  bool choose = false, only_choose = true;
  for (std::size_t c : tested) {
    choose = choose || st_.cams[c].shutter_plan == Plan::kChoose;
    only_choose = only_choose && st_.cams[c].shutter_plan == Plan::kChoose;
  }
  // A choice is tested on the frames that carry the line delay's information; a rolling shutter
  // asked for is solved on every frame from the start.
  const std::string subset = only_choose ? pick_shutter_test_frames(tested) : std::string();
  for (std::size_t c : tested) {
    CameraState& cs = st_.cams[c];
    cs.rolling = true;
    cs.line_delay_fixed = false;
  }
  if (Status s = solve(extended, "rolling shutter", summary); !s.ok()) return s;
  const double lr = 2.0 * (global_cost - summary->final_cost);
  double measurements = 0.0;
  for (std::size_t k = 0; k < built_.frames.size(); ++k)
    if (built_.frames[k]->rolling()) measurements += 2.0 * static_cast<double>(built_.frames[k]->corners());
  const double k = static_cast<double>(tested.size());
  double readout = 0.0;  // the longest of the freed cameras, s
  for (std::size_t c : tested)
    readout = std::max(readout, std::abs(st_.cams[c].line_delay) * (cameras_[c].camera.height - 1));
  const ShutterVerdict verdict = judge_shutter(choose, lr, k, measurements, readout);
  if (!verdict.rolling) {
    st_ = global_state;
    *summary = global_summary;
    for (std::size_t c : tested) st_.cams[c].shutter_choice = verdict.text + subset;
    rebuild(extended);
    return {};
  }
  for (std::size_t c : tested) {
    st_.cams[c].shutter_choice = verdict.text + subset;
    st_.cams[c].rolling_frames.clear();
  }
  // Every frame rolling from the test's solution.
  if (!subset.empty()) {
    rebuild(extended);
    if (Status s = solve(extended, "rolling shutter", summary); !s.ok()) return s;
  }
  // Weighted anew by the corner noise the rolling model leaves (the global one's overstated it).
  for (int round = 0; round < 3 && reestimate_corner_sigma(); ++round)
    if (Status s = solve(extended, "rolling shutter", summary); !s.ok()) return s;
  for (std::size_t c : tested) {
    if (st_.cams[c].line_delay < 0.0)
      warnings_.push_back(
          cameras_[c].name + ": the line delay came out negative (" +
          format_number("%.2f", 1e6 * st_.cams[c].line_delay) +
          " us per row): the rows are read out the other way round than the camera file says; "
          "calibrate again with the other readout (" +
          other_readout_words(cameras_[c].camera.shutter.readout) + ")");
  }
  return {};
}

template <int N>
std::string Estimator<N>::pick_shutter_test_frames(const std::vector<std::size_t>& tested) {
  // A frame's information on the line delay at the global solution: on its time offset (the
  // squared norm of its rows' derivative in it: the compressed rows keep the corners' J^T J) times
  // the spread of its corners' rows (what a line delay adds to a shift of the whole frame).
  std::vector<std::vector<std::pair<double, TimeNs>>> info(st_.cams.size());
  for (std::size_t k = 0; k < built_.frames.size(); ++k) {
    const std::size_t c = built_.frame_camera[k];
    if (std::find(tested.begin(), tested.end(), c) == tested.end()) continue;
    const FrameResidual<N>& f = *built_.frames[k];
    std::vector<double> r(static_cast<std::size_t>(f.num_residuals())), d(r.size());
    std::vector<double*> jac(built_.frame_blocks[k].size(), nullptr);
    jac[FrameResidual<N>::kShift] = d.data();
    if (!f.Evaluate(built_.frame_blocks[k].data(), r.data(), jac.data())) continue;
    double dt2 = 0.0;
    for (double v : d) dt2 += v * v;
    info[c].emplace_back(dt2 * f.row_variance(), built_.frame_t_ns[k]);
  }
  int used = 0, all = 0;
  for (std::size_t c : tested) {
    auto& frames = info[c];
    all += static_cast<int>(frames.size());
    std::sort(frames.begin(), frames.end(), std::greater<>());
    double total = 0.0;
    for (const auto& f : frames) total += f.first;
    std::size_t n = 0;
    for (double sum = 0.0;
         n < frames.size() && (sum < kShutterTestShare * total || n < kShutterTestMinFrames); ++n)
      sum += frames[n].first;
    used += static_cast<int>(n);
    CameraState& cs = st_.cams[c];
    cs.rolling_frames.clear();
    if (n == frames.size()) continue;
    for (std::size_t i = 0; i < n; ++i) cs.rolling_frames.push_back(frames[i].second);
    std::sort(cs.rolling_frames.begin(), cs.rolling_frames.end());
  }
  if (used == all) return {};
  char text[200];
  std::snprintf(text, sizeof text,
                "; tested on the %d of %d frames that hold %.0f %% of the line delay's information", used,
                all, 100.0 * kShutterTestShare);
  return text;
}

template <int N>
void Estimator<N>::warn_rejected_frames() {
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    const auto& rejected = st_.cams[c].rejected;
    if (rejected.empty()) continue;
    std::ostringstream text;
    text << cameras_[c].name << ": " << rejected.size() << (rejected.size() == 1 ? " frame" : " frames")
         << " left out: the target's pose contradicts the gyro (corners detected in the wrong order, "
            "or a mirrored pose of a distant board), at"
         << std::fixed << std::setprecision(3);
    for (std::size_t k = 0; k < std::min<std::size_t>(rejected.size(), 8); ++k)
      text << " " << t_s(rejected[k]);
    if (rejected.size() > 8) text << " ...";
    text << " s";
    warnings_.push_back(text.str());
  }
}

template <int N>
Status Estimator<N>::reweighted_stages(bool automatic, ceres::Solver::Summary* summary) {
  if (automatic) {
    // Both models weighted alike, by the noise the first stage's residuals show.
    reestimate_corner_sigma();
    reestimate_imu_noise();
    if (Status s = choose_model(summary); !s.ok()) return s;
  }
  const bool extended = model_ == CamImuModelKind::kExtended;
  // The next stage weighs the corners by the noise they showed in the one before, and the IMU by
  // its residuals where they disagree with the given noise. The first stage stops early with the
  // IMU intrinsics at their start, so its residuals overstate the noise: the final stage is
  // repeated until the estimates hold (within 10 %).
  // A stage followed by new weights stops at kIntermediateTolerance; the last one runs to
  // kFinalTolerance (continuing from the one before when the weights held).
  bool converged = automatic;  // the last solve ran to kFinalTolerance
  for (int round = automatic ? 1 : 0; round < 4; ++round) {
    bool changed = reestimate_corner_sigma();
    if (round > 0 || !extended) changed = reestimate_imu_noise() || changed;
    const bool may_stop = round > 0 || (!extended && opt_.corner_sigma_px > 0);
    if (may_stop && !changed && converged) break;
    const bool last = round == 3 || (may_stop && !changed);
    if (Status s = solve(extended, extended ? "extended" : "basic", summary,
                         last ? kFinalTolerance : kIntermediateTolerance);
        !s.ok())
      return s;
    converged = last;
    if (last) break;
  }
  return {};
}

template <int N>
Result<CamImuCalibrationResult> Estimator<N>::run() {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = initialise(); !s.ok()) return s.error();
  warn_rejected_frames();
  const auto init_done = std::chrono::steady_clock::now();
  quality_.init_s = std::chrono::duration<double>(init_done - start).count();
  ceres::Solver::Summary summary;
  // First with the IMU intrinsics at their initial values (the trajectory, biases, gravity and
  // extrinsics settle), then everything the model estimates.
  const CamImuFixed& f = opt_.fixed;
  const bool all_fixed = f.S_a && f.M_a && f.S_g && f.M_g && f.C_bg && f.B_g;
  const bool automatic = model_ == CamImuModelKind::kAuto && !all_fixed;
  if (model_ == CamImuModelKind::kAuto) model_ = CamImuModelKind::kExtended;  // the first stage stops early
  if (all_fixed && opt_.model == CamImuModelKind::kAuto)
    model_choice_ = "extended with every intrinsic held at its given value (" +
                    option_words(CalibOption::kImuIntrinsics) + ", " + option_words(CalibOption::kGsens) +
                    " or " + option_words(CalibOption::kFix) + "): nothing to choose";
  // The first stage is preliminary unless the basic model was asked for (then it is that model's).
  // A preliminary stage runs on fewer IMU samples: the cost at the start is that of all of them.
  const bool preliminary = model_ == CamImuModelKind::kExtended;
  double start_cost = 0.0;
  if (preliminary) {
    rebuild(false);
    problem_->Evaluate(ceres::Problem::EvaluateOptions(), &start_cost, nullptr, nullptr, nullptr);
  }
  // The weights are estimated again after it, so it need not converge fully either.
  if (Status s =
          solve(false, "basic", &summary, preliminary ? kPreliminaryTolerance : kIntermediateTolerance);
      !s.ok())
    return s.error();
  quality_.initial_cost = preliminary ? start_cost : summary.initial_cost;
  std::vector<ImuSignalFit> fits;
  fits.push_back(signal_fit("basic"));
  if (!automatic && model_choice_.empty())
    model_choice_ = std::string(camimu_model_name(model_)) + ", as requested (" +
                    option_words(CalibOption::kCamImuModel, camimu_model_name(model_)) + ")";
  if (Status s = reweighted_stages(automatic, &summary); !s.ok()) return s.error();
  const bool extended = model_ == CamImuModelKind::kExtended;
  if (Status s = choose_shutter(extended, &summary); !s.ok()) return s.error();
  if (!extended) fits.clear();
  quality_.final_cost = summary.final_cost;
  // A covariance the model choice computed at this solution is counted as the covariance's.
  quality_.solve_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - init_done).count() -
                     (covariance_ || covariance_failed_ ? covariance_compute_s_ : 0.0);
  quality_.parameters = problem_->NumParameters();
  // Counted as measurements: two per corner, not the compressed rows the solver sees.
  quality_.residuals = problem_->NumResiduals();
  for (const auto* f : built_.frames)
    quality_.residuals += 2 * static_cast<int>(f->corners()) - f->num_residuals();
  quality_.spline_knots = st_.pose.knots;
  fits.push_back(signal_fit(extended ? "extended" : "basic"));
  quality_.accel_residual_rms = fits.back().accel_residual_rms;  // per axis, SI
  quality_.gyro_residual_rms = fits.back().gyro_residual_rms;
  CamImuCalibrationResult out;
  out.signal_fits = std::move(fits);
  out.model_choice = model_choice_;
  fill_result(&out);
  excitation(imu_, out.imu.b_g, &quality_, &warnings_);
  if (opt_.covariance) {
    covariance(&out);
    check_against_prior(&out);
  }
  for (const auto& cs : st_.cams) {
    quality_.xcorr.push_back(cs.xcorr.curve);
    quality_.xcorr_peak_s.push_back(cs.xcorr.shift_s);
  }
  for (auto [rms, given, used, from_residuals, what] :
       {std::tuple{quality_.accel_residual_rms.norm() / std::sqrt(3.0), quality_.accel_sigma_given,
                   quality_.accel_sigma, quality_.accel_noise_from_residuals, "accelerometer"},
        std::tuple{quality_.gyro_residual_rms.norm() / std::sqrt(3.0), quality_.gyro_sigma_given,
                   quality_.gyro_sigma, quality_.gyro_noise_from_residuals, "gyroscope"}}) {
    char text[640];
    if (from_residuals) {
      std::snprintf(
          text, sizeof text,
          "the %s residuals (RMS %.4g per sample) are %.1f times the noise the given figures imply "
          "(%.4g): the problem was weighted with the residuals' own RMS instead, so that the sigmas "
          "account for it (the given figures are kept with %s)",
          what, rms, rms / given, given, option_words(CalibOption::kKeepNoise).c_str());
      warnings_.emplace_back(text);
    } else if (rms > 3.0 * used || rms < used / 3.0) {
      std::snprintf(
          text, sizeof text,
          "the %s residuals (RMS %.4g per sample) are %.1f times the assumed noise (%.4g): the noise "
          "figures (imu.yaml) or the model do not fit this IMU, and the sigmas are %s",
          what, rms, rms / used, used, rms > used ? "too small" : "too large");
      warnings_.emplace_back(text);
    }
  }
  out.quality = quality_;
  out.warnings = warnings_;
  return out;
}

// Every member defined here, for the spline orders calibrate_camimu() runs: camimu_result.cpp
// calls some of them, and an instantiation that the optimiser inlined everywhere here would
// otherwise leave it without a definition.
template class Estimator<4>;
template class Estimator<5>;
template class Estimator<6>;

}  // namespace camimu

using camimu::Estimator;

Result<CamImuCalibrationResult> calibrate_camimu(const std::vector<CamImuSample>& imu,
                                                 const std::vector<CamImuCameraInput>& cameras,
                                                 const TargetDescription& target,
                                                 const CamImuOptions& options,
                                                 const CamImuProgressFn& progress) {
  if (Status s = options.validate(); !s.ok()) return s.error();
  if (cameras.empty()) return make_error(Errc::kInvalidArgument, "no camera to calibrate against the IMU");
  for (const CamImuChainPrior& cp : options.chain_priors) {
    if (static_cast<std::size_t>(cp.camera) >= cameras.size())
      return make_error(Errc::kInvalidArgument, "a camera chain prior names camera " +
                                                    std::to_string(cp.camera) + ", but " +
                                                    std::to_string(cameras.size()) + " are given");
  }
  // Every id indexes the target's points (the initialisation's PnP, the residuals): a detection
  // read from a file is checked before any of them is used.
  const int target_points = target.point_count();
  for (const CamImuCameraInput& cam : cameras) {
    for (const TargetObservation& o : cam.observations) {
      if (Status s = check_observation(o, target_points); !s.ok()) {
        return make_error(Errc::kInvalidArgument, cam.name + ": " + s.error().message);
      }
    }
  }
  int k = 1;
  const std::vector<CamImuSample> averaged = average_imu(imu, options.imu_max_rate_hz, &k);
  CamImuOptions opt = options;
  std::vector<double> fit_sigma;
  if (opt.knot_spacing_s == 0.0 && averaged.size() >= 2) {
    const double rate = 1e9 / static_cast<double>(std::max<TimeNs>(imu_median_interval_ns(averaged), 1));
    opt.knot_spacing_s = choose_knot_spacing(averaged, opt.spline_order,
                                             opt.noise.gyro_noise_density * std::sqrt(rate), &fit_sigma);
  }
  Result<CamImuCalibrationResult> out = [&]() -> Result<CamImuCalibrationResult> {
    switch (options.spline_order) {
      case 4:
        return Estimator<4>(averaged, cameras, target, opt, progress).run();
      case 5:
        return Estimator<5>(averaged, cameras, target, opt, progress).run();
      default:
        return Estimator<6>(averaged, cameras, target, opt, progress).run();
    }
  }();
  if (out.ok()) {
    out->quality.knot_spacing_s = opt.knot_spacing_s;
    out->quality.knot_spacing_chosen = options.knot_spacing_s == 0.0;
    out->quality.gyro_fit_sigma_radps = fit_sigma;
    out->quality.imu_samples_per_residual = k;
    out->quality.imu_residuals = static_cast<int>(averaged.size());
  }
  return out;
}

}  // namespace imucal::calib
