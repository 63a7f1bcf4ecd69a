// SPDX-License-Identifier: BSD-3-Clause
#include "core/calibration_record.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <tuple>

#include "core/die_temperature.hpp"

namespace imucal {
namespace {

using nlohmann::json;

/// A figure: not finite (not determined) as null.
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

/// A sigma as a version 3 record keeps it: in single precision where that holds it (a normal
/// float; CBOR then stores 4 bytes instead of 9, and a sigma's eighth digit means nothing).
double single(double v) {
  const float f = static_cast<float>(v);
  return std::isfinite(f) && std::abs(v) >= static_cast<double>(std::numeric_limits<float>::min())
             ? static_cast<double>(f)
             : v;
}

/// Every number under a key that names a sigma ("sigma", "rotation_sigma_rad", ...) in single().
void single_precision_sigmas(json& j, bool sigma) {
  if (j.is_number_float() && sigma) {
    j = single(j.get<double>());
  } else if (j.is_object()) {
    for (auto& [key, value] : j.items())
      single_precision_sigmas(value, sigma || key.find("sigma") != std::string::npos);
  } else if (j.is_array()) {
    for (auto& value : j) single_precision_sigmas(value, sigma);
  }
}

template <typename Derived>
json vec_json(const Eigen::MatrixBase<Derived>& v) {
  json j = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) j.push_back(num(v(i)));
  return j;
}

template <typename Derived>
json mat_json(const Eigen::MatrixBase<Derived>& m) {
  json j = json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) j.push_back(vec_json(m.row(r)));
  return j;
}

json sigma_json(const ImuSigmaRecord& s) {
  json j = json::object();
  j["model"] = s.model;
  for (const auto& [key, triad] : {std::pair{"accel", &s.accel}, std::pair{"gyro", &s.gyro}}) {
    if (*triad)
      j[key] = {{"misalignment", mat_json((*triad)->T)},
                {"scale", vec_json((*triad)->scale)},
                {"bias", vec_json((*triad)->bias)}};
  }
  if (s.G) j["G"] = mat_json(*s.G);
  if (s.krebs) {
    const KrebsImuSigma& k = *s.krebs;
    j["S_a"] = vec_json(k.S_a);
    j["M_a"] = vec_json(k.M_a);
    j["b_a"] = vec_json(k.b_a);
    j["S_g"] = vec_json(k.S_g);
    j["M_g"] = vec_json(k.M_g);
    j["C_bg_rad"] = vec_json(k.C_bg);
    j["B_g"] = mat_json(k.B_g);
    j["b_g"] = vec_json(k.b_g);
  }
  return j;
}

json thermal_axes_json(const std::array<ThermalAxisModel, 3>& axes) {
  json a = json::array();
  for (const ThermalAxisModel& m : axes) {
    if (m.determined) {
      a.push_back({{"order", m.coeffs.size()}, {"coeffs", vec_json(m.coeffs)}, {"sigma", vec_json(m.sigma)}});
    } else {
      a.push_back({{"order", nullptr}, {"reason", m.reason}});
    }
  }
  return a;
}

/// A list of sigmas: null where not determined.
json sigmas_json(const std::vector<double>& v) {
  json a = json::array();
  for (double x : v) a.push_back(num(x));
  return a;
}

/// A camera's intrinsics in Kalibr's keys and orders (camera_to_yaml's, without the shutter,
/// which the record keeps as line_delay_s) and their sigmas.
json intrinsics_json(const CameraIntrinsicsRecord& k) {
  const CameraModel& c = k.camera;
  return {{"camera_model", projection_model_name(c.projection)},
          {"intrinsics", kalibr_intrinsics(c.projection, c.intrinsics, c.projection_params)},
          {"distortion_model", distortion_model_name(c.distortion_model)},
          {"distortion_coeffs", kalibr_distortion(c.distortion_model, c.distortion_coeffs)},
          {"resolution", {c.width, c.height}},
          {"intrinsics_sigma", sigmas_json(k.intrinsics_sigma)},
          {"distortion_coeffs_sigma", sigmas_json(k.distortion_coeffs_sigma)}};
}

/// Reading the JSON form: every problem names the key.
class Reader {
 public:
  /// A matrix of rows x cols numbers (cols 0: a vector of rows); `finite` refuses null.
  template <typename M>
  Status matrix(const json& parent, const std::string& key, const std::string& where, M& out,
                bool finite) const {
    const std::string what = where + key;
    const auto it = parent.find(key);
    const Eigen::Index rows = out.rows(), cols = out.cols();
    const bool vector = cols == 1;
    auto bad = [&] {
      return make_error(
          Errc::kCorrupt,
          what + " must be " +
              (vector ? std::to_string(rows) : std::to_string(rows) + " rows of " + std::to_string(cols)) +
              (finite ? " finite numbers" : " numbers (null where not determined)"));
    };
    if (it == parent.end() || !it->is_array() || static_cast<Eigen::Index>(it->size()) != rows) return bad();
    for (Eigen::Index r = 0; r < rows; ++r) {
      const json& row = (*it)[static_cast<std::size_t>(r)];
      for (Eigen::Index c = 0; c < cols; ++c) {
        const json* x = &row;
        if (!vector) {
          if (!row.is_array() || static_cast<Eigen::Index>(row.size()) != cols) return bad();
          x = &row[static_cast<std::size_t>(c)];
        }
        if (x->is_null() && !finite) {
          out(r, c) = kNotDetermined;
        } else if (x->is_number() && std::isfinite(x->get<double>())) {
          out(r, c) = x->get<double>();
        } else {
          return bad();
        }
      }
    }
    return {};
  }

  Status text(const json& parent, const std::string& key, const std::string& where, std::string& out) const {
    const auto it = parent.find(key);
    if (it == parent.end() || it->is_null()) return {};
    if (!it->is_string()) return make_error(Errc::kCorrupt, where + key + " must be text");
    out = it->get<std::string>();
    return {};
  }

  Status texts(const json& parent, const std::string& key, const std::string& where,
               std::vector<std::string>& out) const {
    const auto it = parent.find(key);
    if (it == parent.end() || it->is_null()) return {};
    if (!it->is_array()) return make_error(Errc::kCorrupt, where + key + " must be a list of text");
    for (const auto& x : *it) {
      if (!x.is_string()) return make_error(Errc::kCorrupt, where + key + " must be a list of text");
      out.push_back(x.get<std::string>());
    }
    return {};
  }

  /// A figure that may be null (not determined).
  Status figure(const json& parent, const std::string& key, const std::string& where, double& out) const {
    const auto it = parent.find(key);
    if (it == parent.end() || it->is_null()) {
      out = kNotDetermined;
      return {};
    }
    // A record writes what was not determined as null, never as an infinity or NaN (CBOR can
    // hold them): such a figure is an altered record, not one to serve as "not determined".
    if (!it->is_number() || !std::isfinite(it->get<double>()))
      return make_error(Errc::kCorrupt, where + key + " must be a finite number or null");
    out = it->get<double>();
    return {};
  }
};

/// A camera's intrinsics block (camera_from_yaml reads the model, so its rules are the camera
/// file's) with as many sigmas as figures.
Status read_intrinsics(const json& j, const std::string& where, CameraRecord& cam) {
  if (!j.is_object()) return make_error(Errc::kCorrupt, where + "camera must be a mapping");
  // JSON is YAML: the block goes through the camera file's reader.
  YAML::Node node;
  try {
    node = YAML::Load(j.dump(-1, ' ', false, json::error_handler_t::replace));
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, where + "camera is not a camera (" + e.what() + ")");
  }
  auto camera = camera_from_yaml(node, where + "camera");
  if (!camera.ok()) return make_error(Errc::kCorrupt, camera.error().message);
  CameraIntrinsicsRecord k;
  k.camera = *camera;
  const std::size_t n_intrinsics = static_cast<std::size_t>(4 + projection_param_count(k.camera.projection));
  const std::size_t n_coeffs = static_cast<std::size_t>(distortion_coeff_count(k.camera.distortion_model));
  const Reader r;
  for (auto [key, n, out] : {std::tuple{"intrinsics_sigma", n_intrinsics, &k.intrinsics_sigma},
                             std::tuple{"distortion_coeffs_sigma", n_coeffs, &k.distortion_coeffs_sigma}}) {
    Eigen::VectorXd v(static_cast<Eigen::Index>(n));
    IMUCAL_TRY(r.matrix(j, key, where + "camera.", v, false));
    out->assign(v.data(), v.data() + v.size());
  }
  cam.intrinsics = std::move(k);
  return {};
}

Status read_sigma(const json& j, ImuSigmaRecord& s) {
  const Reader r;
  if (!j.is_object()) return make_error(Errc::kCorrupt, "imu.sigma must be a mapping");
  IMUCAL_TRY(r.text(j, "model", "imu.sigma.", s.model));
  for (const auto& [key, triad] : {std::pair{"accel", &s.accel}, std::pair{"gyro", &s.gyro}}) {
    if (!j.contains(key)) continue;
    const json& t = j[key];
    const std::string where = std::string("imu.sigma.") + key + ".";
    if (!t.is_object()) return make_error(Errc::kCorrupt, where + " must be a mapping");
    TriadSigma out;
    IMUCAL_TRY(r.matrix(t, "misalignment", where, out.T, false));
    IMUCAL_TRY(r.matrix(t, "scale", where, out.scale, false));
    IMUCAL_TRY(r.matrix(t, "bias", where, out.bias, false));
    *triad = out;
  }
  if (j.contains("G")) {
    Eigen::Matrix3d G;
    IMUCAL_TRY(r.matrix(j, "G", "imu.sigma.", G, false));
    s.G = G;
  }
  if (j.contains("S_a")) {
    KrebsImuSigma k;
    IMUCAL_TRY(r.matrix(j, "S_a", "imu.sigma.", k.S_a, false));
    IMUCAL_TRY(r.matrix(j, "M_a", "imu.sigma.", k.M_a, false));
    IMUCAL_TRY(r.matrix(j, "b_a", "imu.sigma.", k.b_a, false));
    IMUCAL_TRY(r.matrix(j, "S_g", "imu.sigma.", k.S_g, false));
    IMUCAL_TRY(r.matrix(j, "M_g", "imu.sigma.", k.M_g, false));
    IMUCAL_TRY(r.matrix(j, "C_bg_rad", "imu.sigma.", k.C_bg, false));
    IMUCAL_TRY(r.matrix(j, "B_g", "imu.sigma.", k.B_g, false));
    IMUCAL_TRY(r.matrix(j, "b_g", "imu.sigma.", k.b_g, false));
    s.krebs = k;
  }
  return {};
}

Status read_thermal_axes(const json& t, const char* key, std::array<ThermalAxisModel, 3>& out) {
  const std::string where = std::string("thermal.") + key;
  const auto it = t.find(key);
  if (it == t.end() || !it->is_array() || it->size() != 3)
    return make_error(Errc::kCorrupt, where + " must be a list of 3 axes");
  const Reader r;
  for (std::size_t i = 0; i < 3; ++i) {
    const json& a = (*it)[i];
    const std::string at = where + "[" + std::to_string(i) + "].";
    if (!a.is_object()) return make_error(Errc::kCorrupt, at + " must be a mapping");
    ThermalAxisModel& m = out[i];
    const json order = a.value("order", json());
    if (order.is_null()) {
      m.determined = false;
      IMUCAL_TRY(r.text(a, "reason", at, m.reason));
      continue;
    }
    if (!order.is_number_integer() || order.get<int>() < 0 || order.get<int>() > 3)
      return make_error(Errc::kCorrupt, at + "order must be 0..3 or null");
    m.determined = true;
    m.coeffs.resize(order.get<int>());
    m.sigma.resize(order.get<int>());
    IMUCAL_TRY(r.matrix(a, "coeffs", at, m.coeffs, true));
    IMUCAL_TRY(r.matrix(a, "sigma", at, m.sigma, false));
  }
  return {};
}

/// Equal, with NaN equal to NaN.
template <typename M>
bool same(const M& a, const M& b) {
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    const double x = a.data()[i], y = b.data()[i];
    if (!(x == y || (std::isnan(x) && std::isnan(y)))) return false;
  }
  return true;
}

/// Equal as sigmas are stored: in single precision (a version 3 record), NaN equal to NaN.
template <typename M>
bool same_sigma_values(const M& a, const M& b) {
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    const double x = single(a.data()[i]), y = single(b.data()[i]);
    if (!(x == y || (std::isnan(x) && std::isnan(y)))) return false;
  }
  return true;
}

bool same_thermal(const std::optional<ThermalModel>& a, const std::optional<ThermalModel>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  if (!same(Eigen::Vector3d(a->reference_c, a->min_c, a->max_c),
            Eigen::Vector3d(b->reference_c, b->min_c, b->max_c)))
    return false;
  for (int i = 0; i < 6; ++i) {
    const ThermalAxisModel& x = i < 3 ? a->gyro[i] : a->accel[i - 3];
    const ThermalAxisModel& y = i < 3 ? b->gyro[i] : b->accel[i - 3];
    if (x.determined != y.determined || x.coeffs.size() != y.coeffs.size() || !same(x.coeffs, y.coeffs) ||
        !same_sigma_values(x.sigma, y.sigma))
      return false;
  }
  if (a->scale_model.has_value() != b->scale_model.has_value()) return false;
  if (!a->scale_model) return true;
  const ThermalScaleModel &x = *a->scale_model, &y = *b->scale_model;
  return same(x.gyro_k, y.gyro_k) && same_sigma_values(x.gyro_sigma, y.gyro_sigma) &&
         same(x.accel_k, y.accel_k) && same(x.accel_sigma, y.accel_sigma) &&
         x.temperatures_c == y.temperatures_c;
}

bool same_intrinsics(const std::optional<CameraIntrinsicsRecord>& a,
                     const std::optional<CameraIntrinsicsRecord>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  const CameraModel &x = a->camera, &y = b->camera;
  const auto list = [](const std::vector<double>& v) {
    return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
  };
  return x.kind() == y.kind() && x.width == y.width && x.height == y.height &&
         same(x.intrinsics, y.intrinsics) && same(x.projection_params, y.projection_params) &&
         same(x.distortion_coeffs, y.distortion_coeffs) &&
         a->intrinsics_sigma.size() == b->intrinsics_sigma.size() &&
         a->distortion_coeffs_sigma.size() == b->distortion_coeffs_sigma.size() &&
         same_sigma_values(list(a->intrinsics_sigma), list(b->intrinsics_sigma)) &&
         same_sigma_values(list(a->distortion_coeffs_sigma), list(b->distortion_coeffs_sigma));
}

bool same_sigma(const ImuSigmaRecord& a, const ImuSigmaRecord& b) {
  auto triad = [](const std::optional<TriadSigma>& x, const std::optional<TriadSigma>& y) {
    return x.has_value() == y.has_value() &&
           (!x || (same_sigma_values(x->T, y->T) && same_sigma_values(x->scale, y->scale) &&
                   same_sigma_values(x->bias, y->bias)));
  };
  if (a.model != b.model || !triad(a.accel, b.accel) || !triad(a.gyro, b.gyro)) return false;
  if (a.G.has_value() != b.G.has_value() || (a.G && !same_sigma_values(*a.G, *b.G))) return false;
  if (a.krebs.has_value() != b.krebs.has_value()) return false;
  if (!a.krebs) return true;
  const KrebsImuSigma &x = *a.krebs, &y = *b.krebs;
  return same_sigma_values(x.S_a, y.S_a) && same_sigma_values(x.M_a, y.M_a) &&
         same_sigma_values(x.b_a, y.b_a) && same_sigma_values(x.S_g, y.S_g) &&
         same_sigma_values(x.M_g, y.M_g) && same_sigma_values(x.C_bg, y.C_bg) &&
         same_sigma_values(x.B_g, y.B_g) && same_sigma_values(x.b_g, y.b_g);
}

}  // namespace

json thermal_model_json(const ThermalModel& t) {
  json scale = t.scale;
  if (t.scale_model) {
    const ThermalScaleModel& s = *t.scale_model;
    scale = {{"form", kThermalScaleForm},
             {"gyro_k", vec_json(s.gyro_k)},
             {"gyro_sigma", vec_json(s.gyro_sigma)},
             {"accel_k", vec_json(s.accel_k)},
             {"accel_sigma", vec_json(s.accel_sigma)},
             {"temperatures_c",
              vec_json(Eigen::Map<const Eigen::VectorXd>(
                  s.temperatures_c.data(), static_cast<Eigen::Index>(s.temperatures_c.size())))}};
  }
  return {{"form", kThermalForm},
          {"reference_c", num(t.reference_c)},
          {"valid_range_c", {num(t.min_c), num(t.max_c)}},
          {"scale", scale},
          {"gyro", thermal_axes_json(t.gyro)},
          {"accel", thermal_axes_json(t.accel)}};
}

Result<ThermalModel> thermal_model_from_json(const json& t) {
  if (!t.is_object()) return make_error(Errc::kCorrupt, "thermal must be a mapping");
  const Reader r;
  ThermalModel m;
  IMUCAL_TRY(r.figure(t, "reference_c", "thermal.", m.reference_c));
  Eigen::Vector2d range;
  IMUCAL_TRY(r.matrix(t, "valid_range_c", "thermal.", range, true));
  if (!std::isfinite(m.reference_c) || !(range[0] <= range[1]))
    return make_error(Errc::kCorrupt, "thermal.reference_c must be a number and valid_range_c [min, max]");
  if (!is_die_temperature(m.reference_c) || !is_die_temperature(range[0]) || !is_die_temperature(range[1])) {
    return make_error(Errc::kCorrupt,
                      "thermal.reference_c and valid_range_c must be die temperatures (" +
                          std::to_string(static_cast<int>(kMinDieTemperatureC)) + ".." +
                          std::to_string(static_cast<int>(kMaxDieTemperatureC)) +
                          " deg C); the model was fitted to impossible temperatures: fit it again");
  }
  m.min_c = range[0];
  m.max_c = range[1];
  if (const auto it = t.find("scale"); it != t.end() && it->is_object()) {
    // Scale against temperature fitted (record version 2 written by this version on).
    ThermalScaleModel s;
    IMUCAL_TRY(r.text(*it, "form", "thermal.scale.", m.scale));
    IMUCAL_TRY(r.matrix(*it, "gyro_k", "thermal.scale.", s.gyro_k, false));
    IMUCAL_TRY(r.matrix(*it, "gyro_sigma", "thermal.scale.", s.gyro_sigma, false));
    IMUCAL_TRY(r.matrix(*it, "accel_k", "thermal.scale.", s.accel_k, false));
    IMUCAL_TRY(r.matrix(*it, "accel_sigma", "thermal.scale.", s.accel_sigma, false));
    const auto temps = it->find("temperatures_c");
    if (temps == it->end() || !temps->is_array() || temps->size() < 2)
      return make_error(Errc::kCorrupt, "thermal.scale.temperatures_c must list two or more temperatures");
    for (const auto& x : *temps) {
      if (!x.is_number()) return make_error(Errc::kCorrupt, "thermal.scale.temperatures_c must be numbers");
      s.temperatures_c.push_back(x.get<double>());
    }
    m.scale_model = std::move(s);
  } else {
    IMUCAL_TRY(r.text(t, "scale", "thermal.", m.scale));
  }
  IMUCAL_TRY(read_thermal_axes(t, "gyro", m.gyro));
  IMUCAL_TRY(read_thermal_axes(t, "accel", m.accel));
  return m;
}

json calibration_record_json(const CalibrationRecord& rec) {
  const ImuRecord& i = rec.imu;
  json imu = {{"stream", i.stream},           {"input_units", i.input_units}, {"form", i.form},
              {"A_a", mat_json(i.model.A_a)}, {"b_a", vec_json(i.model.b_a)}, {"A_g", mat_json(i.model.A_g)},
              {"b_g", vec_json(i.model.b_g)}, {"G", mat_json(i.model.G)},     {"source", i.source}};
  if (!i.sigma.model.empty() || i.sigma.accel || i.sigma.krebs) imu["sigma"] = sigma_json(i.sigma);
  json cameras = json::array();
  for (const CameraRecord& c : rec.cameras) {
    cameras.push_back({{"name", c.name},
                       {"stream", c.stream},
                       {"T_cam_imu", mat_json(c.T_cam_imu)},
                       {"rotation_sigma_rad", vec_json(c.rotation_sigma_rad)},
                       {"translation_sigma_m", vec_json(c.translation_sigma_m)},
                       {"timeshift_cam_imu_s", num(c.timeshift_cam_imu_s)},
                       {"timeshift_sigma_s", num(c.timeshift_sigma_s)}});
    if (c.line_delay_s) {
      cameras.back()["line_delay_s"] = num(*c.line_delay_s);
      cameras.back()["line_delay_sigma_s"] = num(c.line_delay_sigma_s);
    }
    if (c.intrinsics) cameras.back()["camera"] = intrinsics_json(*c.intrinsics);
  }
  json files = json::array();
  for (const RecordSourceFile& f : rec.files) {
    json file = {{"path", f.path}, {"kind", f.kind}, {"method", f.method}};
    if (f.fixed) file["fixed"] = *f.fixed;
    files.push_back(file);
  }
  // The oldest version that holds what the record holds, so that an older imucal reads a record
  // it can read in full, and refuses one it would read in part (a newer version).
  const bool intrinsics = std::any_of(rec.cameras.begin(), rec.cameras.end(),
                                      [](const CameraRecord& c) { return c.intrinsics.has_value(); });
  json j = {{"format", kCalibrationFormat},
            {"version", intrinsics    ? 3
                        : rec.thermal ? 2
                                      : kOldestCalibrationRecordVersion},
            {"created_utc", rec.created_utc},
            {"software_version", rec.software_version},
            {"imu", imu},
            {"cameras", cameras},
            {"source", {{"files", files}, {"notes", rec.notes}}}};
  if (!rec.rig.empty()) j["rig"] = rec.rig;
  if (rec.gravity_mps2) j["gravity_mps2"] = num(*rec.gravity_mps2);
  if (rec.thermal) j["thermal"] = thermal_model_json(*rec.thermal);
  // Version 3 on: the sigmas in single precision (versions 1 and 2 stay as they were written).
  if (intrinsics) single_precision_sigmas(j, false);
  return j;
}

Result<CalibrationRecord> calibration_record_from_json(const json& j) {
  if (!j.is_object() || j.value("format", json()) != kCalibrationFormat) {
    return make_error(Errc::kCorrupt, std::string("not an imucal calibration (its \"format\" is not \"") +
                                          kCalibrationFormat + "\")");
  }
  const json version = j.value("version", json());
  const std::string named = version.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  const std::string reads = ", this imucal reads versions " +
                            std::to_string(kOldestCalibrationRecordVersion) + " to " +
                            std::to_string(kCalibrationRecordVersion);
  if (version.is_number_integer() && version.get<std::int64_t>() > kCalibrationRecordVersion) {
    // Not damage: the session and `store` say so and never write over it unasked.
    return make_error(Errc::kNewerVersion, "calibration record version " + named + reads +
                                               " (a newer imucal wrote it: update imucal)");
  }
  if (!version.is_number_integer() || version.get<std::int64_t>() < kOldestCalibrationRecordVersion)
    return make_error(Errc::kCorrupt, "calibration record version " + named + reads);
  const Reader r;
  CalibrationRecord rec;
  IMUCAL_TRY(r.text(j, "created_utc", "", rec.created_utc));
  IMUCAL_TRY(r.text(j, "software_version", "", rec.software_version));
  IMUCAL_TRY(r.text(j, "rig", "", rec.rig));
  if (!j.contains("imu") || !j["imu"].is_object())
    return make_error(Errc::kCorrupt, "the calibration has no imu");
  const json& imu = j["imu"];
  ImuRecord& i = rec.imu;
  IMUCAL_TRY(r.text(imu, "stream", "imu.", i.stream));
  IMUCAL_TRY(r.text(imu, "input_units", "imu.", i.input_units));
  IMUCAL_TRY(r.text(imu, "form", "imu.", i.form));
  IMUCAL_TRY(r.text(imu, "source", "imu.", i.source));
  IMUCAL_TRY(r.matrix(imu, "A_a", "imu.", i.model.A_a, true));
  IMUCAL_TRY(r.matrix(imu, "b_a", "imu.", i.model.b_a, true));
  IMUCAL_TRY(r.matrix(imu, "A_g", "imu.", i.model.A_g, true));
  IMUCAL_TRY(r.matrix(imu, "b_g", "imu.", i.model.b_g, true));
  IMUCAL_TRY(r.matrix(imu, "G", "imu.", i.model.G, true));
  if (imu.contains("sigma")) IMUCAL_TRY(read_sigma(imu["sigma"], i.sigma));
  if (!j.contains("cameras") || !j["cameras"].is_array())
    return make_error(Errc::kCorrupt, "the calibration's cameras must be a list");
  for (const json& c : j["cameras"]) {
    if (!c.is_object()) return make_error(Errc::kCorrupt, "a camera entry is not a mapping");
    CameraRecord cam;
    IMUCAL_TRY(r.text(c, "name", "camera.", cam.name));
    const std::string where = "camera " + (cam.name.empty() ? std::string("?") : cam.name) + " ";
    IMUCAL_TRY(r.text(c, "stream", where, cam.stream));
    IMUCAL_TRY(r.matrix(c, "T_cam_imu", where, cam.T_cam_imu, true));
    if (c.contains("rotation_sigma_rad"))
      IMUCAL_TRY(r.matrix(c, "rotation_sigma_rad", where, cam.rotation_sigma_rad, false));
    if (c.contains("translation_sigma_m"))
      IMUCAL_TRY(r.matrix(c, "translation_sigma_m", where, cam.translation_sigma_m, false));
    IMUCAL_TRY(r.figure(c, "timeshift_cam_imu_s", where, cam.timeshift_cam_imu_s));
    if (std::isnan(cam.timeshift_cam_imu_s)) cam.timeshift_cam_imu_s = 0.0;
    IMUCAL_TRY(r.figure(c, "timeshift_sigma_s", where, cam.timeshift_sigma_s));
    if (c.contains("line_delay_s")) {
      double d = 0.0;
      IMUCAL_TRY(r.figure(c, "line_delay_s", where, d));
      if (!std::isfinite(d))
        return make_error(Errc::kCorrupt, where + "line_delay_s must be a number (s per row)");
      cam.line_delay_s = d;
      IMUCAL_TRY(r.figure(c, "line_delay_sigma_s", where, cam.line_delay_sigma_s));
    }
    if (const auto it = c.find("camera"); it != c.end() && !it->is_null())
      IMUCAL_TRY(read_intrinsics(*it, where, cam));
    rec.cameras.push_back(cam);
  }
  if (j.contains("gravity_mps2") && !j["gravity_mps2"].is_null()) {
    double g = 0.0;
    IMUCAL_TRY(r.figure(j, "gravity_mps2", "", g));
    if (!(g > 0.0)) return make_error(Errc::kCorrupt, "gravity_mps2 must be a positive number (m/s^2)");
    rec.gravity_mps2 = g;
  }
  if (j.contains("thermal") && !j["thermal"].is_null()) {
    auto thermal = thermal_model_from_json(j["thermal"]);
    if (!thermal.ok()) return thermal.error();
    rec.thermal = std::move(*thermal);
  }
  if (j.contains("source")) {
    const json& src = j["source"];
    if (!src.is_object()) return make_error(Errc::kCorrupt, "source must be a mapping");
    IMUCAL_TRY(r.texts(src, "notes", "source.", rec.notes));
    if (src.contains("files")) {
      if (!src["files"].is_array()) return make_error(Errc::kCorrupt, "source.files must be a list");
      for (const json& f : src["files"]) {
        if (!f.is_object()) return make_error(Errc::kCorrupt, "a source.files entry is not a mapping");
        RecordSourceFile file;
        IMUCAL_TRY(r.text(f, "path", "source.files.", file.path));
        IMUCAL_TRY(r.text(f, "kind", "source.files.", file.kind));
        IMUCAL_TRY(r.text(f, "method", "source.files.", file.method));
        if (f.contains("fixed")) {
          file.fixed.emplace();
          IMUCAL_TRY(r.texts(f, "fixed", "source.files.", *file.fixed));
        }
        rec.files.push_back(std::move(file));
      }
    }
  }
  return rec;
}

bool same_calibration(const CalibrationRecord& a, const CalibrationRecord& b) {
  const ImuRecord &x = a.imu, &y = b.imu;
  if (x.stream != y.stream || x.input_units != y.input_units || x.form != y.form || x.source != y.source ||
      !same(x.model.A_a, y.model.A_a) || !same(x.model.b_a, y.model.b_a) || !same(x.model.A_g, y.model.A_g) ||
      !same(x.model.b_g, y.model.b_g) || !same(x.model.G, y.model.G) || !same_sigma(x.sigma, y.sigma) ||
      !same_thermal(a.thermal, b.thermal))
    return false;
  if (a.cameras.size() != b.cameras.size()) return false;
  for (std::size_t k = 0; k < a.cameras.size(); ++k) {
    const CameraRecord &c = a.cameras[k], &d = b.cameras[k];
    if (c.name != d.name || c.stream != d.stream || !same(c.T_cam_imu, d.T_cam_imu) ||
        !same_sigma_values(c.rotation_sigma_rad, d.rotation_sigma_rad) ||
        !same_sigma_values(c.translation_sigma_m, d.translation_sigma_m) ||
        c.timeshift_cam_imu_s != d.timeshift_cam_imu_s ||
        !same_sigma_values(Eigen::Matrix<double, 1, 1>(c.timeshift_sigma_s),
                           Eigen::Matrix<double, 1, 1>(d.timeshift_sigma_s)) ||
        c.line_delay_s.has_value() != d.line_delay_s.has_value() ||
        (c.line_delay_s && (*c.line_delay_s != *d.line_delay_s ||
                            !same_sigma_values(Eigen::Matrix<double, 1, 1>(c.line_delay_sigma_s),
                                               Eigen::Matrix<double, 1, 1>(d.line_delay_sigma_s)))) ||
        !same_intrinsics(c.intrinsics, d.intrinsics))
      return false;
  }
  return true;
}

}  // namespace imucal
