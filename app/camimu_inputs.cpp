// SPDX-License-Identifier: BSD-3-Clause
#include "app/camimu_inputs.hpp"

#include <yaml-cpp/yaml.h>

#include <array>
#include <cmath>
#include <limits>
#include <set>

#include "app/results/static_results.hpp"
#include "core/text_file.hpp"

namespace imucal::app {
namespace {

Result<YAML::Node> load_yaml(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  try {
    return YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path + ": not valid YAML (" + e.msg + ", line " +
                                          std::to_string(e.mark.line + 1) + ")");
  }
}

/// The stream name a Kalibr topic stands for: /cam0/image_raw -> cam0.
std::string stream_of_topic(std::string topic) {
  while (!topic.empty() && topic.front() == '/') topic.erase(topic.begin());
  for (const char* tail : {"/image_raw", "/image"}) {
    const std::string t = tail;
    if (topic.size() > t.size() && topic.compare(topic.size() - t.size(), t.size(), t) == 0) {
      topic.resize(topic.size() - t.size());
      break;
    }
  }
  return topic;
}

std::optional<int> stream_named(const std::string& name, const std::map<int, CameraStreamInfo>& streams) {
  if (name.empty()) return std::nullopt;
  for (const auto& [id, info] : streams) {
    if (info.name == name) return id;
  }
  return std::nullopt;
}

/// The stream imported from a ROS bag's topic `topic` (its device is "rosbag:TOPIC").
std::optional<int> stream_of_bag_topic(const std::string& topic,
                                       const std::map<int, CameraStreamInfo>& streams) {
  if (topic.empty()) return std::nullopt;
  for (const auto& [id, info] : streams) {
    if (info.device == "rosbag:" + topic) return id;
  }
  return std::nullopt;
}

std::string stream_list(const std::map<int, CameraStreamInfo>& streams) {
  std::string names;
  for (const auto& [id, info] : streams) names += (names.empty() ? "" : ", ") + info.name;
  return names.empty() ? "none" : names;
}

/// A static result on the stream's nominal SI values; its units must be the stream's.
Result<CanonicalImuModel> model_on_nominal_si(const NamedCalibration& c, const ImuStreamInfo& info,
                                              std::vector<std::string>* notes) {
  if (c.input_units && *c.input_units != info.units) {
    return make_error(Errc::kInvalidArgument,
                      c.path + " is a calibration for " + imu_units_name(*c.input_units) +
                          " values, but IMU stream '" + info.name + "' holds " + imu_units_name(info.units) +
                          " values: give a calibration of this stream");
  }
  if (!c.input_units) {
    notes->push_back(c.path + " does not say its input units: taken as the stream's (" +
                     imu_units_name(info.units) + ")");
  }
  return canonical_on_nominal_si(c.model, info);
}

}  // namespace

namespace {

/// A camera's T_cn_cnm1 (4 rows of 4, a rigid transform) and, when imucal wrote the file, the
/// covariance under `imucal: T_cn_cnm1_covariance` (6 rows of 6; absent or with a null: none).
Result<std::pair<Eigen::Isometry3d, std::optional<Eigen::Matrix<double, 6, 6>>>> read_chain_pose(
    const YAML::Node& node, const std::string& where) {
  Eigen::Matrix4d m;
  try {
    const YAML::Node rows = node["T_cn_cnm1"];
    if (!rows.IsSequence() || rows.size() != 4) throw YAML::Exception(YAML::Mark(), "4 rows");
    for (int r = 0; r < 4; ++r) {
      if (!rows[r].IsSequence() || rows[r].size() != 4) throw YAML::Exception(YAML::Mark(), "4 columns");
      for (int c = 0; c < 4; ++c) m(r, c) = rows[r][c].as<double>();
    }
  } catch (const YAML::Exception&) {
    return make_error(Errc::kCorrupt, where + ": T_cn_cnm1 must be 4 rows of 4 numbers");
  }
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  if (!m.allFinite() || !(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
      R.determinant() < 0 || !m.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1))) {
    return make_error(Errc::kCorrupt, where + ": T_cn_cnm1 is not a rigid transform");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = m.topRightCorner<3, 1>();
  std::optional<Eigen::Matrix<double, 6, 6>> cov;
  const YAML::Node c = node["imucal"] ? node["imucal"]["T_cn_cnm1_covariance"] : YAML::Node();
  if (c && c.IsSequence() && c.size() == 6) {
    Eigen::Matrix<double, 6, 6> C;
    bool ok = true;
    for (int r = 0; ok && r < 6; ++r) {
      ok = c[r].IsSequence() && c[r].size() == 6;
      for (int k = 0; ok && k < 6; ++k) {
        ok = c[r][k].IsScalar();
        if (ok) {
          try {
            C(r, k) = c[r][k].as<double>();
          } catch (const YAML::Exception&) {
            ok = false;
          }
        }
      }
    }
    if (ok && C.allFinite()) cov = C;
  }
  return std::make_pair(T, cov);
}

/// A number of the file, or NaN for null.
double number_or_nan(const YAML::Node& n) {
  return n.IsNull() ? std::numeric_limits<double>::quiet_NaN() : n.as<double>();
}

/// The intrinsics' covariance a camera's `imucal:` map gives (CamchainCamera's doc): the file
/// holds it in Kalibr's order of the model's n parameters, n x n.
Status read_intrinsics_covariance(const YAML::Node& node, const std::string& where, CamchainCamera* cam) {
  const YAML::Node q = node["imucal"];
  if (!q || !q.IsMap()) return {};
  const std::vector<int> order = kalibr_parameter_indices(cam->camera.kind());
  const auto n = static_cast<int>(order.size());
  std::string names;
  for (const std::string& name : kalibr_parameter_names(cam->camera.kind()))
    names += (names.empty() ? "" : ", ") + name;
  const std::string bad = where + ": imucal.intrinsics_covariance must be " + std::to_string(n) +
                          " rows of " + std::to_string(n) + " numbers (or null), in the order " + names;
  try {
    if (const YAML::Node c = q["intrinsics_covariance"]) {
      if (!c.IsSequence() || static_cast<int>(c.size()) != n) return make_error(Errc::kCorrupt, bad);
      Eigen::MatrixXd C = Eigen::MatrixXd::Zero(10, 10);
      for (int r = 0; r < n; ++r) {
        if (!c[r].IsSequence() || static_cast<int>(c[r].size()) != n) return make_error(Errc::kCorrupt, bad);
        for (int k = 0; k < n; ++k) C(order[r], order[k]) = number_or_nan(c[r][k]);
      }
      for (int r = 0; r < 10; ++r)
        if (C(r, r) < 0.0)
          return make_error(Errc::kCorrupt, where + ": imucal.intrinsics_covariance has a negative variance");
      cam->intrinsics_covariance = C;
      cam->intrinsics_covariance_source = "the covariance of " + where;
      return {};
    }
    // Sigmas alone are not propagated: the intrinsics' errors are strongly correlated (focal
    // length with distortion, principal point with tilt), and taken as independent they overstate
    // the extrinsics' sigmas many times over (a 13 mm translation sigma instead of 0.4 mm on the
    // DAVIS recording of docs/benchmarks.md).
    if (q["intrinsics_sigma"])
      cam->intrinsics_covariance_source =
          where +
          " gives the intrinsics' sigmas but not their covariance (a file of an older imucal: run "
          "calibrate camera again to have it propagated)";
  } catch (const YAML::Exception&) {
    return make_error(Errc::kCorrupt, bad);
  }
  return {};
}

}  // namespace

std::pair<std::string, std::string> stamp_row_from_stream(const CameraStreamInfo& stream, bool given,
                                                          const std::string& who, Shutter* shutter) {
  const auto logged = stamp_row_of_timestamp_source(stream.timestamp_source);
  if (!logged || *logged == shutter->stamp_row) return {};
  const std::string row = stamp_row_name(*logged);
  if (given) {
    return {"", who + " says its stamps refer to the " + stamp_row_name(shutter->stamp_row) +
                    " row, but the log's camera stream '" + stream.name + "' stamps its frames at " +
                    stream.timestamp_source + " (the " + row +
                    " row): the camera's is used; a rolling shutter's time offset and line delay depend on "
                    "which is right (--stamp-row)"};
  }
  shutter->stamp_row = *logged;
  return {who + ": the log's camera stream '" + stream.name + "' stamps its frames at " +
              stream.timestamp_source + ", so a rolling shutter's rows are timed from the " + row +
              " row (--stamp-row to say otherwise)",
          ""};
}

void set_intrinsics_covariance(const calib::CameraIntrinsicsResult& solved, CamchainCamera* camera) {
  if (!solved.covariance_ok) return;
  camera->intrinsics_covariance = solved.covariance;
  camera->intrinsics_covariance_source = "the covariance of " + camera->source;
}

Result<std::vector<CamchainCamera>> read_camchain(const std::string& path) {
  auto root = load_yaml(path);
  if (!root.ok()) return root.error();
  if (!root->IsMap() || !(*root)["cam0"]) {
    return make_error(Errc::kCorrupt, path +
                                          ": no cam0 (expected a camchain YAML as imucal calibrate camera or "
                                          "Kalibr write it)");
  }
  std::vector<CamchainCamera> out;
  for (int i = 0;; ++i) {
    const std::string name = "cam" + std::to_string(i);
    const YAML::Node node = (*root)[name];
    if (!node) break;
    CamchainCamera cam;
    cam.name = name;
    cam.source = path;
    auto model = camera_from_yaml(node, path + " " + name);
    if (!model.ok()) return make_error(Errc::kCorrupt, model.error().message);
    cam.camera = *model;
    try {
      if (node["rostopic"]) cam.rostopic = node["rostopic"].as<std::string>();
      if (node["imucal"] && node["imucal"]["camera_stream"])
        cam.camera_stream = node["imucal"]["camera_stream"].as<std::string>();
      if (node["cam_overlaps"]) cam.cam_overlaps = node["cam_overlaps"].as<std::vector<int>>();
    } catch (const YAML::Exception&) {
      return make_error(Errc::kCorrupt,
                        path + " " + name +
                            ": rostopic and camera_stream must be text, cam_overlaps a list of "
                            "camera numbers");
    }
    if (Status st = read_intrinsics_covariance(node, path + " " + name, &cam); !st.ok()) return st.error();
    cam.stamp_row_given = static_cast<bool>(node["stamp_row"]);
    if (i > 0 && node["T_cn_cnm1"]) {
      auto chain = read_chain_pose(node, path + " " + name);
      if (!chain.ok()) return chain.error();
      cam.T_cn_cnm1 = chain->first;
      cam.T_cn_cnm1_covariance = chain->second;
    }
    out.push_back(std::move(cam));
  }
  return out;
}

Result<std::vector<CamchainCamera>> read_camchain_files(const std::vector<std::string>& paths) {
  if (paths.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no camera given: the camera-IMU calibration needs each camera's intrinsics (the YAML "
                      "of imucal calibrate camera, or a Kalibr camchain)")
        .with_remedy("camera");
  }
  std::vector<CamchainCamera> out;
  for (const auto& path : paths) {
    auto cams = read_camchain(path);
    if (!cams.ok()) return cams.error();
    const int first = static_cast<int>(out.size());
    for (std::size_t k = 0; k < cams->size(); ++k) {
      CamchainCamera& cam = (*cams)[k];
      if (cam.cam_overlaps) {
        for (int& other : *cam.cam_overlaps) other += first;  // the file's numbers, counted from its first
      }
      cam.source = path + " " + cam.name;
      cam.name = "cam" + std::to_string(out.size());
      cam.follows_in_file = k > 0;
      out.push_back(std::move(cam));
    }
  }
  return out;
}

Result<std::vector<int>> match_camera_streams(const std::vector<CamchainCamera>& cameras,
                                              const std::map<int, CameraStreamInfo>& streams) {
  std::vector<int> ids;
  std::set<int> used;
  for (const auto& cam : cameras) {
    std::optional<int> id = stream_named(cam.camera_stream, streams);
    if (!id) id = stream_of_bag_topic(cam.rostopic, streams);
    if (!id) id = stream_named(stream_of_topic(cam.rostopic), streams);
    if (!id && cameras.size() == 1 && streams.size() == 1) id = streams.begin()->first;
    if (!id) {
      return make_error(Errc::kNotFound, cam.source + " " + cam.name + " (camera_stream '" +
                                             cam.camera_stream + "', rostopic '" + cam.rostopic +
                                             "') names no camera stream of the log; its camera streams: " +
                                             stream_list(streams) +
                                             " (set the camera's rostopic to /STREAM/image_raw)");
    }
    if (!used.insert(*id).second) {
      return make_error(Errc::kInvalidArgument, cam.source + " " + cam.name + ": camera stream '" +
                                                    streams.at(*id).name + "' is given to two cameras");
    }
    ids.push_back(*id);
  }
  return ids;
}

Result<calib::CamImuNoise> read_kalibr_imu_noise(const std::string& path) {
  auto root = load_yaml(path);
  if (!root.ok()) return root.error();
  YAML::Node node = *root;
  if (node.IsMap() && !node["accelerometer_noise_density"] && node["imu0"]) node = node["imu0"];
  if (!node.IsMap())
    return make_error(Errc::kCorrupt, path + ": not a Kalibr imu.yaml (a map of noise figures)");
  calib::CamImuNoise noise;
  const std::array<std::pair<const char*, double*>, 4> keys{{
      {"accelerometer_noise_density", &noise.accel_noise_density},
      {"accelerometer_random_walk", &noise.accel_random_walk},
      {"gyroscope_noise_density", &noise.gyro_noise_density},
      {"gyroscope_random_walk", &noise.gyro_random_walk},
  }};
  for (const auto& [key, value] : keys) {
    if (!node[key]) return make_error(Errc::kCorrupt, path + ": " + key + " is missing (Kalibr imu.yaml)");
    try {
      *value = node[key].as<double>();
    } catch (const YAML::Exception&) {
      return make_error(Errc::kCorrupt, path + ": " + key + " is not a number");
    }
    if (!std::isfinite(*value) || *value <= 0.0)
      return make_error(Errc::kCorrupt, path + ": " + key + " must be a positive number");
  }
  return noise;
}

Result<KalibrImuTopic> read_kalibr_imu_topic(const std::string& path) {
  auto root = load_yaml(path);
  if (!root.ok()) return root.error();
  YAML::Node node = *root;
  if (node.IsMap() && !node["accelerometer_noise_density"] && node["imu0"]) node = node["imu0"];
  KalibrImuTopic out;
  if (!node.IsMap()) return out;
  try {
    if (node["rostopic"]) out.rostopic = node["rostopic"].as<std::string>();
    if (node["update_rate"]) out.update_rate = node["update_rate"].as<double>();
  } catch (const YAML::Exception&) {
    return make_error(Errc::kCorrupt,
                      path + ": rostopic must be text and update_rate a number (Kalibr imu.yaml)");
  }
  if (node["update_rate"] && !(std::isfinite(out.update_rate) && out.update_rate > 0.0))
    return make_error(Errc::kCorrupt, path + ": update_rate must be a positive number of Hz");
  return out;
}

std::string camera_rostopic(const CameraStreamInfo& stream) {
  const std::string bag = "rosbag:";
  if (stream.device.compare(0, bag.size(), bag) == 0) return stream.device.substr(bag.size());
  return "/" + stream.name + "/image_raw";
}

std::string imu_rostopic(const ImuStreamInfo& stream) {
  const std::string bag = "rosbag:";
  if (stream.device.compare(0, bag.size(), bag) == 0) return stream.device.substr(bag.size());
  return "/" + stream.name;
}

std::string imu_stream_of_topic(const std::map<int, ImuStreamInfo>& streams, const std::string& topic) {
  if (topic.empty()) return {};
  for (const auto& [id, info] : streams) {
    if (info.device == "rosbag:" + topic) return info.name;
  }
  std::string name = topic;
  while (!name.empty() && name.front() == '/') name.erase(name.begin());
  for (const auto& [id, info] : streams) {
    if (info.name == name) return info.name;
  }
  return {};
}

CanonicalImuModel canonical_on_nominal_si(const CanonicalImuModel& m, const ImuStreamInfo& info) {
  CanonicalImuModel out = m;
  out.A_a = m.A_a * info.accel.scale.cwiseInverse().asDiagonal();
  out.b_a = info.accel.scale.cwiseProduct(m.b_a - info.accel.offset);
  out.A_g = m.A_g * info.gyro.scale.cwiseInverse().asDiagonal();
  out.b_g = info.gyro.scale.cwiseProduct(m.b_g - info.gyro.offset);
  return out;
}

CanonicalImuModel canonical_on_input_units(const CanonicalImuModel& m, const ImuStreamInfo& info) {
  CanonicalImuModel out = m;
  out.A_a = m.A_a * info.accel.scale.asDiagonal();
  out.b_a = m.b_a.cwiseQuotient(info.accel.scale) + info.accel.offset;
  out.A_g = m.A_g * info.gyro.scale.asDiagonal();
  out.b_g = m.b_g.cwiseQuotient(info.gyro.scale) + info.gyro.offset;
  return out;
}

Eigen::Matrix3d krebs_gsens_from_canonical(const Eigen::Matrix3d& G_body, const KrebsImuModel& k) {
  const Eigen::Matrix3d SMg = k.S_g.asDiagonal() * krebs_misalignment(k.M_g);
  return SMg * k.C_bg.transpose() * G_body * k.C_bg;
}

Result<GsensInput> read_gsens_input(const std::string& path) {
  auto G = read_gsens_matrix(path);
  if (!G.ok()) return G.error();
  GsensInput out;
  out.path = path;
  out.G = *G;
  // A full static result also says which frame its G is in; a bare G: file does not.
  if (auto full = read_imucal_calibration(path); full.ok()) out.frame = std::move(*full);
  return out;
}

namespace {

/// The gyro's raw-to-body map of a static calibration's factors (units cancel in its rotation).
std::optional<Eigen::Matrix3d> gyro_to_body(const TedaldiTriad& accel, const TedaldiTriad& gyro) {
  CanonicalImuModel c;
  c.A_a = accel.TK();
  c.A_g = gyro.TK();
  auto k = krebs_from_canonical(c);
  if (!k.ok()) return std::nullopt;
  return Eigen::Matrix3d(k->R_canonical_body.transpose() * c.A_g);
}

}  // namespace

Eigen::Matrix3d held_axes_covariance(const NamedCalibration::Spread& spread) {
  const auto nominal = gyro_to_body(spread.accel, spread.gyro);
  const Eigen::Matrix3d undetermined = Eigen::Matrix3d::Constant(std::nan(""));
  if (!nominal) return undetermined;
  const Eigen::Matrix3d inverse = nominal->inverse();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  const auto add = [&](const TedaldiTriad& accel, const TedaldiTriad& gyro) {
    const auto moved = gyro_to_body(accel, gyro);
    if (!moved) return false;
    // The rotation part of moved * nominal^-1: its antisymmetric part, small.
    const Eigen::Matrix3d m = *moved * inverse;
    const Eigen::Vector3d d(0.5 * (m(2, 1) - m(1, 2)), 0.5 * (m(0, 2) - m(2, 0)), 0.5 * (m(1, 0) - m(0, 1)));
    cov += d * d.transpose();
    return true;
  };
  for (int triad = 0; triad < 2; ++triad) {
    const TriadSigma& sigma = triad == 0 ? spread.accel_sigma : spread.gyro_sigma;
    const TedaldiTriad& base = triad == 0 ? spread.accel : spread.gyro;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        if (i == j || sigma.T(i, j) == 0.0) continue;  // the unit diagonal, and entries not estimated
        if (!std::isfinite(sigma.T(i, j))) return undetermined;
        TedaldiTriad t = base;
        t.T(i, j) += sigma.T(i, j);
        if (!(triad == 0 ? add(t, spread.gyro) : add(spread.accel, t))) return undetermined;
      }
      if (sigma.scale(i) == 0.0) continue;
      if (!std::isfinite(sigma.scale(i))) return undetermined;
      TedaldiTriad t = base;
      t.scale(i) += sigma.scale(i);
      if (!(triad == 0 ? add(t, spread.gyro) : add(spread.accel, t))) return undetermined;
    }
  }
  return cov;
}

Result<ImuPrior> imu_prior(const std::optional<NamedCalibration>& intrinsics,
                           const std::optional<GsensInput>& gsens, const ImuStreamInfo& info) {
  ImuPrior out;
  KrebsImuModel model;
  if (intrinsics) {
    auto si = model_on_nominal_si(*intrinsics, info, &out.notes);
    if (!si.ok()) return si.error();
    auto k = krebs_from_canonical(*si);
    if (!k.ok()) return k.error().context(intrinsics->path);
    model = k->model;
    out.fixed.S_a = out.fixed.M_a = out.fixed.S_g = out.fixed.M_g = out.fixed.C_bg = true;
    if (!si->G.isZero(0.0) || gsens) {
      out.fixed.B_g = true;
    } else {
      out.notes.push_back(intrinsics->path + " holds no g-sensitivity (G = 0): B_g is estimated");
    }
  }
  if (gsens) {
    Eigen::Matrix3d G_body = gsens->G;
    if (gsens->frame) {
      auto si = model_on_nominal_si(*gsens->frame, info, &out.notes);
      if (!si.ok()) return si.error();
      auto k = krebs_from_canonical(*si);
      if (!k.ok()) return k.error().context(gsens->path);
      G_body = k->R_canonical_body.transpose() * gsens->G * k->R_canonical_body;
    } else {
      out.notes.push_back(
          gsens->path +
          " gives G without its calibration: taken as expressed in the accelerometer (body) frame");
    }
    if (!intrinsics) {
      out.notes.push_back(
          "--gsens without --imu-intrinsics: B_g is fixed for S_g = 1, M_g = 0, C_bg = I; the estimated gyro "
          "intrinsics change the canonical G by their own small relative amount");
    }
    model.B_g = krebs_gsens_from_canonical(G_body, model);
    out.fixed.B_g = true;
  }
  if (intrinsics || gsens) out.init = model;
  return out;
}

std::vector<calib::CamImuSample> camimu_samples(const std::vector<ImuSample>& samples,
                                                const ImuStreamInfo& info, std::size_t* saturated) {
  std::vector<calib::CamImuSample> out;
  out.reserve(samples.size());
  *saturated = 0;
  for (const auto& s : samples) {
    if ((s.flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated)) != 0) {
      ++*saturated;
      continue;
    }
    out.push_back({s.t_ns, info.accel.to_si(s.accel), info.gyro.to_si(s.gyro)});
  }
  return out;
}

Status set_fixed_block(const std::string& name, calib::CamImuFixed* f) {
  const std::map<std::string, bool*> blocks = {{"S_a", &f->S_a},
                                               {"M_a", &f->M_a},
                                               {"S_g", &f->S_g},
                                               {"M_g", &f->M_g},
                                               {"C_bg", &f->C_bg},
                                               {"B_g", &f->B_g},
                                               {"T_cam_imu", &f->T_cam_imu},
                                               {"timeshift", &f->timeshift}};
  const auto it = blocks.find(name);
  if (it == blocks.end()) {
    return make_error(Errc::kInvalidArgument,
                      "'" + name +
                          "' is not a block that can be fixed: S_a, M_a, S_g, M_g, C_bg, B_g, T_cam_imu, "
                          "timeshift");
  }
  *it->second = true;
  return {};
}

std::vector<std::string> fixed_block_names(const calib::CamImuFixed& f) {
  std::vector<std::string> out;
  const std::array<std::pair<const char*, bool>, 8> blocks{{{"S_a", f.S_a},
                                                            {"M_a", f.M_a},
                                                            {"S_g", f.S_g},
                                                            {"M_g", f.M_g},
                                                            {"C_bg", f.C_bg},
                                                            {"B_g", f.B_g},
                                                            {"T_cam_imu", f.T_cam_imu},
                                                            {"timeshift", f.timeshift}}};
  for (const auto& [name, fixed] : blocks) {
    if (fixed) out.emplace_back(name);
  }
  return out;
}

calib::CamImuFixed merge_fixed(const calib::CamImuFixed& a, const calib::CamImuFixed& b) {
  calib::CamImuFixed f;
  f.S_a = a.S_a || b.S_a;
  f.M_a = a.M_a || b.M_a;
  f.S_g = a.S_g || b.S_g;
  f.M_g = a.M_g || b.M_g;
  f.C_bg = a.C_bg || b.C_bg;
  f.B_g = a.B_g || b.B_g;
  f.T_cam_imu = a.T_cam_imu || b.T_cam_imu;
  f.timeshift = a.timeshift || b.timeshift;
  return f;
}

}  // namespace imucal::app
