// SPDX-License-Identifier: BSD-3-Clause
// The six faces of calib/static_faces.hpp: face assignment, missing faces in the operator's
// words, and the known-orientation fit against a model it must recover exactly (no noise), with
// sigmas that follow the noise when there is some.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "calib/static_faces.hpp"

namespace imucal::calib {
namespace {

Eigen::Vector3d axis(int face) {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  e[face / 2] = face % 2 == 0 ? 1.0 : -1.0;
  return e;
}

struct Truth {
  TedaldiTriad triad;  // a_O = T K (raw + b)
  Eigen::Matrix3d Q;   // faces' frame from O
};

Truth truth() {
  Truth t;
  t.triad.T = accel_misalignment(Eigen::Vector3d(0.012, -0.02, 0.007));
  t.triad.scale =
      Eigen::Vector3d(1.0 / 8192.0 * 9.81 * 1.01, 1.0 / 8192.0 * 9.81 * 0.98, 1.0 / 8192.0 * 9.81);
  t.triad.bias = Eigen::Vector3d(-120.0, 35.0, 410.0);
  t.Q = Eigen::AngleAxisd(0.03, Eigen::Vector3d(1, 2, -1).normalized()).toRotationMatrix();
  return t;
}

/// Raw means of poses lying on `faces`: raw = (T K)^-1 Q^T g e_f - b.
std::vector<Eigen::Vector3d> raw_means(const Truth& t, const std::vector<int>& faces, double g, double noise,
                                       unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise);
  std::vector<Eigen::Vector3d> out;
  for (int f : faces) {
    const Eigen::Vector3d a = t.Q.transpose() * (g * axis(f));
    out.push_back(t.triad.TK().inverse() * a - t.triad.bias + Eigen::Vector3d(n(rng), n(rng), n(rng)));
  }
  return out;
}

TEST(StaticFaces, FacesAreNamedAsAnOperatorPutsTheRigDown) {
  EXPECT_EQ(face_name(0), "+x up");
  EXPECT_EQ(face_name(5), "-z up");
  EXPECT_EQ(face_in_words(3), "-Y up (resting on its +Y face)");
  const std::vector<int> faces =
      assign_faces({Eigen::Vector3d(0.1, 0, 1).normalized(), Eigen::Vector3d(-1, 0.05, 0).normalized(),
                    Eigen::Vector3d(1, 1, 0).normalized()},
                   15.0 * M_PI / 180.0);
  EXPECT_EQ(faces, (std::vector<int>{4, 1, -1}));  // the last one is 45 deg from both x and y
  const auto counts = face_counts(faces);
  EXPECT_EQ(missing_faces_in_words(counts),
            "+X up (resting on its -X face), +Y up (resting on its -Y face), -Y up (resting on its +Y face), "
            "-Z up (resting on its +Z face)");
  EXPECT_EQ(missing_faces_in_words({1, 1, 1, 1, 1, 1}), "");
}

TEST(StaticFaces, KnownOrientationFitRecoversTheModelAndTheRotation) {
  const Truth t = truth();
  const std::vector<int> faces = {4, 3, 5, 2, 0, 1, 4, 0};
  const double g = 9.81;
  const auto means = raw_means(t, faces, g, 0.0, 1);
  const KnownOrientationFit fit = fit_known_orientation(means, faces, g);
  ASSERT_TRUE(fit.ok) << fit.error;
  EXPECT_TRUE(fit.triad.T.isApprox(t.triad.T, 1e-9)) << fit.triad.T;
  EXPECT_TRUE(fit.triad.scale.isApprox(t.triad.scale, 1e-9));
  EXPECT_TRUE(fit.triad.bias.isApprox(t.triad.bias, 1e-9)) << fit.triad.bias.transpose();
  EXPECT_TRUE(fit.Q.isApprox(t.Q, 1e-9));
  EXPECT_NEAR(fit.q_angle_rad, 0.03, 1e-9);
  EXPECT_LT(fit.direction_rms_rad, 1e-9);
  EXPECT_EQ(fit.residuals, 24);
  EXPECT_EQ(fit.parameters, 12);
}

TEST(StaticFaces, KnownOrientationSigmasFollowTheNoise) {
  // 24 poses, 4 per face, noise of 2 counts on each mean: over 200 draws, the spread of each
  // estimate agrees with the RMS of its reported sigma within 25 %.
  const Truth t = truth();
  std::vector<int> faces;
  for (int k = 0; k < 4; ++k)
    for (int f = 0; f < 6; ++f) faces.push_back(f);
  const double g = 9.81;
  Eigen::Matrix<double, 9, 1> sum_sq_err = Eigen::Matrix<double, 9, 1>::Zero(), sum_var = sum_sq_err;
  const int draws = 200;
  for (int d = 0; d < draws; ++d) {
    const KnownOrientationFit fit = fit_known_orientation(raw_means(t, faces, g, 2.0, 100 + d), faces, g);
    ASSERT_TRUE(fit.ok) << fit.error;
    Eigen::Matrix<double, 9, 1> err;
    err << accel_angles(fit.triad.T) - accel_angles(t.triad.T), fit.triad.scale - t.triad.scale,
        fit.triad.bias - t.triad.bias;
    sum_sq_err += err.cwiseAbs2();
    sum_var += fit.covariance.diagonal();
  }
  for (int i = 0; i < 9; ++i) {
    const double ratio = std::sqrt(sum_var[i] / sum_sq_err[i]);
    EXPECT_GT(ratio, 0.75) << "parameter " << i;
    EXPECT_LT(ratio, 1.25) << "parameter " << i;
  }
}

TEST(StaticFaces, KnownOrientationNeedsEveryFaceAndRefusesAMirror) {
  const Truth t = truth();
  const std::vector<int> five = {4, 3, 5, 2, 0};
  const KnownOrientationFit missing = fit_known_orientation(raw_means(t, five, 9.81, 0.0, 1), five, 9.81);
  EXPECT_FALSE(missing.ok);
  EXPECT_NE(missing.error.find("-X up"), std::string::npos) << missing.error;
  // x's faces swapped: the matrix that fits mirrors an axis, which no accelerometer does.
  const std::vector<int> faces = {4, 3, 5, 2, 0, 1};
  const std::vector<int> swapped = {4, 3, 5, 2, 1, 0};
  const KnownOrientationFit mirror = fit_known_orientation(raw_means(t, faces, 9.81, 0.0, 1), swapped, 9.81);
  EXPECT_FALSE(mirror.ok);
  EXPECT_NE(mirror.error.find("mirrors"), std::string::npos) << mirror.error;
}

}  // namespace
}  // namespace imucal::calib
