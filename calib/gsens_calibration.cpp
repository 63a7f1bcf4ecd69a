// SPDX-License-Identifier: BSD-3-Clause
// The six-orientation g-sensitivity experiment (calib/gsens_calibration.hpp).

#include "calib/gsens_calibration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "calib/allan.hpp"
#include "calib/gravity.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_scan.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {
namespace {

double rad_to_deg(double rad) { return rad * 180.0 / M_PI; }

/// A hold as samples [begin, end) of the recording, with what the fit reads from it.
struct Hold {
  std::size_t begin = 0, end = 0;
  double t0_s = 0.0, t1_s = 0.0;  // span covered: first sample to one period after the last
  Eigen::Vector3d accel_raw = Eigen::Vector3d::Zero(), gyro_raw = Eigen::Vector3d::Zero();
  Eigen::Vector3d a = Eigen::Vector3d::Zero();  // calibrated accelerometer mean, m/s^2
  double tilt_rad = 0.0;
  int face = -1;  // 2 * axis + (negative ? 1 : 0), -1 when tilted from every face
  double face_angle_rad = 0.0;
  double length_s() const { return t1_s - t0_s; }
};

const char* kFaceNames[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};

Eigen::Vector3d mean_of(const std::vector<Eigen::Vector3d>& v, std::size_t begin, std::size_t end) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (std::size_t i = begin; i < end; ++i) sum += v[i] - v[begin];
  return sum / static_cast<double>(end - begin) + v[begin];
}

/// The hold's means, its face and the tilt between its first and last window of samples.
Hold describe_hold(std::size_t begin, std::size_t end, const ScannedRecording& scan, std::size_t window,
                   const GSensitivityOptions& opt) {
  Hold h;
  h.begin = begin;
  h.end = end;
  h.t0_s = scan.t_s[begin];
  h.t1_s = scan.t_s[end - 1] + scan.period_s;
  h.accel_raw = mean_of(scan.accel, begin, end);
  h.gyro_raw = mean_of(scan.gyro, begin, end);
  h.a = opt.A_a * (h.accel_raw - opt.b_a);
  const std::size_t w = std::min(window, (end - begin) / 2);
  const Eigen::Vector3d first = opt.A_a * (mean_of(scan.accel, begin, begin + w) - opt.b_a);
  const Eigen::Vector3d last = opt.A_a * (mean_of(scan.accel, end - w, end) - opt.b_a);
  h.tilt_rad = std::acos(std::clamp(first.normalized().dot(last.normalized()), -1.0, 1.0));
  Eigen::Index axis = 0;
  h.a.cwiseAbs().maxCoeff(&axis);
  h.face_angle_rad = std::acos(std::clamp(std::abs(h.a[axis]) / h.a.norm(), -1.0, 1.0));
  if (h.face_angle_rad <= opt.max_face_angle_deg * M_PI / 180.0) {
    h.face = 2 * static_cast<int>(axis) + (h.a[axis] < 0.0 ? 1 : 0);
  }
  return h;
}

/// Still holds: runs where the accelerometer's and the gyro's variance (eq. 3.9) stay within the
/// still-start ratio of their quietest level (StaticDetection::kStillRatio), never crossing a gap
/// or an invalid sample, trimmed by one detector window at each end (the window centred on a
/// sample near a move sees the move late; the gyro mean of a 30 s hold must not hold a tenth of a
/// second of a 1 rad/s turn), at least min_hold_s long.
std::vector<Hold> find_holds(const ScannedRecording& scan, const GSensitivityOptions& opt,
                             std::vector<std::string>* warnings) {
  const StaticDetection det = detect_variance(scan, opt.window_s);
  std::vector<bool> usable(scan.accel.size());
  for (std::size_t i = 0; i < usable.size(); ++i) {
    usable[i] = scan.accel_ok[i] && scan.gyro_ok[i] &&
                det.gyro_sigma_sq[i] < StaticDetection::kStillRatio * det.gyro_floor_sq;
  }
  const auto runs = detect_static_intervals(det.sigma_sq, StaticDetection::kStillRatio * det.floor_sq, usable,
                                            scan.break_before, 2 * det.window + 2);
  const auto min_samples = static_cast<std::size_t>(std::ceil(opt.min_hold_s * scan.rate_hz));
  std::vector<Hold> holds;
  int short_runs = 0;
  double longest_short_s = 0.0;
  for (const auto& run : runs) {
    const std::size_t begin = run.begin + det.window, end = run.end - det.window;
    if (end - begin < min_samples) {
      const double s = static_cast<double>(end - begin) * scan.period_s;
      if (s >= 2.0) {
        ++short_runs;
        longest_short_s = std::max(longest_short_s, s);
      }
      continue;
    }
    holds.push_back(describe_hold(begin, end, scan, det.window, opt));
  }
  if (short_runs > 0) {
    warnings->push_back(std::to_string(short_runs) + " still period(s) shorter than " +
                        format_number("%.0f", opt.min_hold_s) + " s (after trimming " +
                        format_number("%.1f", opt.window_s) + " s at each end; the longest " +
                        format_number("%.1f", longest_short_s) +
                        " s) were not used: hold each face still for about 30 s");
  }
  return holds;
}

/// Refuses unless every face has a hold; the message names the missing faces and what was found.
Status check_faces(const std::vector<Hold>& holds, const GSensitivityOptions& opt) {
  std::vector<double> seconds(6, 0.0);
  int tilted = 0;
  for (const auto& h : holds) {
    if (h.face < 0) {
      ++tilted;
    } else {
      seconds[static_cast<std::size_t>(h.face)] += h.length_s();
    }
  }
  std::string missing, found;
  for (std::size_t f = 0; f < 6; ++f) {
    if (seconds[f] == 0.0) {
      missing += std::string(missing.empty() ? "" : ", ") + kFaceNames[f];
    } else {
      found += std::string(found.empty() ? "" : ", ") + kFaceNames[f] + " " +
               format_number("%.0f", seconds[f]) + " s";
    }
  }
  if (missing.empty()) return {};
  return make_error(
      Errc::kInsufficientData,
      "the six-orientation experiment needs a still hold of at least " +
          format_number("%.0f", opt.min_hold_s) + " s with each face up; none was found with " + missing +
          " up (found: " + (found.empty() ? "none" : found) +
          (tilted > 0 ? "; " + std::to_string(tilted) + " hold(s) more than " +
                            format_number("%.0f", opt.max_face_angle_deg) + " deg from every face"
                      : std::string()) +
          "). Record again: hold the rig still for about 30 s with each of the six faces up in "
          "turn (face +x up: the accelerometer's x axis reads +g)");
}

/// White noise density and bias random walk of each gyro axis from the Allan deviation pooled over
/// the holds (each hold's overlapping Allan variance at a cluster time, weighted by its number of
/// differences).
void gyro_noise(const std::vector<Hold>& holds, const ScannedRecording& scan, GSensitivityResult* res) {
  std::map<long, std::pair<Eigen::Vector3d, long>> pooled;  // cluster size m -> (sum of w avar, w)
  for (const auto& h : holds) {
    auto curve = allan_deviation(
        std::span<const Eigen::Vector3d>(scan.gyro.data() + h.begin, h.end - h.begin), scan.rate_hz);
    if (!curve.ok()) continue;
    for (std::size_t k = 0; k < curve->tau_s.size(); ++k) {
      const long m = std::lround(curve->tau_s[k] * scan.rate_hz);
      auto& [sum, weight] = pooled[m];
      if (weight == 0) sum.setZero();
      sum += static_cast<double>(curve->clusters[k]) * curve->adev[k].cwiseAbs2();
      weight += curve->clusters[k];
    }
  }
  AllanCurve curve;
  for (const auto& [m, acc] : pooled) {
    curve.tau_s.push_back(static_cast<double>(m) / scan.rate_hz);
    curve.adev.push_back((acc.first / static_cast<double>(acc.second)).cwiseSqrt());
    curve.clusters.push_back(acc.second);
  }
  for (int axis = 0; axis < 3; ++axis) {
    const AllanNoise n = fit_allan_noise(curve, axis);
    res->gyro_noise_density[axis] = n.noise_density;
    res->gyro_random_walk[axis] = n.random_walk;
  }
}

/// The fit of one gyro axis: theta = [b, H row], its covariance before scaling, chi-square.
struct AxisFit {
  Eigen::Vector4d theta = Eigen::Vector4d::Zero();
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  double chi2 = 0.0;
};

/// Generalised least squares y = X theta + e, Cov(e) = S, through the Cholesky factor of S.
AxisFit fit_axis(const Eigen::MatrixXd& X, const Eigen::VectorXd& y, const Eigen::MatrixXd& S) {
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd Xw = llt.matrixL().solve(X);
  const Eigen::VectorXd yw = llt.matrixL().solve(y);
  AxisFit f;
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Xw);
  f.theta = qr.solve(yw);
  f.P = (Xw.transpose() * Xw).inverse();
  f.chi2 = (yw - Xw * f.theta).squaredNorm();
  return f;
}

/// G's covariance from the uncertainty of the models the holds were read through: with the true
/// A_g = (I + E_g) A_g and a = (I + E_a) a_used, G becomes G + E_g G - G E_a to first order; the
/// entries of E_g and E_a are independent with the given relative sigmas.
Eigen::Matrix<double, 9, 9> model_covariance(const Eigen::Matrix3d& G, double s_g, double s_a) {
  Eigen::Matrix<double, 9, 9> C = Eigen::Matrix<double, 9, 9>::Zero();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      for (int r2 = 0; r2 < 3; ++r2) {
        for (int c2 = 0; c2 < 3; ++c2) {
          double v = 0.0;
          if (r == r2) v += s_g * s_g * G.col(c).dot(G.col(c2));
          if (c == c2) v += s_a * s_a * G.row(r).dot(G.row(r2));
          C(3 * r + c, 3 * r2 + c2) = v;
        }
      }
    }
  }
  return C;
}

/// The fit over the holds, one axis at a time, and G, b_g and their covariance from it.
void fit_holds(const std::vector<Hold>& holds, const GSensitivityOptions& opt, GSensitivityResult* res) {
  const auto n = static_cast<Eigen::Index>(holds.size());
  std::vector<double> t0, t1;
  Eigen::MatrixXd X(n, 4);
  Eigen::MatrixXd Y(n, 3);
  for (Eigen::Index k = 0; k < n; ++k) {
    const Hold& h = holds[static_cast<std::size_t>(k)];
    t0.push_back(h.t0_s);
    t1.push_back(h.t1_s);
    X(k, 0) = 1.0;
    X.row(k).tail<3>() = h.a.transpose();
    Y.row(k) = h.gyro_raw.transpose();
  }
  const double t_ref = 0.5 * (t0.front() + t1.back());
  const Eigen::MatrixXd C = random_walk_mean_covariance(t0, t1, t_ref);
  std::vector<AxisFit> fits;
  double chi2 = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    Eigen::MatrixXd S = res->gyro_random_walk[axis] * res->gyro_random_walk[axis] * C;
    for (Eigen::Index k = 0; k < n; ++k) {
      S(k, k) += res->gyro_noise_density[axis] * res->gyro_noise_density[axis] / (t1[k] - t0[k]);
    }
    fits.push_back(fit_axis(X, Y.col(axis), S));
    chi2 += fits.back().chi2;
  }
  res->dof = {3 * static_cast<int>(n), 12};
  res->chi2_per_dof = chi2 / res->dof.dof();
  // The noise model holds the floor; residuals that scatter more than it (a turn in a hold, an
  // underestimated walk) widen the covariance, fewer never narrow it below the floor.
  const double scale = std::max(1.0, res->chi2_per_dof);
  Eigen::Matrix<double, 12, 12> P = Eigen::Matrix<double, 12, 12>::Zero();
  Eigen::Matrix<double, 12, 12> J = Eigen::Matrix<double, 12, 12>::Zero();  // [vec_row(G); b] <- [theta_i]
  Eigen::Matrix3d H;
  for (int i = 0; i < 3; ++i) {
    const AxisFit& f = fits[static_cast<std::size_t>(i)];
    P.block<4, 4>(4 * i, 4 * i) = scale * f.P;
    res->b_g[i] = f.theta[0];
    H.row(i) = f.theta.tail<3>().transpose();
    J(9 + i, 4 * i) = 1.0;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) J(3 * r + c, 4 * i + 1 + c) = opt.A_g(r, i);
    }
  }
  res->G = opt.A_g * H;
  res->covariance = J * P * J.transpose();
  res->covariance.topLeftCorner<9, 9>() +=
      model_covariance(res->G, opt.gyro_model_rel_sigma, opt.accel_model_rel_sigma);
  res->covariance.bottomRightCorner<3, 3>() +=
      opt.accel_offset_sigma_mps2 * opt.accel_offset_sigma_mps2 * H * H.transpose();
  for (int e = 0; e < 9; ++e) res->G_sigma(e / 3, e % 3) = std::sqrt(res->covariance(e, e));
  for (int i = 0; i < 3; ++i) res->b_g_sigma[i] = std::sqrt(res->covariance(9 + i, 9 + i));
  res->b_g_t_ns =
      static_cast<TimeNs>(std::llround(t_ref * 1e9));  // from the first sample; made absolute below
  // Residuals: what the model leaves of each hold, in rad/s.
  double sum_sq = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) {
    const Hold& h = holds[static_cast<std::size_t>(k)];
    GSensitivityHold out;
    out.samples = h.end - h.begin;
    out.face = h.face >= 0 ? kFaceNames[h.face] : "";
    out.face_angle_deg = rad_to_deg(h.face_angle_rad);
    out.accel_mps2 = h.a;
    out.gyro_mean_raw = h.gyro_raw;
    out.residual_radps = opt.A_g * (h.gyro_raw - res->b_g - H * h.a);
    out.tilt_deg = rad_to_deg(h.tilt_rad);
    out.rotation_deg = rad_to_deg(out.residual_radps.norm() * h.length_s());
    sum_sq += out.residual_radps.squaredNorm();
    res->holds.push_back(out);
  }
  res->residual_rms_radps = std::sqrt(sum_sq / (3.0 * static_cast<double>(n)));
}

/// Warnings about holds that turn and residuals beyond the noise. A turn that tilts the rig shows
/// in the accelerometer; a turn about the vertical only in the gyro's residual, which the fit
/// spreads over the other holds (4 parameters per axis from 6 holds), so only the largest is named.
void warn_about_holds(const GSensitivityOptions& opt, GSensitivityResult* res) {
  auto name = [&](std::size_t k) {
    const auto& face = res->holds[k].face;
    return "hold " + std::to_string(k + 1) + " (" + (face.empty() ? "tilted" : face + " up") + ")";
  };
  std::size_t worst = 0;
  for (std::size_t k = 0; k < res->holds.size(); ++k) {
    const auto& h = res->holds[k];
    if (h.rotation_deg > res->holds[worst].rotation_deg) worst = k;
    if (h.tilt_deg > opt.max_rotation_deg) {
      res->warnings.push_back(name(k) + " is rotating: its gravity direction turns " +
                              format_number("%.2f", h.tilt_deg) + " deg (limit " +
                              format_number("%.1f", opt.max_rotation_deg) +
                              " deg), and G absorbs the gyro's reading of the turn. Clamp the rig or hold it "
                              "still, and record again");
    }
  }
  const auto& w = res->holds[worst];
  if (w.rotation_deg > opt.max_rotation_deg) {
    res->warnings.push_back(
        "the gyro means do not fit b_g + H a: " + name(worst) + " is " +
        format_number("%.2g", w.residual_radps.norm()) + " rad/s off the fit, " +
        format_number("%.2f", w.rotation_deg) + " deg over the hold (limit " +
        format_number("%.1f", opt.max_rotation_deg) +
        " deg): a hold turned (about the vertical, which the accelerometer cannot see), or "
        "the bias jumped. Clamp the rig or hold it still, and record again");
  }
  if (res->chi2_per_dof > 4.0) {
    res->warnings.push_back(
        "the holds' gyro means scatter about the fit " + format_number("%.1f", std::sqrt(res->chi2_per_dof)) +
        " times more than their noise (white noise and bias random walk) explains: a hold "
        "turned, the bias drifted with temperature, or the response is not linear in a; the "
        "sigmas were widened by that factor");
  }
}

}  // namespace

Status GSensitivityOptions::validate() const {
  auto fail = [](const std::string& msg) -> Status { return make_error(Errc::kInvalidArgument, msg); };
  if (!(gravity_mps2 > 9.7 && gravity_mps2 < 9.9)) {
    return fail("gravity " + format_number("%g", gravity_mps2) +
                " m/s^2 is not a terrestrial value (9.7..9.9)");
  }
  if (latitude_deg && !(std::abs(*latitude_deg) <= 90.0))
    return fail("the latitude must be in [-90, 90] deg");
  if (!A_a.allFinite() || !b_a.allFinite() || !A_g.allFinite() || !(std::abs(A_a.determinant()) > 0.0) ||
      !(std::abs(A_g.determinant()) > 0.0)) {
    return fail("the accelerometer or gyro model is singular or not finite");
  }
  for (double s : {accel_model_rel_sigma, gyro_model_rel_sigma}) {
    if (!(s >= 0.0 && s <= 0.5)) return fail("a model's relative uncertainty must be in [0, 0.5]");
  }
  if (!(accel_offset_sigma_mps2 >= 0.0 && accel_offset_sigma_mps2 <= 10.0))
    return fail("the accelerometer offset's uncertainty must be in [0, 10] m/s^2");
  if (!(window_s > 0.0 && window_s <= 10.0)) return fail("the detector window must be in (0, 10] s");
  if (!(min_hold_s >= 1.0 && min_hold_s <= 3600.0)) return fail("the shortest hold must be in [1, 3600] s");
  if (!(max_face_angle_deg > 0.0 && max_face_angle_deg <= 45.0))
    return fail("the face angle must be in (0, 45] deg");
  if (!(max_rotation_deg > 0.0)) return fail("the rotation limit of a hold must be positive");
  return {};
}

Eigen::MatrixXd random_walk_mean_covariance(const std::vector<double>& t0, const std::vector<double>& t1,
                                            double t_ref) {
  // Each span splits at t_ref into pieces on one side, as distances [u, v] from t_ref. For pieces
  // on one side W is a Brownian motion in the distance: the mean over [u, v] has variance
  // u + (v - u) / 3, and two disjoint pieces have covariance the mid distance of the nearer one.
  // Pieces on opposite sides are independent.
  struct Piece {
    std::size_t span;
    int side;
    double u, v;
  };
  std::vector<Piece> pieces;
  for (std::size_t k = 0; k < t0.size(); ++k) {
    if (t0[k] < t_ref) pieces.push_back({k, -1, std::max(0.0, t_ref - t1[k]), t_ref - t0[k]});
    if (t1[k] > t_ref) pieces.push_back({k, +1, std::max(0.0, t0[k] - t_ref), t1[k] - t_ref});
  }
  const auto n = static_cast<Eigen::Index>(t0.size());
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(n, n);
  for (const auto& p : pieces) {
    for (const auto& q : pieces) {
      if (p.side != q.side) continue;
      const double c = &p == &q     ? p.u + (p.v - p.u) / 3.0
                       : p.v <= q.u ? 0.5 * (p.u + p.v)
                                    : 0.5 * (q.u + q.v);
      const double w = (p.v - p.u) * (q.v - q.u) / ((t1[p.span] - t0[p.span]) * (t1[q.span] - t0[q.span]));
      C(static_cast<Eigen::Index>(p.span), static_cast<Eigen::Index>(q.span)) += w * c;
    }
  }
  return C;
}

Result<GSensitivityResult> calibrate_gsens(std::span<const ImuSample> samples,
                                           const GSensitivityOptions& opt) {
  IMUCAL_TRY(opt.validate());
  GSensitivityResult res;
  res.gravity_mps2 = opt.gravity_mps2;
  res.A_a = opt.A_a;
  res.b_a = opt.b_a;
  res.A_g = opt.A_g;
  res.accel_model_rel_sigma = opt.accel_model_rel_sigma;
  res.gyro_model_rel_sigma = opt.gyro_model_rel_sigma;
  res.accel_offset_sigma_mps2 = opt.accel_offset_sigma_mps2;
  Result<ScannedRecording> scan = scan_recording(samples, &res.warnings);
  if (!scan.ok()) return scan.error();
  const std::vector<Hold> holds = find_holds(*scan, opt, &res.warnings);
  IMUCAL_TRY(check_faces(holds, opt));
  gyro_noise(holds, *scan, &res);
  if (!(res.gyro_noise_density.minCoeff() > 0.0)) {
    return make_error(Errc::kInsufficientData,
                      "the gyro shows no noise in the holds (a constant signal): the log does not hold "
                      "gyro measurements");
  }
  fit_holds(holds, opt, &res);
  res.b_g_t_ns += samples.front().t_ns;
  for (std::size_t k = 0; k < holds.size(); ++k) {
    res.holds[k].t0_ns = samples[holds[k].begin].t_ns;
    res.holds[k].t1_ns = samples[holds[k].end - 1].t_ns;
  }
  if (opt.latitude_deg) {
    res.earth_rate_removed = earth_rate_gsens(*opt.latitude_deg, opt.gravity_mps2);
    res.G -= res.earth_rate_removed * Eigen::Matrix3d::Identity();
  }
  warn_about_holds(opt, &res);
  return res;
}

}  // namespace imucal::calib
