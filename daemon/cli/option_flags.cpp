// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/cli/option_flags.hpp"

namespace imucal::cli {

namespace {

std::string flag(const char* name, std::string_view value) {
  return value.empty() ? std::string(name) : std::string(name) + " " + std::string(value);
}

}  // namespace

std::string cli_option_words(CalibOption option, std::string_view value) {
  switch (option) {
    case CalibOption::kShutter:
      return flag("--shutter", value);
    case CalibOption::kLineDelay:
      return flag("--line-delay", value);
    case CalibOption::kReadout:
      return flag("--readout", value);
    case CalibOption::kHoldTimeOffsets:
      return "--hold-time-offsets";
    case CalibOption::kCamImuModel:
      return flag("--model", value);
    case CalibOption::kImuIntrinsics:
      return "--imu-intrinsics";
    case CalibOption::kGsens:
      return "--gsens";
    case CalibOption::kFix:
      return "--fix";
    case CalibOption::kKeepNoise:
      return "--keep-noise";
    case CalibOption::kAccelModel:
      return flag("--accel-model", value);
    case CalibOption::kImportOffsets:
      return "--accel-offset and --gyro-offset";
    case CalibOption::kImportScales:
      return "--accel-scale and --gyro-scale";
  }
  return plain_option_words(option, value);
}

}  // namespace imucal::cli
