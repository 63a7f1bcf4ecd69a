// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// imucald's command line as a value: the files and sockets it uses, and the virtual rig's settings.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace imucal::imucald {

struct ServiceOptions {
  std::string config_path = "/etc/imucal/rig.yaml";
  std::string socket_path = "/run/imucal/imucald.sock";
  unsigned socket_mode = 0660;
  std::string state_dir = "/var/lib/imucal";
  bool sim = false;         // the virtual rig (also when imu.bus is sim)
  double time_scale = 1.0;  // virtual rig: rig seconds per wall second; 0 = as fast as it computes
  // virtual rig: "" (nobody moves it), "motion" (moves it), "full" (moves it and presses keys)
  std::string sim_operator;
  std::uint64_t seed = 1;
  std::uint32_t sim_unplug_camera_after = 0;  // virtual rig: its cameras vanish after this many frames (once)
  double sim_unplug_imu_after_s =
      0.0;  // virtual rig: the IMU stops answering this long into a session (once)
  std::optional<double> sim_cold_start_c;         // virtual rig: its die starts here and warms (thermal step)
  std::optional<std::vector<std::string>> start;  // start a session at launch with these steps
  bool exit_after_session = false;
  // The configured devices may appear after the service starts (a driver loaded later): an
  // absent one is no reason for kExitDeviceAbsent.
  bool devices_may_appear_later = false;
  // --live-view [ADDRESS:]PORT: the live view on, there, whatever the configuration says.
  std::optional<std::string> live_view_address;
  std::optional<int> live_view_port;
};

}  // namespace imucal::imucald
