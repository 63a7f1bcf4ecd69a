// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The residual of the single-camera solve (calib/camera_intrinsics.cpp): one target point seen in
// one view, in pixels, with the camera's parameters and the view's pose free. Internal to that
// solve and its tests.
//
//   p_cam = R(q) P + t      (q = qw qx qy qz in Ceres' order, normalised as Ceres' own
//                            QuaternionRotatePoint does),
//   r     = pi(K, e, d; p_cam) - u.
//
// Parameter blocks: intrinsics fu fv pu pv (4), the projection's parameters (2), distortion (4),
// pose qw qx qy qz tx ty tz (7). ReprojectionFunctor is the residual written once over any scalar
// type: automatic differentiation of it over all 17 parameters is the reference the tests compare
// with. ReprojectionCost evaluates the same residual with its Jacobians in stages: the rotation's
// analytically, the projection's in the camera point and its 2 parameters with 5 dual numbers,
// the distortion's in the normalised point and its 4 coefficients with 6, the pixel's
// analytically, and their products; the same derivatives as the reference (to rounding). The
// reference's dual numbers were about half of the solve's time; with the stages `calibrate
// camera` on the DAVIS recording took 8.2 s of CPU instead of 14.3 s (docs/benchmarks.md).

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>

#include "calib/so3.hpp"
#include "core/camera_model.hpp"

namespace imucal::calib {

/// The residual over any scalar type (double, or ceres::Jet for the reference derivatives).
struct ReprojectionFunctor {
  ReprojectionFunctor(const Eigen::Vector3d& p_target, const Eigen::Vector2d& px, CameraModelKind model)
      : p_target_(p_target), px_(px), model_(model) {}

  template <class T>
  bool operator()(const T* intrinsics, const T* projection, const T* distortion, const T* pose,
                  T* residual) const {
    const T p[3] = {T(p_target_.x()), T(p_target_.y()), T(p_target_.z())};
    Eigen::Matrix<T, 3, 1> c;
    ceres::QuaternionRotatePoint(pose, p, c.data());
    c += Eigen::Matrix<T, 3, 1>(pose[4], pose[5], pose[6]);
    const auto camera = CameraModelT<T>::from_params(model_, intrinsics, projection, distortion, 0, 0);
    // Outside the projection's domain (behind a pinhole camera) the projection means nothing:
    // the step is refused.
    Eigen::Matrix<T, 2, 1> m;
    bool computed = false;
    if (!camera.normalise(c, &m, &computed)) return false;
    const Eigen::Matrix<T, 2, 1> uv = camera.to_pixel(camera.distort(m));
    residual[0] = uv.x() - T(px_.x());
    residual[1] = uv.y() - T(px_.y());
    return true;
  }

  Eigen::Vector3d p_target_;
  Eigen::Vector2d px_;
  CameraModelKind model_;
};

/// The same residual with staged Jacobians (see the file's comment).
class ReprojectionCost final : public ceres::SizedCostFunction<2, 4, 2, 4, 7> {
 public:
  ReprojectionCost(const Eigen::Vector3d& p_target, const Eigen::Vector2d& px, CameraModelKind model)
      : p_target_(p_target), px_(px), model_(model) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* intr = parameters[0];
    const double* proj = parameters[1];
    const double* dist = parameters[2];
    const double* pose = parameters[3];
    const Eigen::Map<const Eigen::Vector4d> q(pose);
    const double norm = q.norm();
    const Eigen::Vector4d u = q / norm;
    const Eigen::Vector3d v = u.tail<3>();
    const Eigen::Vector3d& P = p_target_;
    const Eigen::Vector3d vxp = v.cross(P);
    const Eigen::Vector3d c =
        P + 2.0 * u(0) * vxp + 2.0 * v.cross(vxp) + Eigen::Map<const Eigen::Vector3d>(pose + 4);

    const bool want = jacobians != nullptr;
    Eigen::Vector2d m, md;
    Eigen::Matrix<double, 2, 3> m_c;
    Eigen::Matrix2d m_e, md_m;
    Eigen::Matrix<double, 2, 4> md_d;
    if (!want) {
      const auto camera = CameraModel::from_params(model_, intr, proj, dist, 0, 0);
      bool computed = false;
      if (!camera.normalise(c, &m, &computed)) return false;
      md = camera.distort(m);
    } else {
      if (!normalise_with_jacobian(proj, c, &m, &m_c, &m_e)) return false;
      distort_with_jacobian(dist, m, &md, &md_m, &md_d);
    }
    residuals[0] = intr[0] * md.x() + intr[2] - px_.x();
    residuals[1] = intr[1] * md.y() + intr[3] - px_.y();
    if (!want) return true;

    const Eigen::Matrix2d f = Eigen::Vector2d(intr[0], intr[1]).asDiagonal();
    const Eigen::Matrix2d uv_m = f * md_m;
    if (jacobians[0]) {
      Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> J(jacobians[0]);
      J << md.x(), 0.0, 1.0, 0.0, 0.0, md.y(), 0.0, 1.0;
    }
    if (jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[1]);
      J = uv_m * m_e;
    }
    if (jacobians[2]) {
      Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> J(jacobians[2]);
      J = f * md_d;
    }
    if (jacobians[3]) {
      const Eigen::Matrix<double, 2, 3> uv_c = uv_m * m_c;
      // d c / d u for the unit quaternion u = (w, v): c = P + 2w (v x P) + 2 v x (v x P).
      Eigen::Matrix<double, 3, 4> c_u;
      c_u.col(0) = 2.0 * vxp;
      c_u.rightCols<3>() = -2.0 * u(0) * so3::hat(P) + 2.0 * (v.dot(P) * Eigen::Matrix3d::Identity() +
                                                              v * P.transpose() - 2.0 * P * v.transpose());
      // u = q / |q|: d u / d q = (I - u u^T) / |q|.
      const Eigen::Matrix4d u_q = (Eigen::Matrix4d::Identity() - u * u.transpose()) / norm;
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> J(jacobians[3]);
      J.leftCols<4>() = uv_c * c_u * u_q;
      J.rightCols<3>() = uv_c;
    }
    return true;
  }

 private:
  /// The normalised point m of camera point c and its Jacobians in c and the projection's 2
  /// parameters; false outside the projection's domain.
  bool normalise_with_jacobian(const double* proj, const Eigen::Vector3d& c, Eigen::Vector2d* m,
                               Eigen::Matrix<double, 2, 3>* m_c, Eigen::Matrix2d* m_e) const {
    using Jet = ceres::Jet<double, 5>;
    const Jet e[2] = {Jet(proj[0], 3), Jet(proj[1], 4)};
    const Jet zero[4] = {Jet(0.0), Jet(0.0), Jet(0.0), Jet(0.0)};
    const auto camera = CameraModelT<Jet>::from_params(model_, zero, e, zero, 0, 0);
    const Eigen::Matrix<Jet, 3, 1> cj(Jet(c.x(), 0), Jet(c.y(), 1), Jet(c.z(), 2));
    Eigen::Matrix<Jet, 2, 1> mj;
    bool computed = false;
    if (!camera.normalise(cj, &mj, &computed)) return false;
    for (int r = 0; r < 2; ++r) {
      (*m)(r) = mj(r).a;
      m_c->row(r) = mj(r).v.head<3>().transpose();
      m_e->row(r) = mj(r).v.tail<2>().transpose();
    }
    return true;
  }

  /// The distorted point md of normalised point m and its Jacobians in m and the 4 coefficients.
  void distort_with_jacobian(const double* dist, const Eigen::Vector2d& m, Eigen::Vector2d* md,
                             Eigen::Matrix2d* md_m, Eigen::Matrix<double, 2, 4>* md_d) const {
    using Jet = ceres::Jet<double, 6>;
    const Jet d[4] = {Jet(dist[0], 2), Jet(dist[1], 3), Jet(dist[2], 4), Jet(dist[3], 5)};
    const Jet zero[4] = {Jet(0.0), Jet(0.0), Jet(0.0), Jet(0.0)};
    const auto camera = CameraModelT<Jet>::from_params(model_, zero, zero, d, 0, 0);
    const Eigen::Matrix<Jet, 2, 1> out =
        camera.distort(Eigen::Matrix<Jet, 2, 1>(Jet(m.x(), 0), Jet(m.y(), 1)));
    for (int r = 0; r < 2; ++r) {
      (*md)(r) = out(r).a;
      md_m->row(r) = out(r).v.head<2>().transpose();
      md_d->row(r) = out(r).v.tail<4>().transpose();
    }
  }

  Eigen::Vector3d p_target_;
  Eigen::Vector2d px_;
  CameraModelKind model_;
};

}  // namespace imucal::calib
