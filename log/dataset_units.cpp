// SPDX-License-Identifier: BSD-3-Clause
// The unit sanity check of dataset imports (log/dataset_io.hpp, UnitCheck and check_units()):
// whether an import's accelerometer values look like the units it was told, from the median
// magnitude of an evenly spaced subset.

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "log/dataset_io.hpp"

namespace imucal::log {

void UnitCheck::add(const Eigen::Vector3d& accel) {
  if (seen_++ % stride_ != 0) return;
  kept_.push_back(accel);
  // At most 40000: every other one goes, and from now on every (2 stride)-th is kept.
  if (kept_.size() == 40000) {
    for (std::size_t i = 0; i < 20000; ++i) kept_[i] = kept_[2 * i];
    kept_.resize(20000);
    stride_ *= 2;
  }
}

Status check_units(const std::vector<ImuSample>& samples, ImuUnits units, const std::string& source) {
  UnitCheck check;
  for (const auto& s : samples) check.add(s.accel);
  return check.check(units, source);
}

Status UnitCheck::check(ImuUnits units, const std::string& source) const {
  if (kept_.empty()) return {};
  // An evenly spaced subset: the median is robust and this stays cheap.
  std::vector<double> norms;
  norms.reserve(kept_.size());
  std::size_t components = 0, non_integral = 0;
  for (const Eigen::Vector3d& a : kept_) {
    norms.push_back(a.norm());
    for (int k = 0; k < 3; ++k) {
      ++components;
      if (a[k] != std::floor(a[k])) ++non_integral;
    }
  }
  std::nth_element(norms.begin(), norms.begin() + static_cast<std::ptrdiff_t>(norms.size() / 2), norms.end());
  const double median = norms[norms.size() / 2];
  std::ostringstream about;
  about << source << ": the accelerometer magnitude is about " << median << " (median |a|)";
  if (units == ImuUnits::kSi && median > 100.0) {
    return make_error(Errc::kCorrupt, about.str() +
                                          ", far above gravity (9.8 m/s^2): these look like raw counts. "
                                          "Import them as raw counts with their nominal scales, or skip "
                                          "the unit check if the values really are SI")
        .with_remedy("units", "raw")
        .with_remedy("accel_scale")
        .with_remedy("gyro_scale")
        .with_remedy("unit_check", "off");
  }
  if (units == ImuUnits::kSi && median > 0.5 && median < 2.0) {
    return make_error(Errc::kCorrupt,
                      about.str() +
                          ": these look like g, not m/s^2. Import them as raw values with "
                          "an accelerometer scale of 9.80665 (and the gyroscope's unit as its "
                          "scale), or skip the unit check if the values really are m/s^2")
        .with_remedy("units", "raw")
        .with_remedy("accel_scale", "9.80665")
        .with_remedy("gyro_scale")
        .with_remedy("unit_check", "off");
  }
  if (units == ImuUnits::kRaw && median > 5.0 && median < 15.0 &&
      static_cast<double>(non_integral) > 0.5 * static_cast<double>(components)) {
    return make_error(Errc::kCorrupt, about.str() +
                                          " with non-integral values: these look like SI units (m/s^2, "
                                          "rad/s), not raw counts. Import them as SI, or skip the unit "
                                          "check if they really are raw counts")
        .with_remedy("units", "si")
        .with_remedy("unit_check", "off");
  }
  return {};
}

}  // namespace imucal::log
