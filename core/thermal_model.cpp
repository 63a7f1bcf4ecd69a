// SPDX-License-Identifier: BSD-3-Clause
#include "core/thermal_model.hpp"

#include <algorithm>

namespace imucal {

double ThermalAxisModel::change(double dt) const {
  if (!determined) return 0.0;
  double sum = 0.0, power = 1.0;
  for (Eigen::Index j = 0; j < coeffs.size(); ++j) {
    power *= dt;
    sum += coeffs[j] * power;
  }
  return sum;
}

double ThermalModel::clamp(double temperature_c) const { return std::clamp(temperature_c, min_c, max_c); }

Eigen::Vector3d ThermalModel::gyro_change(double temperature_c) const {
  const double dt = clamp(temperature_c) - reference_c;
  return {gyro[0].change(dt), gyro[1].change(dt), gyro[2].change(dt)};
}

Eigen::Vector3d ThermalModel::accel_change(double temperature_c) const {
  const double dt = clamp(temperature_c) - reference_c;
  return {accel[0].change(dt), accel[1].change(dt), accel[2].change(dt)};
}

ThermalModel ThermalModel::scaled(const Eigen::Vector3d& gyro_factor,
                                  const Eigen::Vector3d& accel_factor) const {
  ThermalModel out = *this;
  for (int i = 0; i < 3; ++i) {
    out.gyro[i].coeffs *= gyro_factor[i];
    out.gyro[i].sigma *= gyro_factor[i];
    out.accel[i].coeffs *= accel_factor[i];
    out.accel[i].sigma *= accel_factor[i];
  }
  return out;
}

}  // namespace imucal
