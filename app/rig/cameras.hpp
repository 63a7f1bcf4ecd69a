// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The rig's cameras assembled from their configuration (cameras[] in docs/config.md): each is
// opened through the backend it names (V4L2 in the program; Aravis and libcamera through their
// modules, loaded only when a camera uses them) and configured to its size, pixel format and rate.
// Shared by `imucal record` and the rig service. Simulated cameras are built in sim/, not here.

#include <memory>
#include <string>
#include <vector>

#include "acquisition/recorder.hpp"
#include "core/result.hpp"
#include "core/rig_config.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::app {

/// Opens and configures one camera. Errors say which camera and which step failed, keeping the
/// backend's code (kNotFound for a missing device, kUnsupported for a refused format or a
/// backend this installation lacks, kDevice for a broken one).
[[nodiscard]] Result<std::unique_ptr<drivers::camera::Camera>> open_camera(const CameraConfig& config);

/// Opens every configured camera of a hardware rig and describes each for a recording. A camera
/// with backend sim is refused (the virtual rig builds those).
struct OpenedCameras {
  std::vector<std::unique_ptr<drivers::camera::Camera>> cameras;
  std::vector<acq::RecordCamera> record;  // borrows `cameras`
};
[[nodiscard]] Result<OpenedCameras> open_rig_cameras(const RigConfig& config);

}  // namespace imucal::app
