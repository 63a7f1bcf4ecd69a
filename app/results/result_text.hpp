// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Pieces the result writers and readers of app/results share (internal to them): matrices,
// vectors, triads, error figures and static intervals as JSON and as YAML, and read back.

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "calib/static_calibration.hpp"
#include "core/calibration_record.hpp"
#include "core/imu.hpp"
#include "core/imu_model.hpp"
#include "core/thermal_model.hpp"

namespace imucal::app::result_text {

using nlohmann::json;

inline json mat_json(const Eigen::Matrix3d& m) {
  json j = json::array();
  for (int r = 0; r < 3; ++r) j.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return j;
}
inline json vec_json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

// Reading a result's JSON form (a YAML result through yaml_to_json): a key of the wrong shape
// throws, and the reader says which file (kCorrupt).
template <int N>
Eigen::Matrix<double, N, 1> read_vec(const json& j) {
  if (!j.is_array() || j.size() != N) throw std::runtime_error("expected " + std::to_string(N) + " numbers");
  Eigen::Matrix<double, N, 1> v;
  for (int i = 0; i < N; ++i) v[i] = j[i].is_null() ? std::nan("") : j[i].get<double>();
  return v;
}
template <int R, int C>
Eigen::Matrix<double, R, C> read_mat(const json& j) {
  if (!j.is_array() || j.size() != R) throw std::runtime_error("expected " + std::to_string(R) + " rows");
  Eigen::Matrix<double, R, C> m;
  for (int r = 0; r < R; ++r) m.row(r) = read_vec<C>(j[r]).transpose();
  return m;
}
/// A list of numbers of any length, null as NaN (not determined).
inline std::vector<double> read_list(const json& j) {
  if (!j.is_array()) throw std::runtime_error("expected a list of numbers");
  std::vector<double> v;
  for (const json& x : j) v.push_back(x.is_null() ? std::nan("") : x.get<double>());
  return v;
}
/// The canonical block (A_a, b_a, A_g, b_g, G) of a result; every entry finite.
inline CanonicalImuModel read_canonical(const json& j) {
  // Each entry's problem named by its key.
  const auto entry = [&j](const char* key, auto& out) {
    using M = std::remove_reference_t<decltype(out)>;
    try {
      if constexpr (M::ColsAtCompileTime == 1) {
        out = read_vec<M::RowsAtCompileTime>(j.at(key));
      } else {
        out = read_mat<M::RowsAtCompileTime, M::ColsAtCompileTime>(j.at(key));
      }
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string("canonical.") + key + ": " + e.what());
    }
    if (!out.allFinite())
      throw std::runtime_error(std::string("canonical.") + key + ": must be finite numbers");
  };
  CanonicalImuModel c;
  entry("A_a", c.A_a);
  entry("b_a", c.b_a);
  entry("A_g", c.A_g);
  entry("b_g", c.b_g);
  entry("G", c.G);
  return c;
}
/// A stream's units by name ("si", "raw").
inline ImuUnits read_units(const json& j) {
  const std::string name = j.get<std::string>();
  for (ImuUnits u : {ImuUnits::kSi, ImuUnits::kRaw})
    if (name == imu_units_name(u)) return u;
  throw std::runtime_error("input_units '" + name + "' is neither " + imu_units_name(ImuUnits::kSi) +
                           " nor " + imu_units_name(ImuUnits::kRaw));
}
/// A thermal model as result files write it (emit_thermal), when present.
inline std::optional<ThermalModel> read_thermal(const json& r) {
  if (!r.contains("thermal") || r["thermal"].is_null()) return std::nullopt;
  auto thermal = thermal_model_from_json(r["thermal"]);
  if (!thermal.ok()) throw std::runtime_error(thermal.error().message);
  return *thermal;
}

inline json figures_json(const calib::ErrorFigures& f) {
  return {{"count", f.count},
          {"mean_mps2", f.mean_mps2},
          {"max_mps2", f.max_mps2},
          {"mean_rad", f.mean_rad},
          {"max_rad", f.max_rad}};
}

/// One triad in the JSON convention corrected = misalignment * diag(scale) * (raw - bias).
inline json triad_json(const TedaldiTriad& t, const calib::TriadSigma& s) {
  return {
      {"misalignment", mat_json(t.T)},
      {"scale", vec_json(t.scale)},
      {"bias", vec_json(-t.bias)},
      {"sigma", {{"misalignment", mat_json(s.T)}, {"scale", vec_json(s.scale)}, {"bias", vec_json(s.bias)}}}};
}

inline json intervals_json(const calib::StaticCalibrationResult& r) {
  json intervals = json::array();
  for (const auto& iv : r.intervals) {
    intervals.push_back({{"t0_s", ns_to_s(iv.t0_ns - r.intervals.front().t0_ns)},
                         {"t1_s", ns_to_s(iv.t1_ns - r.intervals.front().t0_ns)},
                         {"t0_ns", iv.t0_ns},
                         {"t1_ns", iv.t1_ns},
                         {"samples", iv.samples}});
  }
  return intervals;
}

/// The thermal model the samples were corrected with (the record's "thermal" block) and its
/// reference temperature, when there is one.
inline void emit_thermal(YAML::Emitter& y, const std::optional<ThermalModel>& thermal) {
  if (!thermal) return;
  y << YAML::Key << "reference_temperature_c" << YAML::Value << thermal->reference_c;
  y << YAML::Key << "thermal" << YAML::Value
    << YAML::Load(thermal_model_json(*thermal).dump(-1, ' ', false, json::error_handler_t::replace));
}

inline void emit_matrix(YAML::Emitter& y, const std::string& key, const Eigen::Matrix3d& m) {
  y << YAML::Key << key << YAML::Value << YAML::BeginSeq;
  for (int r = 0; r < 3; ++r)
    y << YAML::Flow << YAML::BeginSeq << m(r, 0) << m(r, 1) << m(r, 2) << YAML::EndSeq;
  y << YAML::EndSeq;
}
inline void emit_vector(YAML::Emitter& y, const std::string& key, const Eigen::Vector3d& v) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq << v[0] << v[1] << v[2]
    << YAML::EndSeq;
}
inline void emit_triad(YAML::Emitter& y, const std::string& key, const TedaldiTriad& t,
                       const calib::TriadSigma& s) {
  y << YAML::Key << key << YAML::Value << YAML::BeginMap;
  emit_matrix(y, "misalignment", t.T);
  emit_vector(y, "scale", t.scale);
  emit_vector(y, "bias", -t.bias);
  y << YAML::Key << "sigma" << YAML::Value << YAML::BeginMap;
  emit_matrix(y, "misalignment", s.T);
  emit_vector(y, "scale", s.scale);
  emit_vector(y, "bias", s.bias);
  y << YAML::EndMap << YAML::EndMap;
}
inline void emit_figures(YAML::Emitter& y, const std::string& key, const calib::ErrorFigures& f) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "mean_mps2"
    << YAML::Value << f.mean_mps2 << YAML::Key << "max_mps2" << YAML::Value << f.max_mps2 << YAML::Key
    << "mean_rad" << YAML::Value << f.mean_rad << YAML::Key << "max_rad" << YAML::Value << f.max_rad
    << YAML::EndMap;
}

}  // namespace imucal::app::result_text
