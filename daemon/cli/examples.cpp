// SPDX-License-Identifier: BSD-3-Clause
// Examples at the end of every command's --help (the root's own are in main.cpp). One table,
// so that no command is left with the root's examples only; tests/daemon/test_cli_exit_codes.cpp
// runs every line's command with --help and finds each option it uses.

#include <string>
#include <utility>
#include <vector>

#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct Examples {
  std::vector<std::string> path;  // subcommand names from the root
  std::vector<const char*> lines;
};

const std::vector<Examples>& examples() {
  static const std::vector<Examples> kExamples = {
      {{"sim", "static"},
       {"imucal sim static -o static.imulog                      # the virtual rig's static poses, with its "
        "truth",
        "imucal sim static --seed 7 --imu-rate 200 -o static.imulog   # another IMU, sampled at 200 Hz"}},
      {{"sim", "gsens"}, {"imucal sim gsens -o faces.imulog   # six-face holds, for calibrate gsens"}},
      {{"sim", "camimu"},
       {"imucal sim camimu -o camimu.imulog   # IMU and rendered checkerboard frames",
        "imucal sim camimu --seed 2 --line-delay 30 -o rolling.imulog   # a rolling-shutter camera"}},
      {{"sim", "still"}, {"imucal sim still --duration 3600 -o still.imulog   # an hour at rest, for allan"}},
      {{"record"},
       {"imucal record --config /etc/imucal/rig.yaml --duration 60 -o rig.imulog   # the rig's own devices",
        "imucal record --config rig.yaml --sim -o sim.imulog                   # its virtual rig"}},
      {{"calibrate", "static"},
       {"imucal calibrate static static.imulog -o imu.yaml --json imu.json",
        "imucal calibrate static static.imulog --thermal thermal.yaml -o imu.yaml   # corrected to the "
        "model's "
        "reference"}},
      {{"calibrate", "check"}, {"imucal calibrate check static.imulog --calibration imu.yaml"}},
      {{"calibrate", "camimu"},
       {"imucal calibrate camimu camimu.imulog --camera camchain.yaml -o camimu",
        "imucal calibrate camimu rig.imulog --camera camchain.yaml --imu imu.yaml --target target.yaml -o "
        "camimu"}},
      {{"calibrate", "gsens"},
       {"imucal calibrate gsens faces.imulog --imu-intrinsics imu.yaml -o gsens.yaml"}},
      {{"calibrate", "thermal"},
       {"imucal calibrate thermal warmup.imulog -o thermal.yaml",
        "imucal calibrate thermal warmup.imulog --scale-from cold.imulog --scale-from hot.imulog -o "
        "thermal.yaml"}},
      {{"info"}, {"imucal info rig.imulog", "imucal info --json rig.imulog"}},
      {{"allan"},
       {"imucal allan still.imulog -o imu.yaml --json allan.json   # Kalibr's imu.yaml, and the curves"}},
      {{"import", "euroc"}, {"imucal import euroc ./V1_01_easy/mav0 -o v101.imulog"}},
      {{"import", "bag"},
       {"imucal import bag calib.bag -o calib.imulog   # every Imu and image topic",
        "imucal import bag calib.bag --topics /cam0/image_raw /cam1/image_raw /imu0 -o calib.imulog"}},
      {{"import", "rosbag2"},
       {"imucal import rosbag2 ./calib_ros2 -o calib.imulog   # a rosbag2 folder (metadata.yaml, .db3 or "
        ".mcap)"}},
      {{"import", "ascii"},
       {"imucal import ascii --accel acc.txt --gyro gyro.txt --units si -o imu.imulog",
        "imucal import ascii --accel acc.txt --gyro gyro.txt --units raw --accel-offset 32768 -o "
        "imu.imulog"}},
      {{"import", "csv"},
       {"imucal import csv imu.csv --columns t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6 --time-unit ns --units si -o "
        "imu.imulog"}},
      {{"export", "euroc"}, {"imucal export euroc rig.imulog ./rig-euroc   # DIR/mav0/imu0, DIR/mav0/cam0"}},
      {{"export", "bag"}, {"imucal export bag rig.imulog rig.bag   # /imu0 and /cam0/image_raw, for Kalibr"}},
      {{"report"},
       {"imucal report imu.json --log static.imulog -o static.html",
        "imucal report camera.json -o camera.html   # from calibrate camera LOG --json > camera.json",
        "imucal report cam.yaml -o cam.html         # calibrate camera -o's YAML: its tables, no figures",
        "imucal report ./camimu -o camimu.html      # calibrate camimu's output folder"}},
      {{"replay"}, {"imucal replay /var/lib/imucal/sessions/NAME/session.imulog -o ./replay"}},
      {{"store", "read"},
       {"imucal store read --config /etc/imucal/rig.yaml", "imucal store read --json --config rig.yaml"}},
      {{"store", "write"},
       {"imucal store write --config /etc/imucal/rig.yaml imu.yaml camimu/calibration.yaml"}},
      {{"store", "verify"}, {"imucal store verify --config /etc/imucal/rig.yaml imu.yaml"}},
      {{"store", "rollback"}, {"imucal store rollback --config /etc/imucal/rig.yaml"}},
      {{"config", "check"}, {"imucal config check /etc/imucal/rig.yaml"}},
  };
  return kExamples;
}

}  // namespace

void add_examples(CLI::App& root) {
  for (const Examples& e : examples()) {
    CLI::App* cmd = &root;
    for (const std::string& name : e.path) cmd = cmd->get_subcommand(name);
    std::string text = "Examples:\n";
    for (const char* line : e.lines) text += std::string("  ") + line + "\n";
    // A command's own notes (its footer, when it is not the root's) follow the examples.
    const std::string own = cmd->get_footer();
    if (!own.empty() && own != root.get_footer()) text += own;
    cmd->footer(text);
  }
}

}  // namespace imucal::cli
