// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Camera models as small value types templated on the scalar, so that Ceres autodiff can
// evaluate them on Jets. Kalibr's models, a projection and a distortion:
//   pinhole-radtan: pinhole + radial-tangential (k1, k2, p1, p2), the same as OpenCV's
//                   4-coefficient model in cv::projectPoints;
//   pinhole-equi:   pinhole + equidistant (k1..k4), the same as cv::fisheye;
//   pinhole-fov:    pinhole + FOV distortion (w), Devernay and Faugeras;
//   omni-none, omni-radtan: Mei's unified model (xi), without or with radtan;
//   eucm-none:      the extended unified model (alpha, beta);
//   ds-none:        the double sphere model (xi, alpha), Usenko et al. 2018.
// The projections other than the pinhole, their domains and inverses: core/camera_projection.hpp.
// Fields follow Kalibr's camchain YAML: camera_model (pinhole | omni | eucm | ds), intrinsics
// [fu, fv, pu, pv] after the projection's parameters (omni [xi, fu, fv, pu, pv], eucm [alpha,
// beta, fu, ...], ds [xi, alpha, fu, ...]), distortion_model (radtan | equidistant | fov | none),
// distortion_coeffs (4, 4, [w], []), resolution [width, height].
// Pixel convention (OpenCV, Kalibr): integer coordinates are pixel centres, so the image covers
// [-0.5, width - 0.5) x [-0.5, height - 0.5).

#include <Eigen/Core>
#include <cmath>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "core/camera_projection.hpp"
#include "core/result.hpp"

namespace YAML {
class Node;
}

namespace imucal {

enum class DistortionModel { kRadtan, kEquidistant, kNone, kFov };
enum class ProjectionModel { kPinhole, kOmni, kEucm, kDs };

/// A camera model: its projection and distortion (Kalibr's "ds-none" is {kDs, kNone}).
struct CameraModelKind {
  ProjectionModel projection = ProjectionModel::kPinhole;
  DistortionModel distortion = DistortionModel::kRadtan;
  bool operator==(const CameraModelKind&) const = default;
};

/// How many of the projection's parameters (of 2) and of the distortion's (of 4) a model uses:
/// pinhole 0, omni 1 (xi), eucm 2 (alpha, beta), ds 2 (xi, alpha); radtan and equidistant 4,
/// fov 1 (w), none 0. The unused entries are held at 0 by the solves.
int projection_param_count(ProjectionModel model);
int distortion_coeff_count(DistortionModel model);
/// The models imucal calibrates, Kalibr's: pinhole with radtan, equidistant, fov or none; omni
/// with none or radtan; eucm and ds with none.
bool camera_model_supported(CameraModelKind kind);
/// Kalibr's names: "pinhole", "omni", "eucm", "ds".
const char* projection_model_name(ProjectionModel model);
/// Kalibr's option name: "pinhole-radtan", "pinhole-equi", "pinhole-fov", "pinhole-none",
/// "omni-none", "omni-radtan", "eucm-none", "ds-none".
std::string camera_model_name(CameraModelKind kind);
/// The names of the projection's parameters in Kalibr's intrinsics order ({"xi"}, ...).
std::vector<std::string> projection_param_names(ProjectionModel model);
/// The names of the distortion's coefficients ({"k1", "k2", "p1", "p2"}, ..., {"w"}, {}).
std::vector<std::string> distortion_coeff_names(DistortionModel model);
/// Kalibr's intrinsics vector: the projection's used parameters, then fu fv pu pv (also for
/// their sigmas, in the same order).
std::vector<double> kalibr_intrinsics(ProjectionModel model, const Eigen::Vector4d& intrinsics,
                                      const Eigen::Vector2d& projection_params);
/// Kalibr's distortion_coeffs vector: the used coefficients.
std::vector<double> kalibr_distortion(DistortionModel model, const Eigen::Vector4d& coeffs);
/// The model's parameters in Kalibr's order (intrinsics, then distortion_coeffs) as indices
/// into the 10-vector [fu fv pu pv, projection (2), distortion (4)] the solves hold, and
/// their names ("xi", "alpha", "fu", ..., "k1", ...).
std::vector<int> kalibr_parameter_indices(CameraModelKind kind);
std::vector<std::string> kalibr_parameter_names(CameraModelKind kind);
/// "[xi, alpha, fu, fv, pu, pv]" and so on, for messages and help.
std::string kalibr_intrinsics_layout(ProjectionModel model);
/// Kalibr's names back: "pinhole" ...; "radtan", "equidistant" (also "equi"), "fov", "none";
/// "ds-none" ... (only supported combinations). nullopt when unknown.
std::optional<ProjectionModel> parse_projection_name(const std::string& name);
std::optional<DistortionModel> parse_distortion_name(const std::string& name);
std::optional<CameraModelKind> parse_camera_model_name(const std::string& name);

/// How the image rows are exposed. A global shutter exposes every row at once; a rolling shutter
/// starts row after row, `line_delay_s` apart, in the readout direction, so that image row v is
/// seen at t_stamp + row_time(v). The frame's stamp refers to one row (`stamp_row`): the first
/// row read out, the middle row or the last. Kalibr's camchain has no such fields; imucal writes
/// them beside Kalibr's (shutter, line_delay_s, readout_direction, stamp_row: docs/conventions.md §5).
struct Shutter {
  enum class Kind { kGlobal, kRolling };
  enum class Readout { kTopToBottom, kBottomToTop };
  enum class StampRow { kFirst, kMiddle, kLast };
  Kind kind = Kind::kGlobal;
  double line_delay_s = 0.0;  // rolling: time between the starts of consecutive rows
  Readout readout = Readout::kTopToBottom;
  StampRow stamp_row = StampRow::kFirst;

  bool rolling() const { return kind == Kind::kRolling; }
  /// The readout position (0 = first row read) of image row coordinate v (pixels, centres at
  /// integers) minus that of the stamped row, for a sensor of `height` rows: row_time(v) =
  /// row_offset(v) * line_delay_s. Zero for a global shutter.
  double row_offset(double v, int height) const {
    if (!rolling()) return 0.0;
    const double last = static_cast<double>(height - 1);
    const double line = readout == Readout::kTopToBottom ? v : last - v;
    const double ref = stamp_row == StampRow::kFirst    ? 0.0
                       : stamp_row == StampRow::kMiddle ? 0.5 * last
                                                        : last;
    return line - ref;
  }
  double row_time(double v, int height) const { return row_offset(v, height) * line_delay_s; }
  /// The whole frame's readout, s (0 for a global shutter).
  double readout_s(int height) const { return rolling() ? line_delay_s * (height - 1) : 0.0; }
};
const char* shutter_kind_name(Shutter::Kind kind);        // "global", "rolling"
const char* readout_name(Shutter::Readout readout);       // "top_to_bottom", "bottom_to_top"
const char* stamp_row_name(Shutter::StampRow stamp_row);  // "first", "middle", "last"

/// The row a camera stream's stamps refer to, from the session log's timestamp_source:
/// "mid-exposure" (the backends move start-of-exposure stamps there: V4L2's
/// V4L2_BUF_FLAG_TSTAMP_SRC_SOE, libcamera's SensorTimestamp) and "start-of-exposure" refer to
/// the first row read out, "end-of-frame" (V4L2's TSTAMP_SRC_EOF, a UVC camera's default) to the
/// last. Empty for a source that does not say ("dataset", "", unknown names).
std::optional<Shutter::StampRow> stamp_row_of_timestamp_source(const std::string& timestamp_source);

/// Kalibr's name: "radtan", "equidistant", "none" or "fov".
const char* distortion_model_name(DistortionModel model);

/// Radial-tangential distortion of normalised coordinates (x, y) = (X/Z, Y/Z); d = {k1, k2, p1, p2}.
///   r2 = x^2 + y^2, radial = 1 + k1 r2 + k2 r2^2,
///   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2),  yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y.
template <class T>
void distort_radtan(const T* d, const T& x, const T& y, T* xd, T* yd) {
  const T r2 = x * x + y * y;
  const T radial = T(1) + d[0] * r2 + d[1] * r2 * r2;
  const T two_xy = T(2) * x * y;
  *xd = x * radial + d[2] * two_xy + d[3] * (r2 + T(2) * x * x);
  *yd = y * radial + d[2] * (r2 + T(2) * y * y) + d[3] * two_xy;
}

/// Equidistant distortion of normalised coordinates; d = {k1, k2, k3, k4}.
///   r = |(x, y)|, theta = atan(r), theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),
///   (xd, yd) = (theta_d / r) (x, y)   (-> (x, y) as r -> 0).
template <class T>
void distort_equidistant(const T* d, const T& x, const T& y, T* xd, T* yd) {
  using std::atan;
  using std::sqrt;
  const T r2 = x * x + y * y;
  // Below this radius theta_d / r = 1 + (k1 - 1/3) r^2 + O(r^4) is 1 to double precision; the
  // branch also keeps sqrt away from 0, where its derivative (for Jets) is infinite.
  if (r2 < T(1e-16)) {
    *xd = x;
    *yd = y;
    return;
  }
  const T r = sqrt(r2);
  const T theta = atan(r);
  const T t2 = theta * theta;
  const T theta_d = theta * (T(1) + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))));
  const T scale = theta_d / r;
  *xd = x * scale;
  *yd = y * scale;
}

/// A camera: its projection (pinhole, omni, eucm, ds) and distortion (radtan, equidistant, fov,
/// none), the combinations of camera_model_supported.
template <class T>
struct CameraModelT {
  using Vec2 = Eigen::Matrix<T, 2, 1>;
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  using Vec4 = Eigen::Matrix<T, 4, 1>;

  ProjectionModel projection = ProjectionModel::kPinhole;
  DistortionModel distortion_model = DistortionModel::kRadtan;
  Vec4 intrinsics = Vec4::Zero();         // fu, fv, pu, pv (pixels)
  Vec2 projection_params = Vec2::Zero();  // omni: xi, 0; eucm: alpha, beta; ds: xi, alpha; pinhole: 0, 0
  Vec4 distortion_coeffs = Vec4::Zero();  // radtan: k1 k2 p1 p2; equidistant: k1 k2 k3 k4; fov: w 0 0 0
  int width = 0;                          // resolution, pixels
  int height = 0;
  Shutter shutter;  // global unless the camera file says rolling

  CameraModelKind kind() const { return {projection, distortion_model}; }

  struct Projection {
    Vec2 px = Vec2::Zero();
    /// The point is in the projection's domain (pinhole: z > 0) and, for radtan, inside the
    /// region where the distortion is one-to-one (d r_d / d r > 0), so the pixel really is where
    /// the point appears.
    bool in_front = false;
    /// The pixel lies on the sensor.
    bool in_image = false;
    bool valid() const { return in_front && in_image; }
  };

  /// Distorts normalised coordinates.
  Vec2 distort(const Vec2& xy) const {
    Vec2 out;
    switch (distortion_model) {
      case DistortionModel::kRadtan:
        distort_radtan(distortion_coeffs.data(), xy.x(), xy.y(), &out.x(), &out.y());
        break;
      case DistortionModel::kEquidistant:
        distort_equidistant(distortion_coeffs.data(), xy.x(), xy.y(), &out.x(), &out.y());
        break;
      case DistortionModel::kFov:
        distort_fov(distortion_coeffs.data(), xy.x(), xy.y(), &out.x(), &out.y());
        break;
      case DistortionModel::kNone:
        out = xy;
        break;
    }
    return out;
  }

  /// Normalised distorted coordinates -> pixel.
  Vec2 to_pixel(const Vec2& xy_distorted) const {
    return Vec2(intrinsics[0] * xy_distorted.x() + intrinsics[2],
                intrinsics[1] * xy_distorted.y() + intrinsics[3]);
  }

  /// Point -> undistorted normalised coordinates; false outside the projection's domain (the
  /// coordinates are still set where the projection's denominator is positive).
  bool normalise(const Vec3& p, Vec2* m, bool* computed) const {
    const T* e = projection_params.data();
    *computed = true;
    switch (projection) {
      case ProjectionModel::kPinhole:
        if (p.z() == T(0)) {
          *computed = false;
          return false;
        }
        *m = Vec2(p.x() / p.z(), p.y() / p.z());
        return p.z() > T(0);
      case ProjectionModel::kOmni:
        *computed = p.z() + e[0] * p.norm() > T(0);
        return project_omni(e, p, m);
      case ProjectionModel::kEucm:
        return (*computed = project_eucm(e, p, m));
      case ProjectionModel::kDs:
        return (*computed = project_ds(e, p, m));
    }
    return false;
  }

  /// Point in the camera frame -> pixel, with validity. The pixel is computed even when the
  /// point is not valid (as cv::projectPoints does), where the projection's denominator is
  /// not zero.
  Projection project(const Vec3& p_cam) const {
    Projection out;
    Vec2 xy;
    bool computed = false;
    const bool in_domain = normalise(p_cam, &xy, &computed);
    if (!computed) return out;
    out.px = to_pixel(distort(xy));
    out.in_front = in_domain;
    if (out.in_front && distortion_model == DistortionModel::kRadtan) {
      const T r2 = xy.squaredNorm();
      const T slope = T(1) + T(3) * distortion_coeffs[0] * r2 + T(5) * distortion_coeffs[1] * r2 * r2;
      out.in_front = slope > T(0);
    }
    out.in_image = out.px.x() >= T(-0.5) && out.px.y() >= T(-0.5) && out.px.x() < T(width) - T(0.5) &&
                   out.px.y() < T(height) - T(0.5);
    return out;
  }

  /// Pixel -> unit ray in the camera frame: the distortion undone (radtan iteratively, Newton,
  /// to 1e-12 in normalised coordinates; the others in closed form or by a scalar Newton), then
  /// the projection's closed-form inverse. Returns false when the pixel lies outside the model's
  /// invertible region or the iteration does not converge. For plain floating-point scalars.
  bool unproject(const Vec2& px, Vec3* ray) const {
    const Vec2 xd((px.x() - intrinsics[2]) / intrinsics[0], (px.y() - intrinsics[3]) / intrinsics[1]);
    if (distortion_model == DistortionModel::kEquidistant) {
      // Pinhole only (camera_model_supported): the ray comes from theta directly.
      return projection == ProjectionModel::kPinhole && unproject_equidistant(xd, ray);
    }
    Vec2 m = xd;
    if (distortion_model == DistortionModel::kRadtan && !undistort_radtan(xd, &m)) return false;
    if (distortion_model == DistortionModel::kFov && !undistort_fov(distortion_coeffs.data(), xd, &m)) {
      return false;
    }
    const T* e = projection_params.data();
    bool ok = false;
    switch (projection) {
      case ProjectionModel::kPinhole:
        *ray = Vec3(m.x(), m.y(), T(1)).normalized();
        ok = true;
        break;
      case ProjectionModel::kOmni:
        ok = lift_omni(e, m, ray);
        break;
      case ProjectionModel::kEucm:
        ok = lift_eucm(e, m, ray);
        break;
      case ProjectionModel::kDs:
        ok = lift_ds(e, m, ray);
        break;
    }
    if (!ok || projection == ProjectionModel::kPinhole) return ok;
    // The lifts invert the formula; the ray must also lie in the projection's domain and map
    // back to m (a unified model with xi > 1 folds part of the plane over).
    Vec2 back;
    bool computed = false;
    return normalise(*ray, &back, &computed) &&
           (back - m).cwiseAbs().maxCoeff() < T(1e-9) * (T(1) + m.norm());
  }

  /// Radtan's inverse by Newton; false outside the one-to-one region or without convergence.
  bool undistort_radtan(const Vec2& xd, Vec2* out) const {
    using std::abs;
    constexpr int kMaxIterations = 100;
    const T tolerance = T(1e-12);
    const T* d = distortion_coeffs.data();
    Vec2 xy = xd;
    for (int i = 0; i < kMaxIterations; ++i) {
      Vec2 f;
      distort_radtan(d, xy.x(), xy.y(), &f.x(), &f.y());
      f -= xd;
      if (abs(f.x()) < tolerance && abs(f.y()) < tolerance) {
        const T r2 = xy.squaredNorm();
        if (T(1) + T(3) * d[0] * r2 + T(5) * d[1] * r2 * r2 <= T(0)) return false;
        *out = xy;
        return true;
      }
      // Jacobian of the distortion at xy.
      const T x = xy.x();
      const T y = xy.y();
      const T r2 = x * x + y * y;
      const T radial = T(1) + d[0] * r2 + d[1] * r2 * r2;
      const T dradial = T(2) * d[0] + T(4) * d[1] * r2;  // d radial / d r2 * 2
      const T j00 = radial + x * dradial * x + T(2) * d[2] * y + T(6) * d[3] * x;
      const T j01 = x * dradial * y + T(2) * d[2] * x + T(2) * d[3] * y;
      const T j10 = y * dradial * x + T(2) * d[2] * x + T(2) * d[3] * y;
      const T j11 = radial + y * dradial * y + T(6) * d[2] * y + T(2) * d[3] * x;
      const T det = j00 * j11 - j01 * j10;
      if (!(abs(det) > T(1e-300))) return false;
      xy.x() -= (j11 * f.x() - j01 * f.y()) / det;
      xy.y() -= (-j10 * f.x() + j00 * f.y()) / det;
      if (!std::isfinite(static_cast<double>(xy.x())) || !std::isfinite(static_cast<double>(xy.y()))) {
        return false;
      }
    }
    return false;
  }

  /// Equidistant: solve theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8) = r_d for theta in [0, pi/2).
  bool unproject_equidistant(const Vec2& xd, Vec3* ray) const {
    using std::abs;
    using std::cos;
    using std::sin;
    constexpr int kMaxIterations = 100;
    const T tolerance = T(1e-12);
    const T rd = xd.norm();
    if (rd < T(1e-16)) {
      *ray = Vec3(xd.x(), xd.y(), T(1)).normalized();
      return true;
    }
    const T* k = distortion_coeffs.data();
    const T half_pi = T(std::numbers::pi / 2);
    T theta = rd < half_pi ? rd : T(1.5);
    for (int i = 0; i < kMaxIterations; ++i) {
      const T t2 = theta * theta;
      const T f = theta * (T(1) + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) - rd;
      const T df = T(1) + t2 * (T(3) * k[0] + t2 * (T(5) * k[1] + t2 * (T(7) * k[2] + t2 * T(9) * k[3])));
      if (abs(f) < tolerance) {
        if (!(theta >= T(0)) || theta >= half_pi || df <= T(0)) return false;
        const T s = sin(theta) / rd;
        *ray = Vec3(xd.x() * s, xd.y() * s, cos(theta));
        return true;
      }
      if (!(df > T(0))) return false;
      theta -= f / df;
      if (!std::isfinite(static_cast<double>(theta))) return false;
    }
    return false;
  }

  /// The same camera over another scalar (e.g. Jets with constant intrinsics).
  template <class U>
  CameraModelT<U> cast() const {
    CameraModelT<U> out;
    out.projection = projection;
    out.distortion_model = distortion_model;
    out.intrinsics = intrinsics.template cast<U>();
    out.projection_params = projection_params.template cast<U>();
    out.distortion_coeffs = distortion_coeffs.template cast<U>();
    out.width = width;
    out.height = height;
    out.shutter = shutter;
    return out;
  }

  /// A camera whose intrinsics (4), projection parameters (2) and distortion (4) are parameter
  /// blocks (Ceres: const T* blocks).
  static CameraModelT from_params(CameraModelKind kind, const T* intrinsics4, const T* projection2,
                                  const T* distortion4, int width, int height) {
    CameraModelT out;
    out.projection = kind.projection;
    out.distortion_model = kind.distortion;
    out.intrinsics = Eigen::Map<const Vec4>(intrinsics4);
    out.projection_params = Eigen::Map<const Vec2>(projection2);
    out.distortion_coeffs = Eigen::Map<const Vec4>(distortion4);
    out.width = width;
    out.height = height;
    return out;
  }
};

using CameraModel = CameraModelT<double>;

/// Checks that a camera is usable: positive finite focal lengths, a resolution, the principal
/// point on the sensor, finite coefficients.
[[nodiscard]] Status validate_camera(const CameraModel& camera);

/// Sets the camera's parameters from Kalibr's intrinsics and distortion_coeffs vectors for its
/// model (as many entries as the model has; `distortion` may be left empty to keep the
/// coefficients); the camera is then validated.
[[nodiscard]] Status set_kalibr_parameters(CameraModel* camera, const std::vector<double>& intrinsics,
                                           const std::vector<double>& distortion);

/// Reads one camera from a Kalibr camchain entry (the map under `cam0:`): camera_model pinhole,
/// omni, eucm or ds with the intrinsics in Kalibr's order; distortion_model radtan, equidistant,
/// fov or none (a combination of camera_model_supported) with as many distortion_coeffs;
/// imucal's optional shutter keys (absent: global). `source` names the file in errors.
[[nodiscard]] Result<CameraModel> camera_from_yaml(const YAML::Node& node, const std::string& source);
/// Writes camera_model, intrinsics, distortion_model, distortion_coeffs and resolution into
/// the map `node`, and for a rolling shutter imucal's shutter keys (other keys, such as
/// T_cam_imu, are left as they are).
void camera_to_yaml(const CameraModel& camera, YAML::Node& node);

/// The same for YAML text holding one camera map.
[[nodiscard]] Result<CameraModel> parse_camera_yaml(const std::string& text,
                                                    const std::string& source = "<camera>");
std::string camera_to_yaml_text(const CameraModel& camera);

}  // namespace imucal
