// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camimu_init.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "calib/ray_pnp.hpp"
#include "calib/so3.hpp"

namespace imucal::calib::camimu {

std::vector<FramePose> pnp_poses(const CameraModel& camera,
                                 const std::vector<TargetObservation>& observations,
                                 const std::vector<Eigen::Vector3d>& target_points, TimeNs t0_ns,
                                 int min_corners, double max_rms_px) {
  std::vector<FramePose> poses;
  for (const auto& obs : observations) {
    if (static_cast<int>(obs.ids.size()) < min_corners) continue;
    std::vector<Eigen::Vector3d> object, rays;
    for (std::size_t k = 0; k < obs.ids.size(); ++k) {
      Eigen::Vector3d ray;
      if (!camera.unproject(obs.px[k], &ray)) continue;
      object.push_back(target_points[obs.ids[k]]);
      rays.push_back(ray);
    }
    if (static_cast<int>(object.size()) < min_corners) continue;
    // Turned towards the view's mean ray, so that a view far off the axis (a fisheye's border)
    // is solved as a central one (calib/ray_pnp.hpp).
    const auto found = pose_from_rays(object, rays, true);
    if (!found) continue;
    const Eigen::Matrix3d& R_ct = found->R_cam_target;
    const Eigen::Vector3d& t_ct = found->t_cam_target;
    double sq = 0.0;
    int n = 0;
    for (std::size_t k = 0; k < obs.ids.size(); ++k) {
      const auto pr = camera.project(R_ct * target_points[obs.ids[k]] + t_ct);
      if (!pr.in_front) continue;
      sq += (pr.px - obs.px[k]).squaredNorm();
      ++n;
    }
    if (n < min_corners) continue;
    FramePose pose;
    pose.t_ns = obs.t_ns;
    pose.t_s = static_cast<double>(obs.t_ns - t0_ns) * 1e-9;
    pose.R_wc = R_ct.transpose();
    pose.p_wc = -pose.R_wc * t_ct;
    pose.rms_px = std::sqrt(sq / n);
    if (pose.rms_px <= max_rms_px) poses.push_back(pose);
  }
  return poses;
}

std::vector<RateSample> camera_rates(const std::vector<FramePose>& poses, double max_gap_s) {
  std::vector<RateSample> rates;
  for (std::size_t i = 1; i < poses.size(); ++i) {
    const double dt = poses[i].t_s - poses[i - 1].t_s;
    if (dt <= 0 || dt > max_gap_s) continue;
    rates.push_back({0.5 * (poses[i].t_s + poses[i - 1].t_s),
                     so3::log(poses[i - 1].R_wc.transpose() * poses[i].R_wc) / dt});
  }
  return rates;
}

GyroLookup::GyroLookup(std::vector<double> t_s, std::vector<Eigen::Vector3d> w)
    : t_(std::move(t_s)), w_(std::move(w)) {
  q_.reserve(t_.size());
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  for (std::size_t k = 0; k < t_.size(); ++k) {
    q_.push_back(q);
    if (k + 1 < t_.size()) {
      q = (q * Eigen::Quaterniond(so3::exp(w_[k] * (t_[k + 1] - t_[k])))).normalized();
    }
  }
}

std::size_t GyroLookup::nearest(double t_s) const {
  const auto it = std::lower_bound(t_.begin(), t_.end(), t_s);
  if (it == t_.begin()) return 0;
  if (it == t_.end()) return t_.size() - 1;
  const auto k = static_cast<std::size_t>(it - t_.begin());
  return t_[k] - t_s < t_s - t_[k - 1] ? k : k - 1;
}

bool GyroLookup::turn_angle(double t0_s, double t1_s, double* angle) const {
  if (t_.empty() || std::min(t0_s, t1_s) < t_.front() || std::max(t0_s, t1_s) > t_.back()) return false;
  *angle = q_[nearest(t0_s)].angularDistance(q_[nearest(t1_s)]);
  return true;
}

double GyroLookup::max_speed(double t0_s, double t1_s) const {
  double best = 0.0;
  const auto lo = std::lower_bound(t_.begin(), t_.end(), t0_s);
  const auto hi = std::upper_bound(t_.begin(), t_.end(), t1_s);
  for (auto it = lo; it < hi; ++it)
    best = std::max(best, w_[static_cast<std::size_t>(it - t_.begin())].norm());
  return best;
}

std::vector<std::size_t> poses_against_gyro(const std::vector<FramePose>& poses, const GyroLookup& gyro,
                                            double shift_s, double shift_uncertainty_s, double window_s) {
  constexpr double kAngleTolerance = 0.35;  // rad: bias and scale errors over window_s stay far below
  std::vector<std::size_t> bad;
  std::size_t lo = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const double ti = poses[i].t_s;
    while (poses[lo].t_s < ti - window_s) ++lo;
    const double margin = window_s + shift_uncertainty_s;
    const double tolerance =
        kAngleTolerance +
        2.0 * shift_uncertainty_s * gyro.max_speed(ti + shift_s - margin, ti + shift_s + margin);
    int compared = 0;
    int disagree = 0;
    for (std::size_t j = lo; j < poses.size() && poses[j].t_s <= ti + window_s; ++j) {
      if (j == i) continue;
      double gyro_angle = 0.0;
      if (!gyro.turn_angle(ti + shift_s, poses[j].t_s + shift_s, &gyro_angle)) continue;
      const double camera_angle =
          Eigen::Quaterniond(poses[i].R_wc).angularDistance(Eigen::Quaterniond(poses[j].R_wc));
      ++compared;
      if (std::abs(camera_angle - gyro_angle) > tolerance) ++disagree;
    }
    if (compared >= 2 && 2 * disagree > compared) bad.push_back(i);
  }
  return bad;
}

bool GyroLookup::at(double t_s, double half_window_s, Eigen::Vector3d* w) const {
  if (t_.empty() || t_s - half_window_s < t_.front() || t_s + half_window_s > t_.back()) return false;
  auto lo = std::lower_bound(t_.begin(), t_.end(), t_s - half_window_s);
  auto hi = std::upper_bound(t_.begin(), t_.end(), t_s + half_window_s);
  if (hi <= lo) return false;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (auto it = lo; it != hi; ++it) sum += w_[static_cast<std::size_t>(it - t_.begin())];
  *w = sum / static_cast<double>(hi - lo);
  return true;
}

namespace {

// Normalised correlation of the camera's angular speed with the gyro's at one lag.
bool correlation_at(const std::vector<RateSample>& camera, const GyroLookup& gyro, double half_window_s,
                    double lag, double* value) {
  std::vector<double> a, b;
  a.reserve(camera.size());
  b.reserve(camera.size());
  for (const auto& c : camera) {
    Eigen::Vector3d w;
    if (!gyro.at(c.t_s + lag, half_window_s, &w)) continue;
    a.push_back(c.w.norm());
    b.push_back(w.norm());
  }
  if (a.size() < 10) return false;
  const double n = static_cast<double>(a.size());
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) ma += a[i] / n, mb += b[i] / n;
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  if (saa <= 0 || sbb <= 0) return false;
  *value = sab / std::sqrt(saa * sbb);
  return true;
}

}  // namespace

TimeshiftEstimate correlate_timeshift(const std::vector<RateSample>& camera, const GyroLookup& gyro,
                                      double half_window_s, double max_shift_s) {
  TimeshiftEstimate out;
  const double step = 1e-3;
  const int steps = static_cast<int>(std::round(max_shift_s / step));
  int best = -1;
  for (int i = -steps; i <= steps; ++i) {
    double v = 0.0;
    if (!correlation_at(camera, gyro, half_window_s, i * step, &v)) continue;
    out.curve.emplace_back(i * step, v);
    if (best < 0 || v > out.curve[static_cast<std::size_t>(best)].second)
      best = static_cast<int>(out.curve.size()) - 1;
  }
  if (best < 0) return out;
  const auto b = static_cast<std::size_t>(best);
  out.shift_s = out.curve[b].first;
  out.peak = out.curve[b].second;
  if (b > 0 && b + 1 < out.curve.size()) {
    const double y0 = out.curve[b - 1].second, y1 = out.curve[b].second, y2 = out.curve[b + 1].second;
    const double den = y0 - 2 * y1 + y2;
    if (den < 0) out.shift_s += step * 0.5 * (y0 - y2) / den;
  }
  return out;
}

RotationEstimate align_rotation(const std::vector<RateSample>& camera, const GyroLookup& gyro, double shift_s,
                                double half_window_s) {
  std::vector<Eigen::Vector3d> wc, wi;
  for (const auto& c : camera) {
    Eigen::Vector3d w;
    if (!gyro.at(c.t_s + shift_s, half_window_s, &w)) continue;
    wc.push_back(c.w);
    wi.push_back(w);
  }
  RotationEstimate out;
  out.pairs = static_cast<int>(wc.size());
  if (wc.size() < 3) return out;
  // Kabsch with centred rates (the centring absorbs the bias), then Gauss-Newton on R and b.
  Eigen::Vector3d mc = Eigen::Vector3d::Zero(), mi = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < wc.size(); ++k) mc += wc[k], mi += wi[k];
  mc /= static_cast<double>(wc.size());
  mi /= static_cast<double>(wi.size());
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < wc.size(); ++k) H += (wi[k] - mi) * (wc[k] - mc).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Eigen::Matrix3d R = svd.matrixV() * D * svd.matrixU().transpose();
  Eigen::Vector3d b = mi - R.transpose() * mc;
  for (int it = 0; it < 5; ++it) {
    // r = R (wi - b) - wc; R <- R Exp(d): dr/dd = -R [wi - b]x, dr/db = -R.
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t k = 0; k < wc.size(); ++k) {
      Eigen::Matrix<double, 3, 6> J;
      J.leftCols<3>() = -R * so3::hat(wi[k] - b);
      J.rightCols<3>() = -R;
      const Eigen::Vector3d r = R * (wi[k] - b) - wc[k];
      A += J.transpose() * J;
      g += J.transpose() * r;
    }
    const Eigen::Matrix<double, 6, 1> dx = -A.ldlt().solve(g);
    R = R * so3::exp(dx.head<3>());
    b += dx.tail<3>();
  }
  double sq = 0.0;
  for (std::size_t k = 0; k < wc.size(); ++k) sq += (R * (wi[k] - b) - wc[k]).squaredNorm();
  out.R_cam_imu = R;
  out.gyro_bias = b;
  out.rms_radps = std::sqrt(sq / static_cast<double>(wc.size()));
  return out;
}

}  // namespace imucal::calib::camimu
