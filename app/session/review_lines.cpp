// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/review_lines.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/camera_model.hpp"
#include "core/text_format.hpp"

namespace imucal::app::session {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

/// "v +- s" with the digits that show s to two significant digits (at least `least`), or "v +-
/// not determined".
std::string with_sigma(double v, double s, int least) {
  const int digits = decimals_for_sigma(s, least);
  return fixed(v, digits) + " +- " + (std::isfinite(s) ? fixed(s, digits) : std::string("not determined"));
}

/// The sigma of A b from b's, each entry of b independent. A's own uncertainty is left out: it
/// adds about sigma(A) |b|, a hundredth of a count for the MPU-6000's biases of a few hundred
/// counts at relative scale sigmas near 1e-4, but not for an input whose zero is far from 0 (raw
/// counts near 32768), which the rig's driver never gives.
Eigen::Vector3d sigma_through(const Eigen::Matrix3d& A, const Eigen::Vector3d& sigma) {
  return (A.cwiseAbs2() * sigma.cwiseAbs2()).cwiseSqrt();
}

/// Named angles with sigmas in mrad: "yz a +- s, zy ...".
std::string angles_mrad(const std::vector<const char*>& names, const Eigen::VectorXd& v,
                        const Eigen::VectorXd& s) {
  std::string out;
  for (Eigen::Index i = 0; i < v.size(); ++i)
    out += (i > 0 ? ", " : "") + std::string(names[static_cast<std::size_t>(i)]) + " " +
           with_sigma(v[i] * 1e3, s[i] * 1e3, 3);
  return out;
}

/// The g-sensitivity G (rad/s per m/s^2) as three rows in deg/s per g.
std::vector<std::string> gsens_lines(const StaticCalibrationResult& r) {
  const double k = kStandardGravity / kDeg;
  if (r.gsens_mode == GSensitivityMode::kOff)
    return {"G-sensitivity: not estimated (gsens off): stored as 0"};
  std::vector<std::string> lines = {std::string("G-sensitivity (deg/s per g), ") +
                                    (r.gsens_mode == GSensitivityMode::kFixed ? "given, held" : "estimated") +
                                    ":"};
  for (int row = 0; row < 3; ++row) {
    const Eigen::Vector3d g = r.canonical.G.row(row).transpose();
    lines.push_back("  " + std::string(1, "xyz"[row]) + ": " +
                    (r.gsens_mode == GSensitivityMode::kFixed
                         ? figures(g, k, 4)
                         : figures_with_sigmas(g, r.gsens_sigma.row(row).transpose(), k, 4)));
  }
  return lines;
}

/// One fitted axis's coefficients c_1..c_p with sigmas, `k` converting to the shown unit.
std::string coefficients(const calib::ThermalAxisFit& f, double k, const char* unit) {
  if (!f.determined) return "not determined (" + f.reason + ")";
  std::string out;
  for (Eigen::Index j = 1; j < f.coeffs.size(); ++j) {
    const double s = j < f.covariance.rows() ? std::sqrt(std::max(f.covariance(j, j), 0.0)) : kNan;
    out += (j > 1 ? ", " : "") + std::string("c") + std::to_string(j) + " " +
           format_number("%.4g", f.coeffs[j] * k) + " +- " +
           (s > 0.0 ? format_number("%.2g", s * k) : std::string("not determined")) + " " + unit +
           (j > 1 ? "^" + std::to_string(j) : "");
  }
  return out.empty() ? std::string("constant (order 0)") : out;
}

/// A camera model's figures in Kalibr's order with their names and sigmas (px for the focal
/// lengths and the principal point).
std::vector<std::string> intrinsics_lines(const CameraIntrinsicsRecord& k) {
  const CameraModel& c = k.camera;
  const std::vector<std::string> names = kalibr_parameter_names(c.kind());
  std::vector<double> values = kalibr_intrinsics(c.projection, c.intrinsics, c.projection_params);
  const std::vector<double> coeffs = kalibr_distortion(c.distortion_model, c.distortion_coeffs);
  const std::size_t n_intrinsics = values.size();
  values.insert(values.end(), coeffs.begin(), coeffs.end());
  std::vector<double> sigmas = k.intrinsics_sigma;
  sigmas.insert(sigmas.end(), k.distortion_coeffs_sigma.begin(), k.distortion_coeffs_sigma.end());
  std::string projection, distortion;
  for (std::size_t i = 0; i < values.size() && i < names.size(); ++i) {
    const bool px = names[i] == "fu" || names[i] == "fv" || names[i] == "pu" || names[i] == "pv";
    const double s = i < sigmas.size() ? sigmas[i] : kNan;
    std::string& out = i < n_intrinsics ? projection : distortion;
    out +=
        (out.empty() ? "" : ", ") + names[i] + " " + with_sigma(values[i], s, px ? 2 : 4) + (px ? " px" : "");
  }
  std::vector<std::string> lines = {"  intrinsics (" + camera_model_name(c.kind()) + ", " +
                                    std::to_string(c.width) + "x" + std::to_string(c.height) +
                                    "): " + projection};
  if (!distortion.empty()) lines.push_back("  distortion: " + distortion);
  return lines;
}

/// The largest off-diagonal entry of A_now A_stored^-1 - I: the change of the axes' alignment.
double largest_misalignment_change(const Eigen::Matrix3d& now, const Eigen::Matrix3d& stored) {
  const Eigen::Matrix3d d = now * stored.inverse();
  double most = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (i != j) most = std::max(most, std::abs(d(i, j) / d(i, i)));
  return most;
}

}  // namespace

std::string figures(const Eigen::Vector3d& v, double k, int digits) {
  std::string out;
  for (int i = 0; i < 3; ++i) {
    if (i > 0) out += " ";
    out += std::isfinite(v[i]) ? fixed(v[i] * k, digits) : std::string("not determined");
  }
  return out;
}

std::string figures_with_sigmas(const Eigen::Vector3d& v, const Eigen::Vector3d& sigma, double k,
                                int digits) {
  return figures(v, k, digits) + " +- " + figures(sigma, k, digits);
}

std::vector<std::string> imu_review_lines(const StaticCalibrationResult& r, const ImuStreamInfo& info) {
  const auto& m = r.canonical;
  const bool counts = info.units == ImuUnits::kRaw;
  // The biases as the correction removes them, in the units it outputs: a = A_a (a_in - b_a)
  // subtracts A_a b_a m/s^2, w = A_g (w_in - b_g) - G a subtracts A_g b_g rad/s. On raw input the
  // model's own b_a and b_g are counts, shown beside (the model's b = -Tedaldi's bias: the same
  // sigma).
  const Eigen::Vector3d b_a = m.A_a * m.b_a, b_g = m.A_g * m.b_g;
  const Eigen::Vector3d s_a = r.accel_sigma.bias, s_g = r.gyro_sigma.bias;
  std::vector<std::string> lines;
  lines.push_back("Accel bias: " + figures_with_sigmas(b_a, sigma_through(m.A_a, s_a), 1.0, 4) + " m/s^2" +
                  (counts ? " (" + figures_with_sigmas(m.b_a, s_a, 1.0, 1) + " counts)" : std::string()));
  lines.push_back("Gyro bias: " + figures_with_sigmas(b_g, sigma_through(m.A_g, s_g), 1.0 / kDeg, 3) +
                  " deg/s" +
                  (counts ? " (" + figures_with_sigmas(m.b_g, s_g, 1.0, 1) + " counts)" : std::string()));
  // Scales against the nominal conversion (the driver's; 1 on SI input), relative, e-3.
  const Eigen::Vector3d nominal_a = counts ? info.accel.scale : Eigen::Vector3d::Ones();
  const Eigen::Vector3d nominal_g = counts ? info.gyro.scale : Eigen::Vector3d::Ones();
  const auto relative = [](const Eigen::Vector3d& s, const Eigen::Vector3d& nominal) {
    return Eigen::Vector3d(s.cwiseQuotient(nominal).array() - 1.0);
  };
  lines.push_back("Accel scale against nominal (e-3): " +
                  figures_with_sigmas(relative(r.model.accel.scale, nominal_a),
                                      r.accel_sigma.scale.cwiseQuotient(nominal_a.cwiseAbs()), 1e3, 3));
  lines.push_back("Gyro scale against nominal (e-3): " +
                  figures_with_sigmas(relative(r.model.gyro.scale, nominal_g),
                                      r.gyro_sigma.scale.cwiseQuotient(nominal_g.cwiseAbs()), 1e3, 3));
  // Tedaldi's misalignment angles (rad), each with the sigma of its entry of T.
  const Eigen::Matrix3d& Ta = r.model.accel.T;
  const Eigen::Matrix3d& Sa = r.accel_sigma.T;
  lines.push_back("Accel misalignment (mrad): " + angles_mrad({"yz", "zy", "zx"}, accel_angles(Ta),
                                                              Eigen::Vector3d(Sa(0, 1), Sa(0, 2), Sa(1, 2))));
  const Eigen::Matrix3d& Sg = r.gyro_sigma.T;
  Eigen::Matrix<double, 6, 1> sg;
  sg << Sg(0, 1), Sg(0, 2), Sg(1, 0), Sg(1, 2), Sg(2, 0), Sg(2, 1);
  lines.push_back("Gyro misalignment (mrad): " +
                  angles_mrad({"yz", "zy", "xz", "zx", "xy", "yx"}, gyro_angles(r.model.gyro.T), sg));
  for (auto& line : gsens_lines(r)) lines.push_back(std::move(line));
  lines.push_back("Static intervals " + std::to_string(r.intervals.size()) + ", attitudes " +
                  std::to_string(r.distinct_attitudes));
  return lines;
}

std::vector<std::string> thermal_review_lines(const calib::ThermalResult& t) {
  if (!t.determined) return {"Thermal model: not determined: " + t.reason};
  const auto axes = [](const std::array<calib::ThermalAxisFit, 3>& fits,
                       double calib::ThermalAxisFit::*member) {
    Eigen::Vector3d v;
    for (int a = 0; a < 3; ++a) v[a] = fits[a].determined ? fits[a].*member : kNan;
    return v;
  };
  const auto orders = [](const std::array<calib::ThermalAxisFit, 3>& fits) {
    std::string out;
    for (const auto& f : fits)
      out += (out.empty() ? "" : " ") + (f.determined ? std::to_string(f.order) : "-");
    return out;
  };
  const double mg = 1e3 / kStandardGravity;
  std::vector<std::string> lines = {
      "Thermal model: reference " + fixed(t.reference_c, 2) + " C, valid " + fixed(t.temp_min_c, 2) + " .. " +
          fixed(t.temp_max_c, 2) + " C, " + std::to_string(t.bins) + " bins; orders gyro " + orders(t.gyro) +
          ", accel " + orders(t.accel),
      "  gyro drift over the range " +
          figures(axes(t.gyro, &calib::ThermalAxisFit::uncompensated_drift), 1.0 / kDeg, 4) +
          " deg/s; left about the fit (RMS) " +
          figures(axes(t.gyro, &calib::ThermalAxisFit::residual_rms), 1.0 / kDeg, 4) + " deg/s",
      "  accel drift over the range " +
          figures(axes(t.accel, &calib::ThermalAxisFit::uncompensated_drift), mg, 3) +
          " mg; left about the fit (RMS) " +
          figures(axes(t.accel, &calib::ThermalAxisFit::residual_rms), mg, 3) + " mg"};
  // The coefficients the record stores, per K^j about the reference.
  for (int a = 0; a < 3; ++a)
    lines.push_back("  gyro " + std::string(1, "xyz"[a]) + ": " +
                    coefficients(t.gyro[a], 1.0 / kDeg, "deg/s/K"));
  for (int a = 0; a < 3; ++a)
    lines.push_back("  accel " + std::string(1, "xyz"[a]) + ": " + coefficients(t.accel[a], mg, "mg/K"));
  if (t.scale.determined) {
    const ThermalScaleModel& s = t.scale.model;
    lines.push_back("  sensitivity against temperature (ppm/K): gyro " +
                    figures_with_sigmas(s.gyro_k, s.gyro_sigma, 1e6, 1) + ", accel " +
                    figures_with_sigmas(s.accel_k, s.accel_sigma, 1e6, 1));
  } else {
    lines.push_back("  sensitivity against temperature: not determined (" + t.scale.reason + ")");
  }
  return lines;
}

std::vector<std::string> camera_review_lines(const CameraRecord& cam, double rms_px) {
  const Eigen::Matrix3d R = cam.T_cam_imu.topLeftCorner<3, 3>();
  const Eigen::AngleAxisd aa(R);
  const Eigen::Vector3d rotvec = aa.angle() * aa.axis();
  const Eigen::Vector3d t = cam.T_cam_imu.topRightCorner<3, 1>();
  std::string second =
      "  time offset " + with_sigma(cam.timeshift_cam_imu_s * 1e3, cam.timeshift_sigma_s * 1e3, 3) + " ms";
  if (cam.line_delay_s)
    second += ", line delay " + with_sigma(*cam.line_delay_s * 1e6, cam.line_delay_sigma_s * 1e6, 3) +
              " us per row";
  second += ", reprojection RMS " + fixed(rms_px, 3) + " px";
  std::vector<std::string> lines = {
      cam.name + " T_cam_imu: rotation vector " + figures(rotvec, 1.0 / kDeg, 3) +
          " deg (sigma about the camera's x y z " + figures(cam.rotation_sigma_rad, 1.0 / kDeg, 3) +
          " deg), translation " + figures_with_sigmas(t, cam.translation_sigma_m, 1e3, 2) + " mm",
      second};
  if (cam.intrinsics) {
    for (auto& line : intrinsics_lines(*cam.intrinsics)) lines.push_back(std::move(line));
  } else {
    lines.push_back("  intrinsics: not stored with this camera");
  }
  return lines;
}

std::vector<std::string> imu_change_lines(const CanonicalImuModel& c, const CanonicalImuModel& old,
                                          bool counts) {
  const Eigen::Vector3d db_a = c.b_a - old.b_a, db_g = c.b_g - old.b_g;
  // Scale changes as relative changes of the correction's diagonal.
  const Eigen::Vector3d ds_a = c.A_a.diagonal().cwiseQuotient(old.A_a.diagonal()).array() - 1.0;
  const Eigen::Vector3d ds_g = c.A_g.diagonal().cwiseQuotient(old.A_g.diagonal()).array() - 1.0;
  // In the units the correction outputs (m/s^2, deg/s), and in counts beside on raw input.
  const Eigen::Vector3d da = c.A_a * db_a, dg = c.A_g * db_g;
  const double dG = (c.G - old.G).cwiseAbs().maxCoeff() * kStandardGravity / kDeg;
  return {"  accel bias " + figures(da, 1.0, 4) + " m/s^2" +
              (counts ? " (" + figures(db_a, 1.0, 2) + " counts)" : "") + ", scale " + figures(ds_a, 1e3, 3) +
              " e-3",
          "  gyro bias " + figures(dg, 1.0 / kDeg, 4) + " deg/s" +
              (counts ? " (" + figures(db_g, 1.0, 2) + " counts)" : "") + ", scale " + figures(ds_g, 1e3, 3) +
              " e-3",
          "  misalignment: accel " + fixed(largest_misalignment_change(c.A_a, old.A_a) * 1e3, 3) +
              " mrad, gyro " + fixed(largest_misalignment_change(c.A_g, old.A_g) * 1e3, 3) +
              " mrad (largest); G-sensitivity " + fixed(dG, 4) + " deg/s per g (largest entry)"};
}

std::vector<std::string> thermal_change_lines(const ThermalModel& now,
                                              const std::optional<ThermalModel>& stored,
                                              const ImuStreamInfo& info) {
  if (!stored) return {"  thermal model: none stored before (new)"};
  const double lo = std::max(now.min_c, stored->min_c), hi = std::min(now.max_c, stored->max_c);
  if (!(hi > lo)) {
    return {"  thermal model: the stored one's range " + fixed(stored->min_c, 1) + " .. " +
            fixed(stored->max_c, 1) + " C and this one's " + fixed(now.min_c, 1) + " .. " +
            fixed(now.max_c, 1) + " C do not overlap"};
  }
  // Both models' bias change about one temperature of the common range, compared over it.
  const double anchor = std::clamp(now.reference_c, lo, hi);
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero(), accel = Eigen::Vector3d::Zero();
  constexpr int kSteps = 50;
  for (int i = 0; i <= kSteps; ++i) {
    const double T = lo + (hi - lo) * i / kSteps;
    const Eigen::Vector3d dg = (now.gyro_change(T) - now.gyro_change(anchor)) -
                               (stored->gyro_change(T) - stored->gyro_change(anchor));
    const Eigen::Vector3d da = (now.accel_change(T) - now.accel_change(anchor)) -
                               (stored->accel_change(T) - stored->accel_change(anchor));
    gyro = gyro.cwiseMax(dg.cwiseAbs());
    accel = accel.cwiseMax(da.cwiseAbs());
  }
  const bool counts = info.units == ImuUnits::kRaw;
  if (counts) {
    gyro = gyro.cwiseProduct(info.gyro.scale.cwiseAbs());
    accel = accel.cwiseProduct(info.accel.scale.cwiseAbs());
  }
  return {"  thermal model, largest difference of the modelled drift over " + fixed(lo, 1) + " .. " +
          fixed(hi, 1) + " C: gyro " + figures(gyro, 1.0 / kDeg, 4) + " deg/s, accel " +
          figures(accel, 1e3 / kStandardGravity, 3) + " mg"};
}

std::string camera_change_line(const CameraRecord& now, const CameraRecord& old) {
  const Eigen::Matrix3d R_now = now.T_cam_imu.topLeftCorner<3, 3>(),
                        R_old = old.T_cam_imu.topLeftCorner<3, 3>();
  const Eigen::Vector3d dt = now.T_cam_imu.topRightCorner<3, 1>() - old.T_cam_imu.topRightCorner<3, 1>();
  const double angle = Eigen::AngleAxisd(R_now * R_old.transpose()).angle();
  const double dshift = now.timeshift_cam_imu_s - old.timeshift_cam_imu_s;
  std::string line = "  " + now.name + ": translation " + figures(dt, 1e3, 2) + " mm (" +
                     fixed(dt.norm() * 1e3, 2) + " mm), rotation " + fixed(angle / kDeg, 3) +
                     " deg, time offset " + fixed(dshift * 1e3, 3) + " ms";
  if (now.line_delay_s && old.line_delay_s)
    line += ", line delay " + fixed((*now.line_delay_s - *old.line_delay_s) * 1e6, 3) + " us per row";
  if (!now.intrinsics) return line;
  if (!old.intrinsics) return line + "; intrinsics not in the stored record";
  const CameraModel &a = now.intrinsics->camera, &b = old.intrinsics->camera;
  if (a.kind() != b.kind() || a.width != b.width || a.height != b.height) {
    return line + "; intrinsics: " + camera_model_name(b.kind()) + " " + std::to_string(b.width) + "x" +
           std::to_string(b.height) + " before, " + camera_model_name(a.kind()) + " " +
           std::to_string(a.width) + "x" + std::to_string(a.height) + " now";
  }
  const Eigen::Vector4d dk = a.intrinsics - b.intrinsics;
  const double dd = std::max((a.distortion_coeffs - b.distortion_coeffs).cwiseAbs().maxCoeff(),
                             (a.projection_params - b.projection_params).cwiseAbs().maxCoeff());
  return line + "; fu fv pu pv " + fixed(dk[0], 2) + " " + fixed(dk[1], 2) + " " + fixed(dk[2], 2) + " " +
         fixed(dk[3], 2) + " px, other figures " + format_number("%.2g", dd) + " (largest)";
}

}  // namespace imucal::app::session
