// SPDX-License-Identifier: BSD-3-Clause
#include "sim/session_rig.hpp"

namespace imucal::sim {

Result<std::unique_ptr<SessionRig>> SessionRig::create(const SessionRigOptions& options) {
  std::unique_ptr<SessionRig> r(new SessionRig());
  if (options.params) {
    r->params_ = *options.params;
  } else {
    r->params_ = ImuModelParams::draw(options.seed);
    r->params_.temp_start_c = r->params_.temp_final_c - 1.5;
  }
  r->trajectory_ = std::make_unique<OperatorTrajectory>();
  SimRigOptions ro;
  ro.settings = options.settings;
  ro.mounting = options.mounting;
  ro.data_ready.seed = options.seed;
  // Trajectory time is host time (offset 0): the operator schedules turns on the rig's clock.
  r->sensor_ = std::make_shared<TrajectorySensor>(r->params_, options.seed, *r->trajectory_, 0,
                                                  chip_sample_period_s(options.settings, ro.clock_ppm));
  auto rig = SimImuRig::create(TrajectorySensor::source(r->sensor_), ro);
  if (!rig.ok()) return rig.error().context("virtual rig");
  r->rig_ = std::move(*rig);
  r->info_ = drivers::mpu6000::make_stream_info(options.settings, "sim");
  return r;
}

Status SessionRig::advance(TimeNs dt_ns, std::vector<ImuSample>& out) {
  const TimeNs until = rig_->clock().now_ns() + dt_ns;
  std::vector<ImuSample> batch;
  while (rig_->clock().now_ns() < until) {
    IMUCAL_TRY(rig_->acquisition().step(batch));  // step() clears its output
    out.insert(out.end(), batch.begin(), batch.end());
  }
  return {};
}

}  // namespace imucal::sim
