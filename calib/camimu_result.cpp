// SPDX-License-Identifier: BSD-3-Clause
// What the camera-IMU estimator reports from a solution (calib/camimu_estimator.hpp): the
// covariance and the directions the data leave undetermined, the result, the checks against the
// prior, the measured and predicted signals, and the motion's excitation.

#include <algorithm>
#include <cmath>
#include <functional>
#include <iomanip>
#include <sstream>

#include "calib/camimu_estimator.hpp"
#include "core/option_words.hpp"

namespace imucal::calib::camimu {

template <int N>
std::string Estimator<N>::coordinate_name(const double* b, int i) const {
  static const char* xyz[3] = {"x", "y", "z"};
  static const char* m_entries[3] = {"yz", "zy", "zx"};  // Krebs' names of M(1,0), M(2,0), M(2,1)
  const std::string ax = xyz[std::clamp(i, 0, 2)];
  if (b == st_.Sa.data()) return "accelerometer " + ax + " scale (S_a)";
  if (b == st_.Sg.data()) return "gyroscope " + ax + " scale (S_g)";
  if (b == st_.Ma.data())
    return std::string("accelerometer misalignment M_a ") + m_entries[std::clamp(i, 0, 2)];
  if (b == st_.Mg.data()) return std::string("gyroscope misalignment M_g ") + m_entries[std::clamp(i, 0, 2)];
  if (b == st_.C.data()) return "gyroscope-accelerometer rotation C_bg about " + ax;
  if (b == st_.B.data())
    return std::string("g-sensitivity B_g ") + xyz[std::clamp(i / 3, 0, 2)] + xyz[std::clamp(i % 3, 0, 2)];
  if (b == st_.g.data()) return "gravity direction";
  for (std::size_t c = 0; c < st_.cams.size(); ++c) {
    const CameraState& cs = st_.cams[c];
    const std::string name = cameras_[c].name;
    if (b == cs.q_ci.data()) return name + " rotation about the IMU " + ax + " axis";
    if (b == cs.t_ci.data()) return name + " translation " + ax + " (camera frame)";
    if (b == &cs.shift) return name + " time offset";
    if (b == &cs.line_delay) return name + " line delay";
  }
  for (const auto* knots : {&st_.ba, &st_.bg})
    for (const auto& k : *knots)
      if (b == k.data()) return std::string(knots == &st_.ba ? "accelerometer" : "gyroscope") + " bias " + ax;
  return "a parameter";
}

template <int N>
std::string Estimator<N>::describe(const MarginalCovariance::Direction& dir) const {
  if (dir.parts.empty()) return "the trajectory itself: nothing about the calibration can be said";
  std::vector<std::string> names;
  for (const auto& [coord, weight] : dir.parts) {
    std::string n = coordinate_name(coord.block, coord.index);
    if (std::find(names.begin(), names.end(), n) == names.end()) names.push_back(std::move(n));
    if (names.size() == 4) break;
  }
  std::string text;
  for (std::size_t i = 0; i < names.size(); ++i)
    text += (i == 0 ? "" : (i + 1 == names.size() ? " and " : ", ")) + names[i];
  if (dir.parts.size() > names.size()) text += " (and others)";
  // The likely cause: an axis the rig hardly moved along or about.
  std::string why;
  const char* xyz[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (quality_.accel_excitation_mps2(a) < 0.5)
      why += std::string(why.empty() ? "" : "; ") + "the rig barely accelerated along IMU " + xyz[a] +
             " (RMS " + std::to_string(quality_.accel_excitation_mps2(a)).substr(0, 5) + " m/s^2)";
    if (quality_.rotation_excitation_radps(a) < 0.1)
      why += std::string(why.empty() ? "" : "; ") + "the rig barely rotated about IMU " + xyz[a] + " (RMS " +
             std::to_string(quality_.rotation_excitation_radps(a)).substr(0, 5) + " rad/s)";
  }
  return text + ": " + (why.empty() ? "the recording does not tell them apart" : why);
}

template <int N>
std::vector<MarginalCovariance::HeldScore> Estimator<N>::held_intrinsics() const {
  std::vector<MarginalCovariance::HeldScore> out;
  if (!opt_.propagate_intrinsics) return out;
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    const CameraModel& camera = cameras_[c].camera;
    // +-1 sigma along each direction: the projection is linear over it to far below the noise.
    std::vector<std::pair<CameraModel, CameraModel>> moves;
    for (const Eigen::VectorXd& l : intrinsics_directions(cameras_[c].intrinsics_covariance)) {
      CameraModel plus = camera, minus = camera;
      plus.intrinsics += l.head<4>();
      minus.intrinsics -= l.head<4>();
      plus.projection_params += l.segment<2>(4);
      minus.projection_params -= l.segment<2>(4);
      plus.distortion_coeffs += l.tail<4>();
      minus.distortion_coeffs -= l.tail<4>();
      moves.emplace_back(plus, minus);
    }
    if (moves.empty()) continue;
    std::vector<MarginalCovariance::HeldScore> scores(moves.size());
    for (std::size_t k = 0; k < built_.frames.size(); ++k) {
      if (built_.frame_camera[k] != c) continue;
      const auto per_move = built_.frames[k]->intrinsics_scores(built_.frame_blocks[k].data(), moves, 0.5);
      for (std::size_t j = 0; j < moves.size(); ++j)
        for (std::size_t b = 0; b < per_move[j].size(); ++b)
          scores[j].emplace_back(built_.frame_blocks[k][b], per_move[j][b]);
    }
    for (auto& s : scores) out.push_back(std::move(s));
  }
  return out;
}

std::vector<Eigen::VectorXd> intrinsics_directions(const Eigen::MatrixXd& covariance) {
  std::vector<Eigen::VectorXd> out;
  if (covariance.rows() != 10 || covariance.cols() != 10) return out;
  // Coordinates the camera's own solve did not determine (NaN) are left out.
  Eigen::MatrixXd C = covariance;
  for (int i = 0; i < 10; ++i)
    if (!std::isfinite(C(i, i))) {
      C.row(i).setZero();
      C.col(i).setZero();
    }
  if (!C.allFinite()) return out;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (C + C.transpose()));
  // The rows the model does not use are 0: their eigenvalues, 0 to rounding, are no direction.
  const double floor = 1e-12 * es.eigenvalues().cwiseAbs().maxCoeff();
  for (int j = 0; j < 10; ++j)
    if (es.eigenvalues()(j) > floor) out.push_back(es.eigenvectors().col(j) * std::sqrt(es.eigenvalues()(j)));
  return out;
}

namespace {

std::string intrinsics_uncertainty(const CamImuCameraInput& in, bool propagate) {
  if (!propagate) return "not propagated (held as given)";
  if (intrinsics_directions(in.intrinsics_covariance).empty())
    return "not known: " +
           (in.intrinsics_covariance_source.empty()
                ? std::string("the camera file gives no covariance of them")
                : in.intrinsics_covariance_source) +
           "; the sigmas here leave the intrinsics' own error out";
  return "propagated: " + (in.intrinsics_covariance_source.empty() ? std::string("the camera's covariance")
                                                                   : in.intrinsics_covariance_source);
}

/// The directions the covariance leaves undetermined, in words (out->undetermined), and the
/// warnings they and a regularised nuisance deserve.
void note_undetermined(const MarginalCovariance& cov,
                       const std::function<std::string(const MarginalCovariance::Direction&)>& describe,
                       CamImuCalibrationResult* out, std::vector<std::string>* warnings) {
  if (cov.nuisance_regularised())
    warnings->push_back(
        "parts of the trajectory or the bias splines are not determined by the data (no frame or IMU "
        "sample constrains them); the sigmas are conditioned on a weak prior there");
  for (const auto& dir : cov.undetermined()) out->undetermined.push_back(describe(dir));
  if (!out->undetermined.empty()) {
    std::string text = "the recording does not determine every parameter; not determined (sigma NaN): ";
    for (std::size_t i = 0; i < out->undetermined.size(); ++i)
      text += (i ? " | " : "") + out->undetermined[i];
    warnings->push_back(text);
  }
}

}  // namespace

template <int N>
void Estimator<N>::covariance(CamImuCalibrationResult* out) {
  // The computation is counted once, where it ran (often during the model choice).
  const auto start = std::chrono::steady_clock::now();
  const bool reused = covariance_ != nullptr || covariance_failed_;
  const MarginalCovariance* computed = solution_covariance();
  if (computed == nullptr) {
    out->undetermined.push_back("every parameter: the problem could not be evaluated at the solution");
    warnings_.push_back("the covariance could not be computed: every sigma is not determined");
    return;
  }
  const MarginalCovariance& cov = *computed;
  note_undetermined(
      cov, [this](const MarginalCovariance::Direction& d) { return describe(d); }, out, &warnings_);
  // Every sigma is the larger of the plain one and the cluster-robust one (where computed): the
  // robust estimate is itself noisy with few clusters, and the plain one holds where the
  // residuals are independent and correctly weighted (docs/camimu-calibration.md, "Uncertainty").
  using BlockFn = std::function<Eigen::MatrixXd(const double*, const double*)>;
  // Both carry the held intrinsics' share (zero where none was propagated).
  const BlockFn plain = [&](const double* a, const double* b) {
    return Eigen::MatrixXd(cov.block(a, b) + cov.held_block(a, b));
  };
  const BlockFn robust = [&](const double* a, const double* b) {
    return Eigen::MatrixXd(cov.robust_block(a, b) + cov.held_block(a, b));
  };
  const auto larger = [&](const std::function<Eigen::MatrixXd(const BlockFn&)>& of) -> Eigen::VectorXd {
    Eigen::VectorXd s = sigma_of(of(plain));
    if (!cov.has_robust()) return s;
    const Eigen::VectorXd r = sigma_of(of(robust));
    for (Eigen::Index i = 0; i < s.size(); ++i)
      if (std::isfinite(s(i)) && std::isfinite(r(i))) s(i) = std::max(s(i), r(i));
    return s;
  };
  const auto sigma3 = [&](const double* b) -> Eigen::Vector3d {
    return cov.has(b) ? Eigen::Vector3d(larger([&](const BlockFn& f) { return f(b, b); }).head(3))
                      : Eigen::Vector3d::Constant(kNotDetermined);
  };
  KrebsImuSigma& s = out->imu_sigma;
  s.S_a = sigma3(st_.Sa.data());
  s.M_a = sigma3(st_.Ma.data());
  s.S_g = sigma3(st_.Sg.data());
  s.M_g = sigma3(st_.Mg.data());
  s.C_bg = sigma3(st_.C.data());
  if (cov.has(st_.B.data())) {
    const Eigen::VectorXd d = larger([&](const BlockFn& f) { return f(st_.B.data(), st_.B.data()); });
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) s.B_g(r, c) = d(3 * r + c);
  }
  if (cov.has(st_.g.data()))
    out->gravity_sigma_rad =
        Eigen::Vector2d(larger([&](const BlockFn& f) { return f(st_.g.data(), st_.g.data()); }).head(2)) /
        opt_.gravity_mps2;
  // The biases at the start: b(t0) = sum_i w_i knot_i.
  const auto w = RdSpline<N>::weights_at(st_.bias.segment(st_.bias.t0_s).u, 0, st_.bias.dt_s);
  for (auto [knots, sig] : {std::pair{&st_.ba, &s.b_a}, std::pair{&st_.bg, &s.b_g}}) {
    bool all = true;
    for (int i = 0; i < N; ++i) all = all && cov.has((*knots)[static_cast<std::size_t>(i)].data());
    if (!all) continue;
    *sig = larger([&](const BlockFn& f) -> Eigen::MatrixXd {
      Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
      for (int i = 0; i < N; ++i)
        for (int j = i; j < N; ++j) {
          const Eigen::Matrix3d Cij =
              f((*knots)[static_cast<std::size_t>(i)].data(), (*knots)[static_cast<std::size_t>(j)].data());
          C += w(i) * w(j) * (i == j ? Cij : Eigen::Matrix3d(Cij + Cij.transpose()));
        }
      return C;
    });
  }
  for (std::size_t c = 0; c < st_.cams.size(); ++c) {
    CamImuCameraResult& cr = out->cameras[c];
    const CameraState& cs = st_.cams[c];
    if (cov.has(cs.q_ci.data())) {
      // Right perturbation -> about the camera axes: R Exp(d) = Exp(R d) R.
      const Eigen::Matrix3d R = quat_matrix(cs.q_ci.data());
      cr.rotation_sigma_rad = larger([&](const BlockFn& f) -> Eigen::MatrixXd {
        const Eigen::Matrix3d C = f(cs.q_ci.data(), cs.q_ci.data());
        return C.allFinite() ? Eigen::Matrix3d(R * C * R.transpose())
                             : Eigen::Matrix3d::Constant(kNotDetermined);
      });
      cr.translation_sigma_m = sigma3(cs.t_ci.data());
      if (cov.has_held()) {
        const Eigen::Matrix3d C = cov.held_block(cs.q_ci.data(), cs.q_ci.data());
        cr.rotation_sigma_from_intrinsics_rad = sigma_of(R * C * R.transpose());
        cr.translation_sigma_from_intrinsics_m = sigma_of(cov.held_block(cs.t_ci.data(), cs.t_ci.data()));
      }
    }
    cr.intrinsics_uncertainty = intrinsics_uncertainty(cameras_[c], opt_.propagate_intrinsics);
    if (cov.has(&cs.shift))
      cr.timeshift_sigma_s = larger([&](const BlockFn& f) { return f(&cs.shift, &cs.shift); })(0);
    if (cs.rolling && cov.has(&cs.line_delay))
      cr.line_delay_sigma_s = larger([&](const BlockFn& f) { return f(&cs.line_delay, &cs.line_delay); })(0);
  }
  quality_.covariance_clusters = cov.has_robust() ? cov.clusters() : 0;
  quality_.covariance_cluster_s = cov.has_robust() ? opt_.covariance_cluster_s : 0.0;
  quality_.covariance_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() +
                          (reused ? covariance_compute_s_ : 0.0);
}

template <int N>
void Estimator<N>::check_against_prior(CamImuCalibrationResult* out) {
  if (built_.priors.empty()) return;
  const CamImuIntrinsicsPrior& pr = opt_.prior;
  out->prior_source = pr.source;
  KrebsImuSigma& ps = out->prior_sigma;  // NaN where a block has no prior (held fixed)
  const KrebsImuSigma all = prior_sigmas();
  const KrebsImuModel& m = out->imu;
  const KrebsImuSigma& s = out->imu_sigma;
  const auto is_free = [&](const double* b) { return !problem_->IsParameterBlockConstant(b); };
  if (is_free(st_.Sa.data())) ps.S_a = all.S_a;
  if (is_free(st_.Sg.data())) ps.S_g = all.S_g;
  if (is_free(st_.Ma.data())) ps.M_a = all.M_a;
  if (is_free(st_.Mg.data())) ps.M_g = all.M_g;
  if (is_free(st_.C.data())) ps.C_bg = all.C_bg;
  if (is_free(st_.B.data())) ps.B_g = all.B_g;
  const Eigen::Vector3d dC = so3::log(prior0_.C_bg.transpose() * m.C_bg);
  struct Entry {
    const char* name;
    Eigen::VectorXd value, centre, prior_sigma, sigma;
    double bound;  // physical bound on |value - centre|
  };
  const Entry entries[] = {
      {"S_a", m.S_a, prior0_.S_a, ps.S_a, s.S_a, 0.1},
      {"S_g", m.S_g, prior0_.S_g, ps.S_g, s.S_g, 0.1},
      {"M_a", m.M_a, prior0_.M_a, ps.M_a, s.M_a, 0.1},
      {"M_g", m.M_g, prior0_.M_g, ps.M_g, s.M_g, 0.1},
      {"C_bg", dC, Eigen::Vector3d::Zero(), ps.C_bg, s.C_bg, 0.1},
      {"B_g", row_major(m.B_g), row_major(prior0_.B_g), row_major(ps.B_g), row_major(s.B_g), 2e-3},
  };
  const char* xyz[3] = {"x", "y", "z"};
  for (const Entry& e : entries) {
    for (Eigen::Index i = 0; i < e.value.size(); ++i) {
      if (!std::isfinite(e.prior_sigma(i))) continue;
      const bool misalignment = e.name[0] == 'M';
      const char* m_names[3] = {"yz", "zy", "zx"};  // Krebs' names of M(1,0), M(2,0), M(2,1)
      const std::string label = std::string(e.name) + " " +
                                (e.value.size() == 9 ? std::string(xyz[i / 3]) + xyz[i % 3]
                                                     : std::string(misalignment ? m_names[i] : xyz[i]));
      const double off = e.value(i) - e.centre(i);
      const double n = std::abs(off) / e.prior_sigma(i);
      if (n > 3.0 || std::abs(off) > e.bound) {
        char text[640];
        std::snprintf(
            text, sizeof text,
            "%s = %.6g is %.1f prior sigmas from its prior %.6g +- %.3g (%s)%s: check the IMU's units "
            "and noise figures, or give a static calibration (%s)",
            label.c_str(), e.value(i), n, e.centre(i), e.prior_sigma(i), pr.source.c_str(),
            std::abs(off) > e.bound ? ", beyond what a working sensor shows" : "",
            option_words(CalibOption::kImuIntrinsics).c_str());
        warnings_.emplace_back(text);
      }
      if (!(e.sigma(i) < 0.5 * e.prior_sigma(i))) out->prior_dominated.push_back(label);
    }
  }
  if (!out->prior_dominated.empty()) {
    std::string text = "set mostly by the prior (" + pr.source + "; the recording hardly determines them):";
    for (const auto& n : out->prior_dominated) text += " " + n;
    warnings_.push_back(text);
  }
}

template <int N>
void Estimator<N>::fill_result(CamImuCalibrationResult* out) {
  out->model = model_;
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
  const bool basic = model_ == CamImuModelKind::kBasic;
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
    cr.camera.shutter.kind = st_.cams[c].rolling ? Shutter::Kind::kRolling : Shutter::Kind::kGlobal;
    cr.camera.shutter.line_delay_s = st_.cams[c].rolling ? st_.cams[c].line_delay : 0.0;
    cr.shutter_choice = st_.cams[c].shutter_choice;
    cr.corner_sigma_px = st_.cams[c].sigma_px;
    cr.rejected_frames = st_.cams[c].rejected;
  }
  std::vector<Eigen::Vector2d> e;
  std::vector<std::vector<Eigen::Vector2f>> all(cameras_.size());
  for (std::size_t k = 0; k < built_.frames.size(); ++k) {
    CamImuCameraResult& cr = out->cameras[built_.frame_camera[k]];
    const double outlier_px = opt_.reprojection_loss_sigmas * st_.cams[built_.frame_camera[k]].sigma_px;
    cr.outlier_px = outlier_px;
    built_.frames[k]->pixel_residuals(built_.frame_blocks[k].data(), &e);
    cr.frames += 1;
    for (const auto& v : e) {
      cr.corners += 1;
      sq[built_.frame_camera[k]] += v.squaredNorm();
      if (v.norm() > outlier_px) cr.outlier_corners += 1;
      all[built_.frame_camera[k]].push_back(v.cast<float>());
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
  const std::size_t n = built_.imu_residuals.size(), cap = ImuSignalFit::kMaxSamples;
  const std::size_t step = std::max<std::size_t>(1, (n + cap - 1) / cap);
  Eigen::Vector3d sa = Eigen::Vector3d::Zero(), sg = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    Eigen::Matrix<double, 6, 1> r;
    built_.imu_residuals[k]->Evaluate(built_.imu_blocks[k].data(), r.data(), nullptr);
    // r = (predicted - measured) / sigma.
    const Eigen::Vector3d da = r.head<3>() * quality_.accel_sigma, dg = r.tail<3>() * quality_.gyro_sigma;
    sa += da.cwiseAbs2();
    sg += dg.cwiseAbs2();
    if (k % step != 0) continue;
    const CamImuSample& s = imu_[built_.imu_index[k]];
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

// The members above, for the spline orders calibrate_camimu() runs (the others are instantiated
// where they are defined, by its use of Estimator<N>::run()).
#define IMUCAL_CAMIMU_RESULT_MEMBERS(N)                                                      \
  template std::string Estimator<N>::coordinate_name(const double*, int) const;              \
  template std::string Estimator<N>::describe(const MarginalCovariance::Direction&) const;   \
  template void Estimator<N>::covariance(CamImuCalibrationResult*);                          \
  template std::vector<MarginalCovariance::HeldScore> Estimator<N>::held_intrinsics() const; \
  template void Estimator<N>::check_against_prior(CamImuCalibrationResult*);                 \
  template void Estimator<N>::fill_result(CamImuCalibrationResult*);                         \
  template ImuSignalFit Estimator<N>::signal_fit(const std::string&) const;
IMUCAL_CAMIMU_RESULT_MEMBERS(4)
IMUCAL_CAMIMU_RESULT_MEMBERS(5)
IMUCAL_CAMIMU_RESULT_MEMBERS(6)
#undef IMUCAL_CAMIMU_RESULT_MEMBERS

}  // namespace imucal::calib::camimu
