// SPDX-License-Identifier: BSD-3-Clause
#include "app/results/thermal_results.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "app/initial_guess.hpp"
#include "app/solvers.hpp"
#include "app/streams.hpp"
#include "core/die_temperature.hpp"
#include "core/text_file.hpp"
#include "core/text_format.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app {
namespace {

constexpr const char* kThermalMethod =
    "bias against die temperature: polynomial of (T - T_ref), order 0..3 by likelihood, generalised least "
    "squares on time-bin means with white noise and a bias random walk (docs/thermal.md)";

void emit_axis(YAML::Emitter& y, const calib::ThermalAxisFit& a, const char* unit) {
  y << YAML::BeginMap;
  if (!a.determined) {
    y << YAML::Key << "determined" << YAML::Value << false;
    y << YAML::Key << "reason" << YAML::Value << a.reason;
    y << YAML::EndMap;
    return;
  }
  y << YAML::Key << "determined" << YAML::Value << true;
  y << YAML::Key << "order" << YAML::Value << a.order;
  y << YAML::Key << "coefficients" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (Eigen::Index j = 0; j < a.coeffs.size(); ++j) y << a.coeffs[j];
  y << YAML::EndSeq;
  y << YAML::Key << "sigmas" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (Eigen::Index j = 0; j < a.coeffs.size(); ++j) y << std::sqrt(a.covariance(j, j));
  y << YAML::EndSeq;
  y << YAML::Key << "covariance" << YAML::Value << YAML::BeginSeq;
  for (Eigen::Index r = 0; r < a.covariance.rows(); ++r) {
    y << YAML::Flow << YAML::BeginSeq;
    for (Eigen::Index c = 0; c < a.covariance.cols(); ++c) y << a.covariance(r, c);
    y << YAML::EndSeq;
  }
  y << YAML::EndSeq;
  y << YAML::Key << "aic" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (double b : a.aic) {
    if (std::isfinite(b)) {
      y << b;
    } else {
      y << YAML::Null;
    }
  }
  y << YAML::EndSeq;
  y << YAML::Key << "uncompensated_drift" << YAML::Value << a.uncompensated_drift;
  y << YAML::Key << "residual_rms" << YAML::Value << a.residual_rms;
  y << YAML::Key << "model_sigma_rms" << YAML::Value << a.model_sigma_rms;
  y << YAML::Key << "white_noise_density" << YAML::Value << a.white_noise_density;
  y << YAML::Key << "bias_random_walk" << YAML::Value << a.random_walk;
  y << YAML::Key << "unit" << YAML::Value << unit;
  y << YAML::EndMap;
}

/// Three numbers as a flow list; one not determined (not finite) is null.
void emit_vec3(YAML::Emitter& y, const char* key, const Eigen::Vector3d& v) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < 3; ++i) {
    if (std::isfinite(v[i])) {
      y << v[i];
    } else {
      y << YAML::Null;
    }
  }
  y << YAML::EndSeq;
}

/// scale_against_temperature: the reason it is not determined, or the fit and its points.
void emit_scale(YAML::Emitter& y, const calib::ThermalScaleFit& s) {
  y << YAML::Key << "scale_against_temperature" << YAML::Value;
  if (!s.determined) {
    y << "not determined: " + s.reason;
    return;
  }
  y << YAML::BeginMap;
  y << YAML::Key << "form" << YAML::Value
    << std::string(kThermalScaleForm) +
           " per axis: k the relative change of the sensitivity (output per input) per K, the model's scale "
           "(SI per count) the inverse, fitted to the static calibrations below (null: an input sigma was "
           "not determined)";
  emit_vec3(y, "gyro_k", s.model.gyro_k);
  emit_vec3(y, "gyro_sigma", s.model.gyro_sigma);
  emit_vec3(y, "accel_k", s.model.accel_k);
  emit_vec3(y, "accel_sigma", s.model.accel_sigma);
  emit_vec3(y, "gyro_chi2_dof", s.gyro_chi2_dof);
  emit_vec3(y, "accel_chi2_dof", s.accel_chi2_dof);
  y << YAML::Key << "points" << YAML::Value << YAML::BeginSeq;
  for (const auto& p : s.points) {
    y << YAML::BeginMap;
    y << YAML::Key << "source" << YAML::Value << p.source;
    y << YAML::Key << "temperature_c" << YAML::Value << p.temperature_c;
    y << YAML::Key << "temperature_span_c" << YAML::Value << p.temperature_span_c;
    emit_vec3(y, "gyro_scale", p.gyro);
    emit_vec3(y, "gyro_scale_sigma", p.gyro_sigma);
    emit_vec3(y, "accel_scale", p.accel);
    emit_vec3(y, "accel_scale_sigma", p.accel_sigma);
    y << YAML::EndMap;
  }
  y << YAML::EndSeq;
  y << YAML::EndMap;
}

void emit_sensor(YAML::Emitter& y, const char* name, const std::array<calib::ThermalAxisFit, 3>& axes,
                 const char* unit, const char* c0) {
  y << YAML::Key << name << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "unit" << YAML::Value << unit;
  y << YAML::Key << "c0" << YAML::Value << c0;
  for (int a = 0; a < 3; ++a) {
    y << YAML::Key << std::string(1, "xyz"[a]);
    y << YAML::Value;
    emit_axis(y, axes[a], unit);
  }
  y << YAML::EndMap;
}

}  // namespace

std::string thermal_result_yaml(const calib::ThermalResult& r, const ImuStreamInfo& info,
                                const std::string& log_path) {
  YAML::Emitter y;
  y.SetDoublePrecision(12);
  y << YAML::BeginMap;
  y << YAML::Key << "format" << YAML::Value << kThermalFormat;
  y << YAML::Key << "method" << YAML::Value << kThermalMethod;
  y << YAML::Key << "log" << YAML::Value << log_path;
  y << YAML::Key << "stream" << YAML::Value << info.name;
  y << YAML::Key << "input_units" << YAML::Value << imu_units_name(info.units);
  y << YAML::Key << "form" << YAML::Value
    << "b(T) = c0 + c1 (T - T_ref) + c2 (T - T_ref)^2 + c3 (T - T_ref)^3 per axis, SI units per K^j, T in "
       "deg C; correct a sample by subtracting b(T) - c0";
  y << YAML::Key << "reference_temperature_c" << YAML::Value << r.reference_c;
  y << YAML::Key << "reference_choice" << YAML::Value << "the middle of the range covered (or --reference)";
  y << YAML::Key << "valid_range_c" << YAML::Value << YAML::Flow << YAML::BeginSeq << r.temp_min_c
    << r.temp_max_c << YAML::EndSeq;
  y << YAML::Key << "duration_s" << YAML::Value << r.duration_s;
  y << YAML::Key << "samples" << YAML::Value << r.samples;
  y << YAML::Key << "bins" << YAML::Value << r.bins;
  y << YAML::Key << "bin_s" << YAML::Value << r.bin_s;
  y << YAML::Key << "temperature_monotonic" << YAML::Value << r.temperature_monotonic;
  y << YAML::Key << "order_criterion" << YAML::Value
    << "least -2 ln L + (order + 3), over orders 0..3: a term kept when it lowers -2 ln L by more than 1 "
       "(L the likelihood of the bin means under the fitted noise; aic below is -2 ln L + 2 (order + 3))";
  y << YAML::Key << "covariance_note" << YAML::Value
    << "the coefficients' covariance under the fitted white noise and bias random walk of the bin means "
       "(their ratio taken as known)";
  emit_sensor(
      y, "gyro", r.gyro, "rad/s",
      "the rate at the reference temperature: bias plus the earth rate and the g-sensitivity's share");
  emit_sensor(y, "accel", r.accel, "m/s^2",
              "the value at the reference temperature, gravity's projection included: not a bias; only "
              "c1..c3 describe the accelerometer's temperature dependence");
  emit_scale(y, r.scale);
  y << YAML::Key << "warnings" << YAML::Value << YAML::BeginSeq;
  for (const auto& w : r.warnings) y << w;
  y << YAML::EndSeq;
  y << YAML::Key << "bin_means" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "columns" << YAML::Value << YAML::Flow << YAML::BeginSeq << "t_s"
    << "temperature_c"
    << "gyro_x"
    << "gyro_y"
    << "gyro_z"
    << "accel_x"
    << "accel_y"
    << "accel_z"
    << "samples" << YAML::EndSeq;
  y << YAML::Key << "rows" << YAML::Value << YAML::BeginSeq;
  for (const calib::ThermalBinMean& b : r.bin_means) {
    y << YAML::Flow << YAML::BeginSeq << b.t_s << b.temperature_c << b.gyro[0] << b.gyro[1] << b.gyro[2]
      << b.accel[0] << b.accel[1] << b.accel[2] << b.samples << YAML::EndSeq;
  }
  y << YAML::EndSeq << YAML::EndMap;
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

namespace {

/// Reading a thermal file: every problem names the key (the caller adds the path).
struct ThermalReader {
  const YAML::Node& root;

  YAML::Node need(const YAML::Node& parent, const std::string& key, const std::string& where) const {
    YAML::Node n = parent[key];
    if (!n) throw std::runtime_error(where + key + " is missing");
    return n;
  }
  double number(const YAML::Node& parent, const std::string& key, const std::string& where) const {
    try {
      return need(parent, key, where).as<double>();
    } catch (const YAML::Exception&) {
      throw std::runtime_error(where + key + " must be a number");
    }
  }
  std::vector<double> numbers(const YAML::Node& parent, const std::string& key, const std::string& where,
                              std::size_t size) const {
    return numbers_of(need(parent, key, where), where + key, size);
  }
  /// A list of `size` numbers (null: NaN); `what` names it in the error.
  static std::vector<double> numbers_of(const YAML::Node& n, const std::string& what, std::size_t size) {
    const auto bad = [&] {
      return std::runtime_error(what + " must be a list of " + std::to_string(size) + " numbers");
    };
    if (!n.IsSequence() || n.size() != size) throw bad();
    std::vector<double> out;
    for (const auto& x : n) {
      try {
        out.push_back(x.IsNull() ? std::nan("") : x.as<double>());
      } catch (const YAML::Exception&) {
        throw bad();
      }
    }
    return out;
  }
  std::string text(const YAML::Node& parent, const std::string& key) const {
    const YAML::Node n = parent[key];
    return n && n.IsScalar() ? n.Scalar() : std::string();
  }

  calib::ThermalAxisFit axis(const YAML::Node& sensor, const std::string& name,
                             const std::string& where) const {
    const std::string at = where + name + ".";
    const YAML::Node a = need(sensor, name, where);
    calib::ThermalAxisFit f;
    try {
      f.determined = need(a, "determined", at).as<bool>();
    } catch (const YAML::Exception&) {
      throw std::runtime_error(at + "determined must be true or false");
    }
    if (!f.determined) {
      f.reason = text(a, "reason");
      return f;
    }
    const double order = number(a, "order", at);
    if (!(order >= 0 && order <= 3 && order == std::floor(order)))
      throw std::runtime_error(at + "order must be 0..3");
    f.order = static_cast<int>(order);
    const auto n = static_cast<std::size_t>(f.order + 1);
    const auto c = numbers(a, "coefficients", at, n);
    f.coeffs = Eigen::Map<const Eigen::VectorXd>(c.data(), f.order + 1);
    const YAML::Node cov = need(a, "covariance", at);
    if (!cov.IsSequence() || cov.size() != n)
      throw std::runtime_error(at + "covariance must be " + std::to_string(n) + " rows");
    f.covariance.resize(f.order + 1, f.order + 1);
    for (std::size_t r = 0; r < n; ++r) {
      const auto row = ThermalReader::numbers_of(cov[r], at + "covariance[" + std::to_string(r) + "]", n);
      for (std::size_t k = 0; k < n; ++k) f.covariance(r, k) = row[k];
    }
    if (!f.coeffs.allFinite() || !f.covariance.allFinite())
      throw std::runtime_error(at + "coefficients and covariance must be finite");
    const auto aic = numbers(a, "aic", at, 4);
    std::copy(aic.begin(), aic.end(), f.aic.begin());
    f.uncompensated_drift = number(a, "uncompensated_drift", at);
    f.residual_rms = number(a, "residual_rms", at);
    f.model_sigma_rms = number(a, "model_sigma_rms", at);
    f.white_noise_density = number(a, "white_noise_density", at);
    f.random_walk = number(a, "bias_random_walk", at);
    return f;
  }
};

Eigen::Vector3d vec3_of(const YAML::Node& parent, const std::string& key, const std::string& where) {
  const YAML::Node n = parent[key];
  if (!n) throw std::runtime_error(where + key + " is missing");
  const auto v = ThermalReader::numbers_of(n, where + key, 3);
  return {v[0], v[1], v[2]};
}

/// scale_against_temperature: a text (not determined: the reason) or the fit with its points.
void read_scale(const ThermalReader& r, const YAML::Node& root, calib::ThermalScaleFit& out) {
  const YAML::Node s = root["scale_against_temperature"];
  if (!s || s.IsScalar()) {
    const std::string text = s ? s.as<std::string>("") : std::string();
    const std::string prefix = "not determined: ";
    out.determined = false;
    out.reason = text.starts_with(prefix) ? text.substr(prefix.size()) : text;
    return;
  }
  const std::string at = "scale_against_temperature.";
  if (!s.IsMap()) throw std::runtime_error(at + " must be a text or a map");
  out.determined = true;
  out.reason.clear();
  out.model.gyro_k = vec3_of(s, "gyro_k", at);
  out.model.gyro_sigma = vec3_of(s, "gyro_sigma", at);
  out.model.accel_k = vec3_of(s, "accel_k", at);
  out.model.accel_sigma = vec3_of(s, "accel_sigma", at);
  if (s["gyro_chi2_dof"]) out.gyro_chi2_dof = vec3_of(s, "gyro_chi2_dof", at);
  if (s["accel_chi2_dof"]) out.accel_chi2_dof = vec3_of(s, "accel_chi2_dof", at);
  const YAML::Node points = r.need(s, "points", at);
  if (!points.IsSequence() || points.size() < 2)
    throw std::runtime_error(at + "points must list two or more");
  out.points.clear();
  out.model.temperatures_c.clear();
  for (std::size_t k = 0; k < points.size(); ++k) {
    const std::string where = at + "points[" + std::to_string(k) + "].";
    calib::ThermalScalePoint p;
    p.source = points[k]["source"].as<std::string>("");
    p.temperature_c = r.number(points[k], "temperature_c", where);
    if (!is_die_temperature(p.temperature_c))
      throw std::runtime_error(where + "temperature_c is not a die temperature (-60..150 deg C)");
    p.temperature_span_c = r.number(points[k], "temperature_span_c", where);
    p.gyro = vec3_of(points[k], "gyro_scale", where);
    p.gyro_sigma = vec3_of(points[k], "gyro_scale_sigma", where);
    p.accel = vec3_of(points[k], "accel_scale", where);
    p.accel_sigma = vec3_of(points[k], "accel_scale_sigma", where);
    out.model.temperatures_c.push_back(p.temperature_c);
    out.points.push_back(std::move(p));
  }
}

}  // namespace

Result<ThermalFile> read_thermal_file(const std::string& path) {
  auto loaded = read_yaml_file(path);
  if (!loaded.ok()) return loaded.error();
  const YAML::Node root = *loaded;
  if (!root.IsMap() || !root["format"] || root["format"].as<std::string>("") != kThermalFormat) {
    return make_error(Errc::kCorrupt, path + ": not a thermal model (no \"format: " + kThermalFormat +
                                          "\"): give the file `imucal calibrate thermal -o` wrote");
  }
  const ThermalReader r{root};
  ThermalFile f;
  f.path = path;
  try {
    f.log = r.text(root, "log");
    f.stream = r.text(root, "stream");
    f.input_units = r.text(root, "input_units");
    calib::ThermalResult& res = f.result;
    res.determined = true;
    res.reference_c = r.number(root, "reference_temperature_c", "");
    const auto range = r.numbers(root, "valid_range_c", "", 2);
    res.temp_min_c = range[0];
    res.temp_max_c = range[1];
    if (!std::isfinite(res.reference_c) || !(res.temp_min_c <= res.temp_max_c))
      throw std::runtime_error("reference_temperature_c and valid_range_c [min, max] must be finite");
    // A model fitted to impossible temperatures (an old build took 1e308 deg C) is not applied.
    if (!is_die_temperature(res.reference_c) || !is_die_temperature(res.temp_min_c) ||
        !is_die_temperature(res.temp_max_c)) {
      throw std::runtime_error(
          "reference_temperature_c and valid_range_c must be die temperatures (-60..150 deg C); fit the "
          "model again with calibrate thermal");
    }
    res.duration_s = r.number(root, "duration_s", "");
    res.samples = static_cast<std::size_t>(std::max(0.0, r.number(root, "samples", "")));
    res.bins = static_cast<int>(r.number(root, "bins", ""));
    res.bin_s = r.number(root, "bin_s", "");
    res.temperature_monotonic = root["temperature_monotonic"].as<bool>(true);
    for (const char* sensor : {"gyro", "accel"}) {
      const YAML::Node s = r.need(root, sensor, "");
      auto& axes = std::string(sensor) == "gyro" ? res.gyro : res.accel;
      for (int a = 0; a < 3; ++a) axes[a] = r.axis(s, std::string(1, "xyz"[a]), std::string(sensor) + ".");
    }
    read_scale(r, root, res.scale);
    if (const YAML::Node w = root["warnings"]; w && w.IsSequence()) {
      for (const auto& x : w) res.warnings.push_back(x.as<std::string>(""));
    }
    if (const YAML::Node b = root["bin_means"]; b && b["rows"] && b["rows"].IsSequence()) {
      for (std::size_t k = 0; k < b["rows"].size(); ++k) {
        const auto row =
            ThermalReader::numbers_of(b["rows"][k], "bin_means.rows[" + std::to_string(k) + "]", 9);
        res.bin_means.push_back({row[0], row[1], Eigen::Vector3d(row[2], row[3], row[4]),
                                 Eigen::Vector3d(row[5], row[6], row[7]),
                                 static_cast<std::size_t>(std::max(0.0, row[8]))});
      }
    }
  } catch (const std::exception& e) {
    return make_error(Errc::kCorrupt, path + ": " + e.what());
  }
  f.model = calib::thermal_model(f.result);
  return f;
}

ThermalModel thermal_model_on_input_units(const ThermalModel& si_model, const ImuStreamInfo& info,
                                          const AxisConversion& accel, const AxisConversion& gyro) {
  if (info.units == ImuUnits::kSi) return si_model;
  return si_model.scaled(gyro.scale.cwiseInverse(), accel.scale.cwiseInverse());
}

std::string ThermalCorrection::warning() const {
  std::string w;
  if (clamped > 0) {
    w = std::to_string(clamped) + " samples outside the thermal model's range (" + fixed(model_min_c, 2) +
        " .. " + fixed(model_max_c, 2) + " deg C; the samples met " + fixed(min_c, 2) + " .. " +
        fixed(max_c, 2) +
        ") were corrected at its nearest end: what the die's move beyond it does to the bias is left in them";
  }
  if (without_temperature > 0) {
    w += (w.empty() ? "" : "; ") + std::to_string(without_temperature) +
         " samples without a die temperature were not corrected";
  }
  return w;
}

Result<ThermalCorrection> correct_to_reference_temperature(std::vector<ImuSample>& samples,
                                                           const ImuStreamInfo& info,
                                                           const ThermalModel& model) {
  ThermalCorrection c;
  c.model_min_c = model.min_c;
  c.model_max_c = model.max_c;
  for (ImuSample& s : samples) {
    if (!std::isfinite(s.temperature)) {
      ++c.without_temperature;
      continue;
    }
    const double t = info.temperature_scale * s.temperature + info.temperature_offset;
    if (c.corrected == 0) c.min_c = c.max_c = t;
    c.min_c = std::min(c.min_c, t);
    c.max_c = std::max(c.max_c, t);
    if (t < model.min_c || t > model.max_c) ++c.clamped;
    c.mean_c += model.clamp(t);
    s.gyro -= model.gyro_change(t);
    s.accel -= model.accel_change(t);
    ++c.corrected;
  }
  if (c.corrected > 0) c.mean_c /= static_cast<double>(c.corrected);
  if (c.corrected == 0) {
    return make_error(Errc::kInsufficientData,
                      "the log has no die temperature, so the thermal model cannot be applied: record with a "
                      "temperature (imucal record stores it) or leave out --thermal");
  }
  return c;
}

std::string thermal_uncertainty_warning(const calib::ThermalResult& r, double temperature_c) {
  if (!r.determined) return {};
  const double t = std::clamp(temperature_c, r.temp_min_c, r.temp_max_c);
  const auto sigmas = [&](const std::array<calib::ThermalAxisFit, 3>& fits, double k, int digits) {
    std::string out;
    for (const auto& f : fits) {
      const double s = f.change_sigma(t, r.reference_c) * k;
      out += (out.empty() ? "" : " ") + (std::isfinite(s) ? fixed(s, digits) : std::string("not determined"));
    }
    return out;
  };
  return "the biases' sigmas leave out the thermal model's own uncertainty at the samples' mean "
         "temperature " +
         fixed(t, 2) + " deg C: gyro " + sigmas(r.gyro, 180.0 / std::numbers::pi, 4) + " deg/s, accel " +
         sigmas(r.accel, 1e3 / kStandardGravity, 3) + " mg (add it in quadrature)";
}

Result<AppliedThermal> apply_thermal(const calib::ThermalResult& result, std::vector<ImuSample>& samples,
                                     const ImuStreamInfo& info, const std::string& source) {
  AppliedThermal applied;
  applied.path = source;
  applied.model = calib::thermal_model(result);
  if (info.units != ImuUnits::kSi) {
    auto guess = nominal_guess(info, {});
    if (!guess.ok() || !guess->accel) {
      return make_error(Errc::kInvalidArgument,
                        "stream " + info.name +
                            " is in raw counts and its log gives no full-scale range: the thermal model of " +
                            source + " (SI) cannot be converted to counts");
    }
    applied.model = thermal_model_on_input_units(applied.model, info, *guess->accel, guess->gyro);
  }
  auto corrected = correct_to_reference_temperature(samples, info, applied.model);
  if (!corrected.ok()) return corrected.error();
  applied.correction = *corrected;
  for (const std::string& w : {corrected->warning(), thermal_uncertainty_warning(result, corrected->mean_c)})
    if (!w.empty()) applied.warnings.push_back(w + " (" + source + ")");
  return applied;
}

Result<AppliedThermal> apply_thermal_file(const ThermalFile& file, std::vector<ImuSample>& samples,
                                          const ImuStreamInfo& info) {
  auto applied = apply_thermal(file.result, samples, info, file.path);
  if (!applied.ok()) return applied.error().context("the thermal model " + file.path);
  if (!file.stream.empty() && file.stream != info.name) {
    applied->warnings.insert(applied->warnings.begin(), "the thermal model " + file.path + " is of stream " +
                                                            file.stream + " (" + file.log +
                                                            "), applied to stream " + info.name);
  }
  return applied;
}

Result<calib::ThermalScalePoint> scale_point_from_log(const std::string& path, const std::string& stream,
                                                      std::vector<std::string>& warnings) {
  auto loaded = load_imu_stream(path, stream, DamagePolicy::kRefuse);
  if (!loaded.ok()) return loaded.error().context("--scale-from " + path);
  const ImuStreamInfo& info = loaded->info;
  calib::ThermalScalePoint p;
  p.source = path;
  double sum = 0.0, lo = std::numeric_limits<double>::infinity(), hi = -lo;
  std::size_t n = 0;
  for (const ImuSample& s : loaded->samples) {
    if (!std::isfinite(s.temperature)) continue;
    const double t = info.temperature_scale * s.temperature + info.temperature_offset;
    if (!is_die_temperature(t)) {
      return make_error(Errc::kCorrupt, "--scale-from " + path + ": the sample at t_ns " +
                                            std::to_string(s.t_ns) + " gives a die temperature of " +
                                            format_number("%g", t) +
                                            " deg C, which no die reaches: its temperatures are wrong");
    }
    sum += t, lo = std::min(lo, t), hi = std::max(hi, t), ++n;
  }
  if (n == 0) {
    return make_error(Errc::kInsufficientData,
                      "--scale-from " + path +
                          ": its samples carry no die temperature, so it cannot be placed on "
                          "the temperature axis; record with the temperature (imucal record writes it)");
  }
  p.temperature_c = sum / static_cast<double>(n);
  p.temperature_span_c = hi - lo;
  if (p.temperature_span_c > 2.0)
    warnings.push_back("--scale-from " + path + ": the die moved by " + fixed(p.temperature_span_c, 2) +
                       " deg C over it; its scale is taken at its mean temperature " +
                       fixed(p.temperature_c, 2) + " deg C");
  calib::StaticCalibrationOptions options;
  auto guess = nominal_guess(info, {});
  if (!guess.ok()) return guess.error().context("--scale-from " + path);
  options.accel_init = guess->accel;
  options.gyro_init = guess->gyro;
  auto result = app::calibrate_static(loaded->samples, options);
  if (!result.ok())
    return result.error().context("--scale-from " + path +
                                  " (a recording of static poses, as calibrate static takes)");
  p.gyro = result->model.gyro.scale;
  p.gyro_sigma = result->gyro_sigma.scale;
  p.accel = result->model.accel.scale;
  p.accel_sigma = result->accel_sigma.scale;
  return p;
}

}  // namespace imucal::app
