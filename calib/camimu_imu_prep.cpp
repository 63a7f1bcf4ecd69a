// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camimu_imu_prep.hpp"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <span>

#include "calib/spline.hpp"

namespace imucal::calib {

TimeNs imu_median_interval_ns(const std::vector<CamImuSample>& imu) {
  std::vector<TimeNs> t(imu.size());
  for (std::size_t i = 0; i < imu.size(); ++i) t[i] = imu[i].t_ns;
  return median_interval_ns(std::span<const TimeNs>(t));
}

std::vector<CamImuSample> average_imu(const std::vector<CamImuSample>& imu, double max_rate_hz, int* k_out) {
  *k_out = 1;
  if (imu.size() < 3 || max_rate_hz <= 0.0) return imu;
  const TimeNs dt = std::max<TimeNs>(imu_median_interval_ns(imu), 1);
  const int k = static_cast<int>(std::floor(1e9 / static_cast<double>(dt) / max_rate_hz + 1e-9));
  if (k < 2) return imu;
  *k_out = k;
  const TimeNs max_span = (k - 1) * dt + dt / 2;
  std::vector<CamImuSample> out;
  out.reserve(imu.size() / static_cast<std::size_t>(k) + 1);
  std::size_t i = 0;
  while (i + static_cast<std::size_t>(k) <= imu.size()) {
    const std::size_t last = i + static_cast<std::size_t>(k) - 1;
    if (imu[last].t_ns - imu[i].t_ns > max_span) {
      ++i;  // a gap inside: slide past it
      continue;
    }
    CamImuSample g;
    TimeNs offsets = 0;
    for (std::size_t j = i; j <= last; ++j) {
      offsets += imu[j].t_ns - imu[i].t_ns;
      g.accel += imu[j].accel;
      g.gyro += imu[j].gyro;
    }
    g.t_ns = imu[i].t_ns + offsets / k;
    g.accel /= k;
    g.gyro /= k;
    out.push_back(g);
    i = last + 1;
  }
  return out;
}

namespace {

/// The unbiased residual sigma of a least-squares B-spline of order M with knots every dt fitted
/// to the gyro samples (three axes, one shared normal matrix); NaN with too few samples.
template <int M>
double gyro_fit_sigma(const std::vector<CamImuSample>& imu, double dt) {
  const double t0 = 1e-9 * static_cast<double>(imu.front().t_ns);
  const double T = 1e-9 * static_cast<double>(imu.back().t_ns - imu.front().t_ns);
  const int knots = static_cast<int>(std::ceil(T / dt)) + M;
  const SplineTiming<M> timing{0.0, dt, knots};
  const auto n = static_cast<double>(imu.size());
  if (n < 1.5 * knots) return std::nan("");
  std::vector<Eigen::Triplet<double>> trip;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(knots, 3);
  std::vector<std::pair<int, Eigen::Matrix<double, M, 1>>> rows;
  rows.reserve(imu.size());
  for (const auto& s : imu) {
    const SplineSegment seg = timing.segment(1e-9 * static_cast<double>(s.t_ns) - t0);
    const Eigen::Matrix<double, M, 1> w = RdSpline<M>::weights_at(seg.u, 0, dt);
    rows.push_back({seg.first_knot, w});
    for (int i = 0; i < M; ++i) {
      rhs.row(seg.first_knot + i) += w(i) * s.gyro.transpose();
      for (int j = 0; j < M; ++j) trip.emplace_back(seg.first_knot + i, seg.first_knot + j, w(i) * w(j));
    }
  }
  Eigen::SparseMatrix<double> A(knots, knots);
  A.setFromTriplets(trip.begin(), trip.end());
  for (int i = 0; i < knots; ++i) A.coeffRef(i, i) += 1e-9;  // a knot past the last sample
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
  if (ldlt.info() != Eigen::Success) return std::nan("");
  const Eigen::MatrixXd x = ldlt.solve(rhs);
  double ssr = 0.0;
  for (std::size_t k = 0; k < imu.size(); ++k) {
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    for (int i = 0; i < M; ++i) v += rows[k].second(i) * x.row(rows[k].first + i).transpose();
    ssr += (v - imu[k].gyro).squaredNorm();
  }
  return std::sqrt(ssr / (3.0 * (n - knots)));
}

}  // namespace

double choose_knot_spacing(const std::vector<CamImuSample>& imu, int spline_order, double gyro_sigma,
                           std::vector<double>* fit_sigma) {
  std::vector<double> sig;
  for (double dt : kKnotSpacingCandidates) {
    if (imu.size() < 10) {
      sig.push_back(std::nan(""));
      continue;
    }
    // The angular velocity of an order-N rotation spline is of order N - 1.
    sig.push_back(spline_order <= 4   ? gyro_fit_sigma<3>(imu, dt)
                  : spline_order == 5 ? gyro_fit_sigma<4>(imu, dt)
                                      : gyro_fit_sigma<5>(imu, dt));
  }
  if (fit_sigma) *fit_sigma = sig;
  double finest = std::nan("");
  for (double v : sig)
    if (std::isfinite(v)) finest = v;  // the last finite one: the finest the data allow
  const double limit = std::max(3.0 * finest, 1.5 * gyro_sigma);
  for (std::size_t i = 0; i < sig.size(); ++i)
    if (std::isfinite(sig[i]) && sig[i] <= limit) return kKnotSpacingCandidates[i];
  return kKnotSpacingCandidates[0];
}

}  // namespace imucal::calib
