// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The projections and the FOV distortion of the camera models beyond the pinhole
// (core/camera_model.hpp), as free functions templated on the scalar (Ceres Jets). Each maps a
// point p = (x, y, z) of the camera frame to normalised image coordinates m, to which the
// distortion and then the focal lengths and principal point are applied; each has a closed-form
// inverse (lift) from undistorted normalised coordinates to a ray.
//
//   omni (Mei's unified model, Kalibr's OmniProjection), e = [xi]:
//     d = |p|,  m = (x, y) / (z + xi d);      defined where z > -w d, w = xi <= 1 ? xi : 1 / xi.
//   eucm (extended unified, Khomutenko et al. 2016), e = [alpha, beta]:
//     rho = sqrt(beta (x^2 + y^2) + z^2),  m = (x, y) / (alpha rho + (1 - alpha) z);
//     defined where z > -w rho, w = alpha <= 1/2 ? alpha / (1 - alpha) : (1 - alpha) / alpha.
//   ds (double sphere, Usenko et al. 2018), e = [xi, alpha]:
//     d1 = |p|,  zs = xi d1 + z,  d2 = sqrt(x^2 + y^2 + zs^2),  m = (x, y) / (alpha d2 + (1 - alpha) zs);
//     defined where z > -w2 d1, w1 as eucm's w, w2 = (w1 + xi) / sqrt(2 w1 xi + xi^2 + 1).
//   fov distortion (Devernay and Faugeras 2001, Kalibr's FovDistortion), d = [w]:
//     r = |m|,  m_d = m atan(2 r tan(w / 2)) / (w r);  inverse r = tan(r_d w) / (2 tan(w / 2)).
// Kalibr's and basalt's equations; written here from the papers' forms.

#include <Eigen/Core>
#include <cmath>
#include <numbers>

namespace imucal {

/// FOV distortion of normalised coordinates, d = {w}. For |w| below 1e-4 the factor's series
/// 1 + w^2 (1/12 - r^2/3) (exact to O(w^4)) keeps the derivative in w finite at w = 0.
template <class T>
void distort_fov(const T* d, const T& x, const T& y, T* xd, T* yd) {
  using std::abs;
  using std::atan;
  using std::sqrt;
  using std::tan;
  const T& w = d[0];
  const T r2 = x * x + y * y;
  T factor;
  if (abs(w) < T(1e-4)) {
    factor = T(1) + w * w * (T(1.0 / 12.0) - r2 / T(3));
  } else if (r2 < T(1e-16)) {
    // atan(r t) / (w r) -> t / w as r -> 0.
    factor = T(2) * tan(w / T(2)) / w;
  } else {
    const T r = sqrt(r2);
    factor = atan(r * T(2) * tan(w / T(2))) / (w * r);
  }
  *xd = x * factor;
  *yd = y * factor;
}

/// Inverse of distort_fov; false where no undistorted point maps there (|r_d w| >= pi/2).
template <class T>
bool undistort_fov(const T* d, const Eigen::Matrix<T, 2, 1>& md, Eigen::Matrix<T, 2, 1>* m) {
  using std::abs;
  using std::tan;
  const T& w = d[0];
  const T rd = md.norm();
  if (abs(w) < T(1e-4) || rd < T(1e-16)) {
    // The series' inverse to the same order, and the centre.
    const T factor =
        abs(w) < T(1e-4) ? T(1) + w * w * (T(1.0 / 12.0) - rd * rd / T(3)) : T(2) * tan(w / T(2)) / w;
    *m = md / factor;
    return true;
  }
  if (!(abs(rd * w) < T(std::numbers::pi / 2))) return false;
  *m = md * (tan(rd * w) / (T(2) * tan(w / T(2)) * rd));
  return true;
}

/// The bound w of a unified-type projection's domain z > -w d, for the parameter a (omni: xi;
/// eucm and ds: alpha / (1 - alpha), written symmetric in alpha about 1/2).
template <class T>
T unified_domain_bound_alpha(const T& alpha) {
  return alpha > T(0.5) ? (T(1) - alpha) / alpha : alpha / (T(1) - alpha);
}

/// omni: point -> normalised m; false outside the projection's domain.
template <class T>
bool project_omni(const T* e, const Eigen::Matrix<T, 3, 1>& p, Eigen::Matrix<T, 2, 1>* m) {
  const T& xi = e[0];
  const T d = p.norm();
  const T w = xi <= T(1) ? xi : T(1) / xi;
  const T den = p.z() + xi * d;
  if (!(den > T(0))) return false;
  *m = Eigen::Matrix<T, 2, 1>(p.x() / den, p.y() / den);
  return p.z() > -w * d;
}

template <class T>
bool project_eucm(const T* e, const Eigen::Matrix<T, 3, 1>& p, Eigen::Matrix<T, 2, 1>* m) {
  using std::sqrt;
  const T& alpha = e[0];
  const T& beta = e[1];
  const T rho = sqrt(beta * (p.x() * p.x() + p.y() * p.y()) + p.z() * p.z());
  const T den = alpha * rho + (T(1) - alpha) * p.z();
  if (!(den > T(0))) return false;
  *m = Eigen::Matrix<T, 2, 1>(p.x() / den, p.y() / den);
  return p.z() > -unified_domain_bound_alpha(alpha) * rho;
}

template <class T>
bool project_ds(const T* e, const Eigen::Matrix<T, 3, 1>& p, Eigen::Matrix<T, 2, 1>* m) {
  using std::sqrt;
  const T& xi = e[0];
  const T& alpha = e[1];
  const T r2 = p.x() * p.x() + p.y() * p.y();
  const T d1 = p.norm();
  const T zs = xi * d1 + p.z();
  const T d2 = sqrt(r2 + zs * zs);
  const T den = alpha * d2 + (T(1) - alpha) * zs;
  if (!(den > T(0))) return false;
  *m = Eigen::Matrix<T, 2, 1>(p.x() / den, p.y() / den);
  const T w1 = unified_domain_bound_alpha(alpha);
  const T w2 = (w1 + xi) / sqrt(T(2) * w1 * xi + xi * xi + T(1));
  return p.z() > -w2 * d1;
}

/// omni: undistorted normalised m -> unit ray; false where m is no image of a point.
template <class T>
bool lift_omni(const T* e, const Eigen::Matrix<T, 2, 1>& m, Eigen::Matrix<T, 3, 1>* ray) {
  using std::sqrt;
  const T& xi = e[0];
  const T r2 = m.squaredNorm();
  const T disc = T(1) + (T(1) - xi * xi) * r2;
  if (!(disc >= T(0))) return false;
  const T mz = T(1) - xi * (r2 + T(1)) / (xi + sqrt(disc));
  *ray = Eigen::Matrix<T, 3, 1>(m.x(), m.y(), mz).normalized();
  return true;
}

template <class T>
bool lift_eucm(const T* e, const Eigen::Matrix<T, 2, 1>& m, Eigen::Matrix<T, 3, 1>* ray) {
  using std::sqrt;
  const T& alpha = e[0];
  const T& beta = e[1];
  const T r2 = m.squaredNorm();
  const T disc = T(1) - (T(2) * alpha - T(1)) * beta * r2;
  if (!(disc >= T(0))) return false;
  const T mz = (T(1) - alpha * alpha * beta * r2) / (alpha * sqrt(disc) + (T(1) - alpha));
  *ray = Eigen::Matrix<T, 3, 1>(m.x(), m.y(), mz).normalized();
  return true;
}

template <class T>
bool lift_ds(const T* e, const Eigen::Matrix<T, 2, 1>& m, Eigen::Matrix<T, 3, 1>* ray) {
  using std::sqrt;
  const T& xi = e[0];
  const T& alpha = e[1];
  const T r2 = m.squaredNorm();
  const T disc = T(1) - (T(2) * alpha - T(1)) * r2;
  if (!(disc >= T(0))) return false;
  const T mz = (T(1) - alpha * alpha * r2) / (alpha * sqrt(disc) + T(1) - alpha);
  const T disc2 = mz * mz + (T(1) - xi * xi) * r2;
  if (!(disc2 >= T(0))) return false;
  const T k = (mz * xi + sqrt(disc2)) / (mz * mz + r2);
  *ray = Eigen::Matrix<T, 3, 1>(k * m.x(), k * m.y(), k * mz - xi).normalized();
  return true;
}

}  // namespace imucal
