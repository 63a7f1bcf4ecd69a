// SPDX-License-Identifier: BSD-3-Clause
#include "sim/truth.hpp"

#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "core/text_file.hpp"
#include "core/version.hpp"
#include "log/dataset_io.hpp"

namespace imucal::sim {
namespace {

YAML::Node vec(const Eigen::Vector3d& v) {
  YAML::Node n;
  for (int i = 0; i < 3; ++i) n.push_back(v[i]);
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}

YAML::Node mat(const Eigen::Matrix3d& m) {
  YAML::Node n;
  for (int r = 0; r < 3; ++r) n.push_back(vec(m.row(r).transpose()));
  return n;
}

YAML::Node quat(const Eigen::Quaterniond& q) {
  YAML::Node n;
  n.push_back(q.w());
  n.push_back(q.x());
  n.push_back(q.y());
  n.push_back(q.z());
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}

YAML::Node canonical_node(const CanonicalImuModel& c) {
  YAML::Node n;
  n["A_a"] = mat(c.A_a);
  n["b_a"] = vec(c.b_a);
  n["A_g"] = mat(c.A_g);
  n["b_g"] = vec(c.b_g);
  n["G"] = mat(c.G);
  return n;
}

YAML::Node tedaldi_node(const TedaldiImuModel& t) {
  YAML::Node n;
  n["T_a"] = mat(t.accel.T);
  n["K_a"] = vec(t.accel.scale);
  n["b_a"] = vec(t.accel.bias);
  n["T_g"] = mat(t.gyro.T);
  n["K_g"] = vec(t.gyro.scale);
  n["b_g"] = vec(t.gyro.bias);
  return n;
}

// --- reading, with errors that name the key -------------------------------------------------

struct Reader {
  std::string source;
  std::string error;

  bool fail(const std::string& key, const std::string& what) {
    if (error.empty()) error = source + ": " + key + ": " + what;
    return false;
  }
  bool num(const YAML::Node& n, const std::string& key, double* out) {
    if (!n.IsScalar()) return fail(key, "expected a number");
    try {
      *out = n.as<double>();
    } catch (const YAML::Exception&) {
      return fail(key, "expected a number, got '" + n.Scalar() + "'");
    }
    return true;
  }
  bool vec3(const YAML::Node& n, const std::string& key, Eigen::Vector3d* out) {
    if (!n.IsSequence() || n.size() != 3) return fail(key, "expected a list of 3 numbers");
    for (int i = 0; i < 3; ++i)
      if (!num(n[i], key, &(*out)[i])) return false;
    return true;
  }
  bool mat3(const YAML::Node& n, const std::string& key, Eigen::Matrix3d* out) {
    if (!n.IsSequence() || n.size() != 3) return fail(key, "expected 3 rows of 3 numbers");
    for (int r = 0; r < 3; ++r) {
      Eigen::Vector3d row;
      if (!vec3(n[r], key, &row)) return false;
      out->row(r) = row.transpose();
    }
    return true;
  }
  // Optional keys keep the default when absent.
  bool opt_num(const YAML::Node& parent, const char* k, const std::string& path, double* out) {
    const YAML::Node n = parent[k];
    return !n ? true : num(n, path + "." + k, out);
  }
  bool opt_vec(const YAML::Node& parent, const char* k, const std::string& path, Eigen::Vector3d* out) {
    const YAML::Node n = parent[k];
    return !n ? true : vec3(n, path + "." + k, out);
  }
  bool opt_mat(const YAML::Node& parent, const char* k, const std::string& path, Eigen::Matrix3d* out) {
    const YAML::Node n = parent[k];
    return !n ? true : mat3(n, path + "." + k, out);
  }
  bool opt_int(const YAML::Node& parent, const char* k, const std::string& path, int* out) {
    double v = *out;
    if (!opt_num(parent, k, path, &v)) return false;
    if (v != std::floor(v)) return fail(path + "." + k, "expected an integer");
    *out = static_cast<int>(v);
    return true;
  }
  bool opt_bool(const YAML::Node& parent, const char* k, const std::string& path, bool* out) {
    const YAML::Node n = parent[k];
    if (!n) return true;
    try {
      *out = n.as<bool>();
    } catch (const YAML::Exception&) {
      return fail(path + "." + k, "expected true or false");
    }
    return true;
  }
};

}  // namespace

CanonicalImuModel canonical_correction(const ImuModelParams& p, bool counts) {
  // a_raw = S_a M_a f + b_a  =>  f = (S_a M_a)^-1 (a_raw - b_a)
  // w_raw = S_g M_g C_bg^T w + B_g f + b_g  =>  w = A_g (w_raw - b_g) - A_g B_g f
  CanonicalImuModel c;
  c.A_a = p.accel_matrix().inverse();
  c.b_a = p.accel_bias;
  c.A_g = p.gyro_matrix().inverse();
  c.b_g = p.gyro_bias;
  c.G = c.A_g * p.g_sensitivity;
  if (counts) {
    const double sa = p.accel_mps2_per_count(), sg = p.gyro_radps_per_count();
    c.A_a *= sa;
    c.b_a /= sa;
    c.A_g *= sg;
    c.b_g /= sg;
  }
  return c;
}

CanonicalImuModel canonical_in_tedaldi_frame(const ImuModelParams& p, bool counts) {
  return canonical_in_aof(canonical_correction(p, counts)).model;
}

TedaldiConversion tedaldi_form(const ImuModelParams& p, bool counts) {
  // The Tedaldi form has no g-sensitivity: G stays out, as in tedaldi_from_canonical, which
  // refuses a model with G rather than dropping it.
  const CanonicalInAof o = canonical_in_aof(canonical_correction(p, counts));
  TedaldiConversion t;
  t.R_canonical_aof = o.R_canonical_aof;
  t.model.accel = tedaldi_triad(o.model.A_a, o.model.b_a);
  t.model.gyro = tedaldi_triad(o.model.A_g, o.model.b_g);
  return t;
}

YAML::Node imu_params_to_yaml(const ImuModelParams& p) {
  YAML::Node n;
  YAML::Node a;
  a["scale"] = vec(p.accel_scale);
  a["misalignment"] = mat(p.accel_misalignment);
  a["bias_mps2"] = vec(p.accel_bias);
  a["noise_density"] = p.accel_noise_density;
  a["bias_random_walk"] = p.accel_bias_random_walk;
  a["bias_temp_coeff"] = vec(p.accel_bias_temp_coeff);
  a["bias_temp_coeff2"] = vec(p.accel_bias_temp_coeff2);
  a["bias_temp_coeff3"] = vec(p.accel_bias_temp_coeff3);
  a["scale_temp_coeff"] = vec(p.accel_scale_temp_coeff);
  a["full_scale_g"] = p.accel_full_scale_g;
  n["accel"] = a;
  YAML::Node g;
  g["scale"] = vec(p.gyro_scale);
  g["misalignment"] = mat(p.gyro_misalignment);
  g["q_body_gyro"] = quat(p.q_body_gyro);
  g["g_sensitivity"] = mat(p.g_sensitivity);
  g["bias_radps"] = vec(p.gyro_bias);
  g["noise_density"] = p.gyro_noise_density;
  g["bias_random_walk"] = p.gyro_bias_random_walk;
  g["bias_temp_coeff"] = vec(p.gyro_bias_temp_coeff);
  g["bias_temp_coeff2"] = vec(p.gyro_bias_temp_coeff2);
  g["bias_temp_coeff3"] = vec(p.gyro_bias_temp_coeff3);
  g["scale_temp_coeff"] = vec(p.gyro_scale_temp_coeff);
  g["full_scale_dps"] = p.gyro_full_scale_dps;
  n["gyro"] = g;
  n["gravity_mps2"] = p.gravity_mps2;
  n["earth_rotation"] = p.earth_rotation;
  n["latitude_deg"] = p.latitude_deg;
  YAML::Node t;
  t["profile"] = temperature_profile_name(p.temp_profile);
  t["start_c"] = p.temp_start_c;
  t["final_c"] = p.temp_final_c;
  t["time_constant_s"] = p.temp_time_constant_s;
  t["ramp_s"] = p.temp_ramp_s;
  t["step_time_s"] = p.temp_step_time_s;
  // The bias_temp_coeff* above are of (T - reference_c)^j: the start temperature.
  t["reference_c"] = p.temp_ref_c();
  // The scale_temp_coeff above: relative per K of (T - scale_reference_c).
  t["scale_reference_c"] = ImuModelParams::kScaleTempRefC;
  n["temperature"] = t;
  return n;
}

Result<ImuModelParams> imu_params_from_yaml(const YAML::Node& node, const std::string& source) {
  if (!node.IsMap()) return make_error(Errc::kCorrupt, source + ": expected a map of IMU parameters");
  Reader rd{source, {}};
  ImuModelParams p;
  const YAML::Node a = node["accel"], g = node["gyro"], t = node["temperature"];
  if (!a || !g) {
    return make_error(Errc::kCorrupt, source + ": needs 'accel' and 'gyro' sections (see docs/simulator.md)");
  }
  Eigen::Vector4d q(1, 0, 0, 0);
  bool ok = rd.opt_vec(a, "scale", "imu.accel", &p.accel_scale) &&
            rd.opt_mat(a, "misalignment", "imu.accel", &p.accel_misalignment) &&
            rd.opt_vec(a, "bias_mps2", "imu.accel", &p.accel_bias) &&
            rd.opt_num(a, "noise_density", "imu.accel", &p.accel_noise_density) &&
            rd.opt_num(a, "bias_random_walk", "imu.accel", &p.accel_bias_random_walk) &&
            rd.opt_vec(a, "bias_temp_coeff", "imu.accel", &p.accel_bias_temp_coeff) &&
            rd.opt_vec(a, "bias_temp_coeff2", "imu.accel", &p.accel_bias_temp_coeff2) &&
            rd.opt_vec(a, "bias_temp_coeff3", "imu.accel", &p.accel_bias_temp_coeff3) &&
            rd.opt_vec(a, "scale_temp_coeff", "imu.accel", &p.accel_scale_temp_coeff) &&
            rd.opt_int(a, "full_scale_g", "imu.accel", &p.accel_full_scale_g) &&
            rd.opt_vec(g, "scale", "imu.gyro", &p.gyro_scale) &&
            rd.opt_mat(g, "misalignment", "imu.gyro", &p.gyro_misalignment) &&
            rd.opt_mat(g, "g_sensitivity", "imu.gyro", &p.g_sensitivity) &&
            rd.opt_vec(g, "bias_radps", "imu.gyro", &p.gyro_bias) &&
            rd.opt_num(g, "noise_density", "imu.gyro", &p.gyro_noise_density) &&
            rd.opt_num(g, "bias_random_walk", "imu.gyro", &p.gyro_bias_random_walk) &&
            rd.opt_vec(g, "bias_temp_coeff", "imu.gyro", &p.gyro_bias_temp_coeff) &&
            rd.opt_vec(g, "bias_temp_coeff2", "imu.gyro", &p.gyro_bias_temp_coeff2) &&
            rd.opt_vec(g, "bias_temp_coeff3", "imu.gyro", &p.gyro_bias_temp_coeff3) &&
            rd.opt_vec(g, "scale_temp_coeff", "imu.gyro", &p.gyro_scale_temp_coeff) &&
            rd.opt_int(g, "full_scale_dps", "imu.gyro", &p.gyro_full_scale_dps) &&
            rd.opt_num(node, "gravity_mps2", "imu", &p.gravity_mps2) &&
            rd.opt_bool(node, "earth_rotation", "imu", &p.earth_rotation) &&
            rd.opt_num(node, "latitude_deg", "imu", &p.latitude_deg);
  if (ok && g["q_body_gyro"]) {
    const YAML::Node qn = g["q_body_gyro"];
    if (!qn.IsSequence() || qn.size() != 4) {
      ok = rd.fail("imu.gyro.q_body_gyro", "expected [w, x, y, z]");
    } else {
      for (int i = 0; i < 4 && ok; ++i) ok = rd.num(qn[i], "imu.gyro.q_body_gyro", &q[i]);
    }
  }
  if (ok && t) {
    ok = rd.opt_num(t, "start_c", "imu.temperature", &p.temp_start_c) &&
         rd.opt_num(t, "final_c", "imu.temperature", &p.temp_final_c) &&
         rd.opt_num(t, "time_constant_s", "imu.temperature", &p.temp_time_constant_s) &&
         rd.opt_num(t, "ramp_s", "imu.temperature", &p.temp_ramp_s) &&
         rd.opt_num(t, "step_time_s", "imu.temperature", &p.temp_step_time_s);
    if (ok && t["profile"]) {
      auto profile = parse_temperature_profile(t["profile"].as<std::string>(""));
      if (profile.ok()) {
        p.temp_profile = *profile;
      } else {
        ok = rd.fail("imu.temperature.profile", profile.error().message);
      }
    }
  }
  if (!ok) return make_error(Errc::kCorrupt, rd.error);
  p.q_body_gyro = Eigen::Quaterniond(q[0], q[1], q[2], q[3]);
  if (std::abs(p.q_body_gyro.norm() - 1.0) > 1e-6) {
    return make_error(Errc::kCorrupt,
                      source + ": imu.gyro.q_body_gyro is not a unit quaternion [w, x, y, z]");
  }
  auto status = p.validate();
  if (!status.ok()) return make_error(Errc::kCorrupt, source + ": " + status.error().message);
  return p;
}

Result<ImuModelParams> load_imu_params(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error().context("cannot read the truth file");
  YAML::Node doc;
  try {
    doc = YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path + ": not valid YAML (" + e.msg + ", line " +
                                          std::to_string(e.mark.line + 1) + ")");
  }
  if (!doc.IsMap()) {
    return make_error(Errc::kCorrupt, path + ": expected a truth file written by 'imucal sim' (a YAML map)");
  }
  return imu_params_from_yaml(doc["imu"] ? doc["imu"] : doc, path);
}

YAML::Node truth_to_yaml(const SimTruth& truth) {
  YAML::Node doc;
  doc["software_version"] = std::string(kVersion);
  doc["kind"] = truth.kind;
  doc["seed"] = truth.seed;
  doc["params_from_file"] = truth.params_from_file;
  doc["frames"] =
      "body = accelerometer orthogonal frame (x along the accel x axis, y in the accel x-y plane); "
      "world z up, gravity (0, 0, -g)";
  doc["imu"] = imu_params_to_yaml(truth.imu);

  YAML::Node canon;
  canon["note"] = "a = A_a (a_raw - b_a), w = A_g (w_raw - b_g) - G a, body frame, turn-on biases";
  canon["si"] = canonical_node(canonical_correction(truth.imu, false));
  canon["counts"] = canonical_node(canonical_correction(truth.imu, true));
  doc["canonical"] = canon;

  const TedaldiConversion ts = tedaldi_form(truth.imu, false);
  // Body vectors -> frame O.
  const Eigen::Quaterniond q_tedaldi_body =
      Eigen::Quaterniond(Eigen::Matrix3d(ts.R_canonical_aof.transpose())).normalized();
  YAML::Node ted;
  ted["note"] =
      "a_O = T_a K_a (a_S + b_a), w_O = T_g K_g (w_S + b_g) (Tedaldi eqs. 2.6, 2.7); frame O has z along the "
      "accel z axis; q_tedaldi_body rotates body vectors into O; canonical_* is the canonical correction in "
      "O";
  ted["q_tedaldi_body"] = quat(q_tedaldi_body);
  ted["angle_deg"] = Eigen::AngleAxisd(q_tedaldi_body).angle() * 180.0 / std::numbers::pi;
  ted["si"] = tedaldi_node(ts.model);
  ted["counts"] = tedaldi_node(tedaldi_form(truth.imu, true).model);
  ted["canonical_si"] = canonical_node(canonical_in_tedaldi_frame(truth.imu, false));
  ted["canonical_counts"] = canonical_node(canonical_in_tedaldi_frame(truth.imu, true));
  doc["tedaldi"] = ted;

  YAML::Node tr;
  tr["script"] = truth.trajectory.script;
  tr["duration_s"] = truth.trajectory.duration_s;
  tr["poses"] = truth.trajectory.poses;
  tr["mean_accel_mps2"] = truth.trajectory.mean_accel_mps2;
  tr["mean_rate_radps"] = truth.trajectory.mean_rate_radps;
  tr["max_accel_mps2"] = truth.trajectory.max_accel_mps2;
  tr["max_rate_radps"] = truth.trajectory.max_rate_radps;
  YAML::Node segs;
  for (const Segment& s : truth.trajectory.segments) {
    YAML::Node sn;
    sn.push_back(s.kind);
    sn.push_back(s.t0_ns);
    sn.push_back(s.t1_ns);
    sn.SetStyle(YAML::EmitterStyle::Flow);
    segs.push_back(sn);
  }
  tr["segments_note"] = "[kind, t0_ns, t1_ns]";
  tr["segments"] = segs;
  doc["trajectory"] = tr;

  const RecordingSummary& r = truth.recording;
  YAML::Node rec;
  rec["imu_rate_hz"] = r.imu_rate_hz;
  rec["samples"] = r.samples;
  rec["dropped_samples"] = r.dropped_samples;
  rec["accel_saturated_samples"] = r.accel_saturated;
  rec["gyro_saturated_samples"] = r.gyro_saturated;
  rec["accel_bias_mean_mps2"] = vec(r.accel_bias_mean);
  rec["gyro_bias_mean_radps"] = vec(r.gyro_bias_mean);
  rec["accel_bias_end_mps2"] = vec(r.accel_bias_end);
  rec["gyro_bias_end_radps"] = vec(r.gyro_bias_end);
  rec["temperature_start_c"] = r.temperature_start_c;
  rec["temperature_end_c"] = r.temperature_end_c;
  doc["recording"] = rec;
  return doc;
}

Status write_truth_yaml(const std::string& path, const YAML::Node& doc, bool overwrite) {
  std::error_code ec;
  // A device, FIFO, socket or folder at the path is never replaced, overwrite or not.
  IMUCAL_TRY(log::check_replaceable(path));
  if (!overwrite && std::filesystem::exists(path, ec)) {
    return make_error(Errc::kAlreadyExists, path + " already exists");
  }
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::Comment("Ground truth of a simulated recording (imucal sim); format: docs/simulator.md");
  out << doc;
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) return make_error(Errc::kIo, "cannot write " + tmp);
    f << out.c_str() << "\n";
    if (!f.flush()) return make_error(Errc::kIo, "cannot write " + tmp);
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) return make_error(Errc::kIo, "cannot rename " + tmp + " to " + path + ": " + ec.message());
  return {};
}

std::string truth_path_for(const std::string& log_path) {
  const std::string ext = ".imulog";
  if (log_path.size() > ext.size() && log_path.compare(log_path.size() - ext.size(), ext.size(), ext) == 0) {
    return log_path.substr(0, log_path.size() - ext.size()) + ".truth.yaml";
  }
  return log_path + ".truth.yaml";
}

}  // namespace imucal::sim
