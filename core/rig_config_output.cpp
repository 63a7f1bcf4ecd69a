// SPDX-License-Identifier: BSD-3-Clause
// The rig configuration written out (core/rig_config.hpp): the normalized YAML that reads back
// to the same configuration, and the JSON a session log stores.

#include <yaml-cpp/yaml.h>

#include <charconv>
#include <nlohmann/json.hpp>
#include <string>

#include "core/rig_config.hpp"
#include "core/rig_config_fields.hpp"
#include "core/text_format.hpp"

namespace imucal {

namespace {

using rig_config_detail::kSessionNumbers;

/// Shortest text that reads back to the same double (so 0.06 stays "0.06").
std::string num(double v) {
  char buf[64];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  (void)ec;  // 64 bytes always hold the shortest form of a double
  return std::string(buf, ptr);
}

void emit_target(YAML::Emitter& out, const TargetDescription& t) {
  out << YAML::BeginMap;
  if (t.type == TargetDescription::Type::kCheckerboard) {
    out << YAML::Key << "target_type" << YAML::Value << "checkerboard";
    out << YAML::Key << "targetCols" << YAML::Value << t.cols;
    out << YAML::Key << "targetRows" << YAML::Value << t.rows;
    out << YAML::Key << "rowSpacingMeters" << YAML::Value << num(t.row_spacing_m);
    out << YAML::Key << "colSpacingMeters" << YAML::Value << num(t.col_spacing_m);
  } else {
    out << YAML::Key << "target_type" << YAML::Value << "aprilgrid";
    out << YAML::Key << "tagCols" << YAML::Value << t.tag_cols;
    out << YAML::Key << "tagRows" << YAML::Value << t.tag_rows;
    out << YAML::Key << "tagSize" << YAML::Value << num(t.tag_size_m);
    out << YAML::Key << "tagSpacing" << YAML::Value << num(t.tag_spacing);
  }
  out << YAML::EndMap;
}

// "+x" for a signed unit axis (sides).
std::string axis_text(const Eigen::Vector3d& v) {
  Eigen::Index i = 0;
  v.cwiseAbs().maxCoeff(&i);
  return std::string(v[i] < 0 ? "-" : "+") + static_cast<char>('x' + i);
}

}  // namespace

std::string rig_config_to_yaml(const RigConfig& c) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << c.name;
  out << YAML::Key << "imu" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "bus" << YAML::Value << imu_bus_name(c.imu.bus);
  out << YAML::Key << "device" << YAML::Value << c.imu.device;
  out << YAML::Key << "driver" << YAML::Value << imu_driver_name(c.imu.driver);
  if (!c.imu.iio_device.empty()) out << YAML::Key << "iio_device" << YAML::Value << c.imu.iio_device;
  if (c.imu.bus == ImuBus::kI2c)
    out << YAML::Key << "i2c_address" << YAML::Value
        << format_hex(static_cast<unsigned long>(c.imu.i2c_address), 2);
  if (c.imu.bus == ImuBus::kSpi) {
    out << YAML::Key << "spi_config_speed_hz" << YAML::Value << c.imu.spi_config_speed_hz;
    out << YAML::Key << "spi_data_speed_hz" << YAML::Value << c.imu.spi_data_speed_hz;
  }
  out << YAML::Key << "accel_range_g" << YAML::Value << c.imu.accel_range_g;
  out << YAML::Key << "gyro_range_dps" << YAML::Value << c.imu.gyro_range_dps;
  out << YAML::Key << "rate_hz" << YAML::Value << num(c.imu.rate_hz);
  out << YAML::Key << "dlpf_hz" << YAML::Value << c.imu.dlpf_hz;
  if (c.imu.data_ready) {
    out << YAML::Key << "data_ready" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "chip" << YAML::Value << c.imu.data_ready->chip;
    out << YAML::Key << "line" << YAML::Value << c.imu.data_ready->line;
    out << YAML::EndMap;
  }
  out << YAML::Key << "mounting" << YAML::Value << YAML::BeginMap << YAML::Key << "R_rig_imu" << YAML::Value
      << YAML::BeginSeq;
  for (int r = 0; r < 3; ++r) {
    out << YAML::Flow << YAML::BeginSeq;
    for (int k = 0; k < 3; ++k) out << num(c.imu.R_rig_imu(r, k));
    out << YAML::EndSeq;
  }
  out << YAML::EndSeq << YAML::EndMap;
  out << YAML::EndMap;
  if (c.sides) {
    out << YAML::Key << "sides" << YAML::Value << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "front" << YAML::Value << axis_text(c.sides->front);
    out << YAML::Key << "left" << YAML::Value << axis_text(c.sides->left);
    out << YAML::Key << "top" << YAML::Value << axis_text(c.sides->top) << YAML::EndMap;
  }

  out << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (const auto& cam : c.cameras) {
    out << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << cam.name;
    out << YAML::Key << "backend" << YAML::Value << camera_backend_name(cam.backend);
    out << YAML::Key << "device" << YAML::Value << cam.device;
    out << YAML::Key << "width" << YAML::Value << cam.width;
    out << YAML::Key << "height" << YAML::Value << cam.height;
    out << YAML::Key << "rate_hz" << YAML::Value << num(cam.rate_hz);
    out << YAML::Key << "pixel_format" << YAML::Value << YAML::DoubleQuoted << cam.pixel_format;
    if (cam.shutter.rolling()) {
      out << YAML::Key << "shutter" << YAML::Value << "rolling";
      out << YAML::Key << "line_delay_us" << YAML::Value << num(1e6 * cam.shutter.line_delay_s);
      out << YAML::Key << "readout_direction" << YAML::Value << readout_name(cam.shutter.readout);
      out << YAML::Key << "stamp_row" << YAML::Value << stamp_row_name(cam.shutter.stamp_row);
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq;
  if (c.target) {
    out << YAML::Key << "target" << YAML::Value;
    emit_target(out, *c.target);
  }
  out << YAML::Key << "storage" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "backend" << YAML::Value << storage_backend_name(c.storage.backend);
  if (c.storage.backend == StorageBackend::kI2cEeprom) {
    out << YAML::Key << "i2c_device" << YAML::Value << c.storage.i2c_device;
    out << YAML::Key << "i2c_address" << YAML::Value
        << format_hex(static_cast<unsigned long>(c.storage.i2c_address), 2);
    out << YAML::Key << "page_bytes" << YAML::Value << c.storage.page_bytes;
    out << YAML::Key << "address_bytes" << YAML::Value << c.storage.address_bytes;
  } else {
    out << YAML::Key << "path" << YAML::Value << c.storage.path;
  }
  out << YAML::Key << "size_bytes" << YAML::Value << c.storage.size_bytes;
  out << YAML::Key << "offset_bytes" << YAML::Value << c.storage.offset_bytes;
  out << YAML::Key << "program_gyro_offsets" << YAML::Value << c.storage.program_gyro_offsets;
  out << YAML::EndMap;
  out << YAML::Key << "session" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "steps" << YAML::Value << YAML::Flow << c.session.steps;
  for (const auto& n : kSessionNumbers) out << YAML::Key << n.key << YAML::Value << num(c.session.*n.member);
  out << YAML::Key << "poses" << YAML::Value << c.session.poses;
  out << YAML::Key << "poses_min" << YAML::Value << c.session.poses_min;
  out << YAML::Key << "auto_write" << YAML::Value << c.session.auto_write;
  out << YAML::EndMap;
  out << YAML::Key << "live_view" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << c.live_view.enabled;
  out << YAML::Key << "address" << YAML::Value << c.live_view.address;
  out << YAML::Key << "port" << YAML::Value << c.live_view.port;
  out << YAML::Key << "frame_rate_hz" << YAML::Value << num(c.live_view.frame_rate_hz);
  out << YAML::Key << "width" << YAML::Value << c.live_view.width;
  out << YAML::EndMap;
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

std::string rig_config_to_json(const RigConfig& c) {
  using nlohmann::json;
  json imu = {{"bus", imu_bus_name(c.imu.bus)},
              {"device", c.imu.device},
              {"driver", imu_driver_name(c.imu.driver)},
              {"accel_range_g", c.imu.accel_range_g},
              {"gyro_range_dps", c.imu.gyro_range_dps},
              {"rate_hz", c.imu.rate_hz},
              {"dlpf_hz", c.imu.dlpf_hz}};
  if (c.imu.bus == ImuBus::kI2c) imu["i2c_address"] = c.imu.i2c_address;
  if (c.imu.bus == ImuBus::kSpi) {
    imu["spi_config_speed_hz"] = c.imu.spi_config_speed_hz;
    imu["spi_data_speed_hz"] = c.imu.spi_data_speed_hz;
  }
  if (c.imu.data_ready)
    imu["data_ready"] = {{"chip", c.imu.data_ready->chip}, {"line", c.imu.data_ready->line}};
  json R = json::array();
  for (int r = 0; r < 3; ++r)
    R.push_back({c.imu.R_rig_imu(r, 0), c.imu.R_rig_imu(r, 1), c.imu.R_rig_imu(r, 2)});
  imu["mounting"] = {{"R_rig_imu", R}};
  json cams = json::array();
  for (const auto& cam : c.cameras) {
    cams.push_back({{"name", cam.name},
                    {"backend", camera_backend_name(cam.backend)},
                    {"device", cam.device},
                    {"width", cam.width},
                    {"height", cam.height},
                    {"rate_hz", cam.rate_hz},
                    {"pixel_format", cam.pixel_format},
                    {"shutter", shutter_kind_name(cam.shutter.kind)}});
    if (cam.shutter.rolling()) {
      cams.back()["line_delay_us"] = 1e6 * cam.shutter.line_delay_s;
      cams.back()["readout_direction"] = readout_name(cam.shutter.readout);
      cams.back()["stamp_row"] = stamp_row_name(cam.shutter.stamp_row);
    }
  }
  json storage = {{"backend", storage_backend_name(c.storage.backend)},
                  {"size_bytes", c.storage.size_bytes},
                  {"offset_bytes", c.storage.offset_bytes},
                  {"program_gyro_offsets", c.storage.program_gyro_offsets}};
  if (c.storage.backend == StorageBackend::kI2cEeprom) {
    storage["i2c_device"] = c.storage.i2c_device;
    storage["i2c_address"] = c.storage.i2c_address;
    storage["page_bytes"] = c.storage.page_bytes;
    storage["address_bytes"] = c.storage.address_bytes;
  } else {
    storage["path"] = c.storage.path;
  }
  json session = {{"steps", c.session.steps},
                  {"poses", c.session.poses},
                  {"poses_min", c.session.poses_min},
                  {"auto_write", c.session.auto_write}};
  for (const auto& n : kSessionNumbers) session[n.key] = c.session.*n.member;
  json live_view = {{"enabled", c.live_view.enabled},
                    {"address", c.live_view.address},
                    {"port", c.live_view.port},
                    {"frame_rate_hz", c.live_view.frame_rate_hz},
                    {"width", c.live_view.width}};
  json root = {{"name", c.name},     {"imu", imu},         {"cameras", cams},
               {"storage", storage}, {"session", session}, {"live_view", live_view}};
  if (c.sides) {
    root["sides"] = {{"front", axis_text(c.sides->front)},
                     {"left", axis_text(c.sides->left)},
                     {"top", axis_text(c.sides->top)}};
  }
  if (c.target) {
    const auto& t = *c.target;
    if (t.type == TargetDescription::Type::kCheckerboard) {
      root["target"] = {{"target_type", "checkerboard"},
                        {"targetCols", t.cols},
                        {"targetRows", t.rows},
                        {"rowSpacingMeters", t.row_spacing_m},
                        {"colSpacingMeters", t.col_spacing_m}};
    } else {
      root["target"] = {{"target_type", "aprilgrid"},
                        {"tagCols", t.tag_cols},
                        {"tagRows", t.tag_rows},
                        {"tagSize", t.tag_size_m},
                        {"tagSpacing", t.tag_spacing}};
    }
  }
  return root.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace imucal
