#pragma once
// Camera models as small value types templated on the scalar, so that Ceres autodiff can
// evaluate them on Jets. Two Kalibr models:
//   pinhole-radtan: pinhole + radial-tangential (k1, k2, p1, p2), the same as OpenCV's
//                   4-coefficient model in cv::projectPoints;
//   pinhole-equi:   pinhole + equidistant (k1..k4), the same as cv::fisheye.
// Fields follow Kalibr's camchain YAML: camera_model (pinhole), intrinsics [fu, fv, pu, pv],
// distortion_model (radtan | equidistant), distortion_coeffs, resolution [width, height].
// Pixel convention (OpenCV, Kalibr): integer coordinates are pixel centres, so the image covers
// [-0.5, width - 0.5) x [-0.5, height - 0.5).

#include <Eigen/Core>
#include <cmath>
#include <numbers>
#include <optional>
#include <string>

#include "core/result.hpp"

namespace YAML {
class Node;
}

namespace imucal {

enum class DistortionModel { kRadtan, kEquidistant };

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

/// Kalibr's name: "radtan" or "equidistant".
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

/// A pinhole camera with radtan or equidistant distortion.
template <class T>
struct CameraModelT {
  using Vec2 = Eigen::Matrix<T, 2, 1>;
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  using Vec4 = Eigen::Matrix<T, 4, 1>;

  DistortionModel distortion_model = DistortionModel::kRadtan;
  Vec4 intrinsics = Vec4::Zero();         // fu, fv, pu, pv (pixels)
  Vec4 distortion_coeffs = Vec4::Zero();  // radtan: k1 k2 p1 p2; equidistant: k1 k2 k3 k4
  int width = 0;                          // resolution, pixels
  int height = 0;
  Shutter shutter;  // global unless the camera file says rolling

  struct Projection {
    Vec2 px = Vec2::Zero();
    /// z > 0 and, for radtan, inside the region where the distortion is one-to-one
    /// (d r_d / d r > 0), so the pixel really is where the point appears.
    bool in_front = false;
    /// The pixel lies on the sensor.
    bool in_image = false;
    bool valid() const { return in_front && in_image; }
  };

  /// Distorts normalised coordinates.
  Vec2 distort(const Vec2& xy) const {
    Vec2 out;
    if (distortion_model == DistortionModel::kRadtan) {
      distort_radtan(distortion_coeffs.data(), xy.x(), xy.y(), &out.x(), &out.y());
    } else {
      distort_equidistant(distortion_coeffs.data(), xy.x(), xy.y(), &out.x(), &out.y());
    }
    return out;
  }

  /// Normalised distorted coordinates -> pixel.
  Vec2 to_pixel(const Vec2& xy_distorted) const {
    return Vec2(intrinsics[0] * xy_distorted.x() + intrinsics[2],
                intrinsics[1] * xy_distorted.y() + intrinsics[3]);
  }

  /// Point in the camera frame -> pixel, with validity. The pixel is computed even when the
  /// point is not valid (as cv::projectPoints does), for z != 0.
  Projection project(const Vec3& p_cam) const {
    Projection out;
    const T z = p_cam.z();
    if (z == T(0)) return out;
    const Vec2 xy(p_cam.x() / z, p_cam.y() / z);
    out.px = to_pixel(distort(xy));
    out.in_front = z > T(0);
    if (out.in_front && distortion_model == DistortionModel::kRadtan) {
      const T r2 = xy.squaredNorm();
      const T slope = T(1) + T(3) * distortion_coeffs[0] * r2 + T(5) * distortion_coeffs[1] * r2 * r2;
      out.in_front = slope > T(0);
    }
    out.in_image = out.px.x() >= T(-0.5) && out.px.y() >= T(-0.5) && out.px.x() < T(width) - T(0.5) &&
                   out.px.y() < T(height) - T(0.5);
    return out;
  }

  /// Pixel -> unit ray in the camera frame, undistorting iteratively (Newton) until the
  /// distortion residual is below 1e-12 in normalised coordinates. Returns false when the
  /// pixel lies outside the model's invertible region or the iteration does not converge.
  /// For plain floating-point scalars (not Jets).
  bool unproject(const Vec2& px, Vec3* ray) const {
    using std::abs;
    using std::cos;
    using std::sin;
    using std::sqrt;
    const Vec2 xd((px.x() - intrinsics[2]) / intrinsics[0], (px.y() - intrinsics[3]) / intrinsics[1]);
    constexpr int kMaxIterations = 100;
    const T tolerance = T(1e-12);
    if (distortion_model == DistortionModel::kRadtan) {
      const T* d = distortion_coeffs.data();
      Vec2 xy = xd;
      for (int i = 0; i < kMaxIterations; ++i) {
        Vec2 f;
        distort_radtan(d, xy.x(), xy.y(), &f.x(), &f.y());
        f -= xd;
        if (abs(f.x()) < tolerance && abs(f.y()) < tolerance) {
          const T r2 = xy.squaredNorm();
          if (T(1) + T(3) * d[0] * r2 + T(5) * d[1] * r2 * r2 <= T(0)) return false;
          *ray = Vec3(xy.x(), xy.y(), T(1)).normalized();
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
    // Equidistant: solve theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8) = r_d for theta in [0, pi/2).
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
    out.distortion_model = distortion_model;
    out.intrinsics = intrinsics.template cast<U>();
    out.distortion_coeffs = distortion_coeffs.template cast<U>();
    out.width = width;
    out.height = height;
    out.shutter = shutter;
    return out;
  }

  /// A camera whose intrinsics and distortion are parameter blocks (Ceres: const T* blocks).
  static CameraModelT from_params(DistortionModel model, const T* intrinsics4, const T* distortion4,
                                  int width, int height) {
    CameraModelT out;
    out.distortion_model = model;
    out.intrinsics = Eigen::Map<const Vec4>(intrinsics4);
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

/// Reads one camera from a Kalibr camchain entry (the map under `cam0:`): camera_model must be
/// "pinhole"; distortion_model "radtan" or "equidistant"; imucal's optional shutter keys
/// (absent: global). `source` names the file in errors.
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
