// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camera_chain_links.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "calib/so3.hpp"

namespace imucal::calib::chain {
namespace {

double median_of(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// The pose of a camera's track at time t, interpolated between the two views around it when
/// they are at most max_gap_s apart; false otherwise.
bool interpolate(const std::vector<PoseSample>& track, double t, double max_gap_s, Eigen::Matrix3d* R,
                 Eigen::Vector3d* p) {
  const auto it =
      std::upper_bound(track.begin(), track.end(), t, [](double x, const PoseSample& s) { return x < s.t; });
  if (it == track.begin() || it == track.end()) return false;
  const PoseSample& b = *it;
  const PoseSample& a = *(it - 1);
  if (b.t - a.t > max_gap_s) return false;
  const double u = b.t > a.t ? (t - a.t) / (b.t - a.t) : 0.0;
  *R = a.R_wc * so3::exp(u * so3::log(a.R_wc.transpose() * b.R_wc));
  *p = (1.0 - u) * a.p_wc + u * b.p_wc;
  return true;
}

/// The rotation nearest (chordal) to the mean of `Rs`.
Eigen::Matrix3d mean_rotation(const std::vector<Eigen::Matrix3d>& Rs) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& R : Rs) sum += R;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

/// The relative poses T_a_b of b's views against a's track shifted by `shift`, and a score of
/// their spread (median over the views of |t - median t|^2 + (distance x angle to the mean)^2).
Link link_at(const std::vector<PoseSample>& a, const std::vector<PoseSample>& b, double shift,
             double max_gap_s) {
  std::vector<Eigen::Matrix3d> R_ab;
  std::vector<Eigen::Vector3d> t_ab;
  std::vector<double> dist;
  for (const PoseSample& s : b) {
    Eigen::Matrix3d Ra;
    Eigen::Vector3d pa;
    if (!interpolate(a, s.t + shift, max_gap_s, &Ra, &pa)) continue;
    R_ab.push_back(Ra.transpose() * s.R_wc);
    t_ab.push_back(Ra.transpose() * (s.p_wc - pa));
    dist.push_back(pa.norm());
  }
  Link out;
  out.shared = static_cast<int>(R_ab.size());
  out.shift = shift;
  if (R_ab.empty()) return out;
  const Eigen::Matrix3d R = mean_rotation(R_ab);
  Eigen::Vector3d t_med;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c;
    for (const auto& t : t_ab) c.push_back(t(k));
    t_med(k) = median_of(c);
  }
  std::vector<double> spread;
  for (std::size_t i = 0; i < R_ab.size(); ++i) {
    const double angle = so3::log(R.transpose() * R_ab[i]).norm();
    spread.push_back((t_ab[i] - t_med).squaredNorm() + std::pow(dist[i] * angle, 2));
  }
  out.score = median_of(spread);
  out.R_ba = R.transpose();
  out.t_ba = -R.transpose() * t_med;
  return out;
}

}  // namespace

/// The link of b against a: the offset on a 1 ms grid within +-max_shift_s (0 alone when
/// offsets are not estimated) with the smallest spread among those with at least min_shared
/// views, refined by a parabola through its neighbours.
Link find_link(const std::vector<PoseSample>& a, const std::vector<PoseSample>& b, double max_shift_s,
               double max_gap_s, int min_shared) {
  const double step = 1e-3;
  const int n = static_cast<int>(std::floor(max_shift_s / step));
  std::vector<Link> grid;
  for (int k = -n; k <= n; ++k) grid.push_back(link_at(a, b, k * step, max_gap_s));
  int best = -1;
  for (int k = 0; k < static_cast<int>(grid.size()); ++k) {
    if (grid[k].shared < min_shared) continue;
    if (best < 0 || grid[k].score < grid[best].score) best = k;
  }
  if (best < 0) return Link{};
  if (best > 0 && best + 1 < static_cast<int>(grid.size()) && grid[best - 1].shared >= min_shared &&
      grid[best + 1].shared >= min_shared) {
    const double y0 = grid[best - 1].score, y1 = grid[best].score, y2 = grid[best + 1].score;
    const double den = y0 - 2.0 * y1 + y2;
    if (den > 0.0) {
      const double dx = std::clamp(0.5 * (y0 - y2) / den, -0.5, 0.5);
      Link refined = link_at(a, b, grid[best].shift + dx * step, max_gap_s);
      if (refined.shared >= min_shared) return refined;
    }
  }
  return grid[best];
}

// d(T_cn_cnm1) / d(T_n_0, T_m_0) by central differences in the tangent spaces (right
/// perturbations of the rotations, then translations), 6 x 12.
Eigen::Matrix<double, 6, 12> relative_jacobian(const Eigen::Isometry3d& T_n0, const Eigen::Isometry3d& T_m0) {
  const auto rel = [](const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) { return a * b.inverse(); };
  const Eigen::Isometry3d T = rel(T_n0, T_m0);
  const auto perturb = [](const Eigen::Isometry3d& X, const Eigen::Matrix<double, 6, 1>& d) {
    Eigen::Isometry3d Y = X;
    Y.linear() = X.linear() * so3::exp(d.head<3>());
    Y.translation() = X.translation() + d.tail<3>();
    return Y;
  };
  Eigen::Matrix<double, 6, 12> J;
  const double h = 1e-6;
  for (int k = 0; k < 12; ++k) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d(k % 6) = h;
    const Eigen::Isometry3d plus = k < 6 ? rel(perturb(T_n0, d), T_m0) : rel(T_n0, perturb(T_m0, d));
    const Eigen::Isometry3d minus = k < 6 ? rel(perturb(T_n0, -d), T_m0) : rel(T_n0, perturb(T_m0, -d));
    Eigen::Matrix<double, 6, 1> col;
    col.head<3>() = (so3::log(T.linear().transpose() * plus.linear()) -
                     so3::log(T.linear().transpose() * minus.linear())) /
                    (2.0 * h);
    col.tail<3>() = (plus.translation() - minus.translation()) / (2.0 * h);
    J.col(k) = col;
  }
  return J;
}

}  // namespace imucal::calib::chain
