// Observations read back from a file checked against the target (calib/observation_check.hpp).
// In imucal_calib, without OpenCV or Ceres, so that every estimator that reads ids can use it.

#include "calib/observation_check.hpp"

#include <string>

namespace imucal::calib {

Status check_observation(const TargetObservation& o, int target_points) {
  const std::string at = "the detection at t_ns " + std::to_string(o.t_ns);
  if (o.px.size() != o.ids.size()) {
    return make_error(Errc::kCorrupt, at + " holds " + std::to_string(o.ids.size()) + " point ids but " +
                                          std::to_string(o.px.size()) + " pixel positions");
  }
  for (std::size_t i = 0; i < o.ids.size(); ++i) {
    const int id = o.ids[i];
    if (id < 0 || id >= target_points) {
      return make_error(Errc::kCorrupt, at + " holds point id " + std::to_string(id) +
                                            ", outside the target's " + std::to_string(target_points) +
                                            " points (ids 0-" + std::to_string(target_points - 1) + ")");
    }
    if (!o.px[i].allFinite()) {
      return make_error(Errc::kCorrupt, at + " holds a pixel position of point id " + std::to_string(id) +
                                            " that is not a finite number");
    }
  }
  return {};
}

}  // namespace imucal::calib
