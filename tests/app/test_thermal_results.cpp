// SPDX-License-Identifier: BSD-3-Clause
// The thermal result file (app/results/thermal_results.hpp): written and read back unchanged,
// refused when it is something else; and the correction of samples to the reference temperature,
// checked on a warm-up generated here (not by the simulator): after the correction a second fit
// finds almost none of the curve left.

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "app/results/thermal_results.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

constexpr double kRate = 10.0;  // Hz
constexpr double kDuration = 3600.0;

/// Bias truth per axis about 20 deg C: gyro in rad/s, accelerometer in m/s^2.
double gyro_truth(int axis, double dT) { return (4e-4 - 2e-4 * axis) * dT + 6e-6 * dT * dT; }
double accel_truth(int axis, double dT) { return (0.01 + 0.005 * axis) * dT - 1.5e-4 * dT * dT; }

/// An SI still rig warming from 20 to 55 deg C (time constant 900 s), with white noise only.
std::vector<ImuSample> warm_up(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gyro_noise(0.0, 2e-3), accel_noise(0.0, 2e-2);
  std::vector<ImuSample> out;
  for (int k = 0; k < static_cast<int>(kDuration * kRate); ++k) {
    const double t = k / kRate;
    ImuSample s;
    s.t_ns = s_to_ns(t);
    s.temperature = 55.0 - 35.0 * std::exp(-t / 900.0);
    const double dT = s.temperature - 20.0;
    for (int a = 0; a < 3; ++a) {
      s.gyro[a] = 0.01 * (a + 1) + gyro_truth(a, dT) + gyro_noise(rng);
      s.accel[a] = (a == 2 ? 9.81 : 0.0) + accel_truth(a, dT) + accel_noise(rng);
    }
    out.push_back(s);
  }
  return out;
}

ImuStreamInfo si_stream() {
  ImuStreamInfo info;
  info.name = "imu0";
  info.units = ImuUnits::kSi;
  info.rate_hz = kRate;
  return info;
}

calib::ThermalResult fit(const std::vector<ImuSample>& samples) {
  calib::ThermalOptions o;
  auto r = calib::calibrate_thermal(samples, o);
  EXPECT_TRUE(r.ok()) << r.error().message;
  return r.ok() ? *r : calib::ThermalResult{};
}

TEST(ThermalResults, TheFileReadsBackAsTheResultItWasWrittenFrom) {
  const calib::ThermalResult r = fit(warm_up(1));
  ASSERT_TRUE(r.determined);
  ASSERT_FALSE(r.bin_means.empty());
  const std::string path = test::scratch_dir() + "/thermal.yaml";
  test::write_file(path, app::thermal_result_yaml(r, si_stream(), "warm.imulog"));

  auto f = app::read_thermal_file(path);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->log, "warm.imulog");
  EXPECT_EQ(f->stream, "imu0");
  EXPECT_EQ(f->input_units, "si");
  // Written with 12 significant digits.
  EXPECT_NEAR(f->result.reference_c, r.reference_c, 1e-9);
  EXPECT_NEAR(f->result.temp_min_c, r.temp_min_c, 1e-9);
  EXPECT_NEAR(f->result.temp_max_c, r.temp_max_c, 1e-9);
  ASSERT_EQ(f->result.bin_means.size(), r.bin_means.size());
  EXPECT_NEAR(f->result.bin_means[3].accel[2], r.bin_means[3].accel[2], 1e-9);
  for (int a = 0; a < 6; ++a) {
    const calib::ThermalAxisFit& x = a < 3 ? r.gyro[a] : r.accel[a - 3];
    const calib::ThermalAxisFit& y = a < 3 ? f->result.gyro[a] : f->result.accel[a - 3];
    ASSERT_EQ(x.order, y.order) << a;
    EXPECT_TRUE(x.coeffs.isApprox(y.coeffs, 1e-9)) << a;
    EXPECT_TRUE(x.covariance.isApprox(y.covariance, 1e-9)) << a;
    // The model to apply drops c_0 (for the accelerometer, gravity's projection).
    const ThermalAxisModel& m = a < 3 ? f->model.gyro[a] : f->model.accel[a - 3];
    ASSERT_EQ(m.coeffs.size(), x.order);
    if (x.order > 0) {
      EXPECT_NEAR(m.coeffs[0], x.coeffs[1], 1e-12);
      EXPECT_NEAR(m.sigma[0], std::sqrt(x.covariance(1, 1)), 1e-12);
    }
  }
}

TEST(ThermalResults, AnythingElseIsRefusedNamingTheFileAndTheKey) {
  const std::string dir = test::scratch_dir();
  test::write_file(dir + "/static.yaml", "method: static multi-position (Tedaldi 2013)\nstream: imu0\n");
  auto other = app::read_thermal_file(dir + "/static.yaml");
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.error().message.find("not a thermal model"), std::string::npos) << other.error().message;

  const calib::ThermalResult r = fit(warm_up(2));
  std::string text = app::thermal_result_yaml(r, si_stream(), "warm.imulog");
  const std::string key = "reference_temperature_c:";
  text.replace(text.find(key), key.size(), "reference_temp:");
  test::write_file(dir + "/broken.yaml", text);
  auto broken = app::read_thermal_file(dir + "/broken.yaml");
  ASSERT_FALSE(broken.ok());
  EXPECT_EQ(broken.error().code, Errc::kCorrupt);
  EXPECT_NE(broken.error().message.find(dir + "/broken.yaml: reference_temperature_c is missing"),
            std::string::npos)
      << broken.error().message;
}

TEST(ThermalResults, CorrectedSamplesLeaveAlmostNoneOfTheCurve) {
  const std::vector<ImuSample> samples = warm_up(3);
  const calib::ThermalResult before = fit(samples);
  ASSERT_TRUE(before.determined);
  const ThermalModel model = calib::thermal_model(before);

  std::vector<ImuSample> corrected = samples;
  auto c = app::correct_to_reference_temperature(corrected, si_stream(), model);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->corrected, samples.size());
  EXPECT_EQ(c->without_temperature, 0u);
  // A subtraction of the model's change at each sample's temperature, nothing else.
  const ImuSample& s = samples[5000];
  EXPECT_NEAR(corrected[5000].gyro[1], s.gyro[1] - model.gyro_change(s.temperature)[1], 1e-15);
  EXPECT_NEAR(corrected[5000].accel[0], s.accel[0] - model.accel_change(s.temperature)[0], 1e-15);

  const calib::ThermalResult after = fit(corrected);
  ASSERT_TRUE(after.determined);
  for (int a = 0; a < 6; ++a) {
    const calib::ThermalAxisFit& x = a < 3 ? before.gyro[a] : before.accel[a - 3];
    const calib::ThermalAxisFit& y = a < 3 ? after.gyro[a] : after.accel[a - 3];
    EXPECT_LT(y.uncompensated_drift, 0.1 * x.uncompensated_drift) << "axis " << a;
  }
  // The change at the reference temperature is zero: the biases there are kept.
  EXPECT_NEAR(model.gyro_change(model.reference_c).norm(), 0.0, 1e-15);
}

TEST(ThermalResults, AGyroOnlyRecordingFitsTheGyroAndSaysTheAccelerometerIsNotDetermined) {
  std::vector<ImuSample> samples = warm_up(4);
  for (ImuSample& s : samples) s.accel.setConstant(std::nan(""));
  const calib::ThermalResult r = fit(samples);
  ASSERT_TRUE(r.determined);
  for (int a = 0; a < 3; ++a) {
    EXPECT_TRUE(r.gyro[a].determined) << a;
    EXPECT_FALSE(r.accel[a].determined) << a;
    EXPECT_EQ(r.accel[a].reason, "the recording has no accelerometer values");
  }
  // The file says so, and its model subtracts nothing from the accelerometer.
  const std::string path = test::scratch_dir() + "/gyro-only.yaml";
  test::write_file(path, app::thermal_result_yaml(r, si_stream(), "gyro-only"));
  auto f = app::read_thermal_file(path);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_FALSE(f->model.accel[1].determined);
  EXPECT_EQ(f->model.accel_change(50.0), Eigen::Vector3d::Zero());
  EXPECT_NE(f->model.gyro_change(50.0)[0], 0.0);
}

TEST(ThermalResults, SamplesOutsideTheRangeOrWithoutATemperatureAreCountedAndARawStreamIsCorrectedInCounts) {
  ThermalModel m;
  m.reference_c = 30.0;
  m.min_c = 20.0;
  m.max_c = 40.0;
  for (int a = 0; a < 3; ++a) {
    m.gyro[a].determined = m.accel[a].determined = true;
    m.gyro[a].coeffs = Eigen::VectorXd::Constant(1, 1e-3);  // rad/s per K
    m.gyro[a].sigma = Eigen::VectorXd::Constant(1, 1e-5);
    m.accel[a].coeffs = Eigen::VectorXd::Constant(1, 0.02);  // m/s^2 per K
    m.accel[a].sigma = Eigen::VectorXd::Constant(1, 1e-4);
  }
  ImuStreamInfo raw = si_stream();
  raw.units = ImuUnits::kRaw;
  raw.temperature_scale = 1.0 / 340.0;
  raw.temperature_offset = 36.53;
  AxisConversion accel, gyro;
  accel.scale.setConstant(9.80665 / 16384.0);
  gyro.scale.setConstant(1.3323e-4);
  const ThermalModel counts = app::thermal_model_on_input_units(m, raw, accel, gyro);
  EXPECT_NEAR(counts.gyro[0].coeffs[0], 1e-3 / 1.3323e-4, 1e-9);
  EXPECT_NEAR(counts.accel[2].sigma[0], 1e-4 / (9.80665 / 16384.0), 1e-9);

  std::vector<ImuSample> v(3);
  v[0].temperature = (45.0 - 36.53) * 340.0;  // 45 deg C: clamped to 40
  v[1].temperature = (25.0 - 36.53) * 340.0;
  v[2].temperature = std::nan("");
  auto c = app::correct_to_reference_temperature(v, raw, counts);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->corrected, 2u);
  EXPECT_EQ(c->clamped, 1u);
  EXPECT_EQ(c->without_temperature, 1u);
  EXPECT_NEAR(v[0].gyro[0], -10.0 * 1e-3 / 1.3323e-4, 1e-6);
  EXPECT_NEAR(v[1].gyro[0], 5.0 * 1e-3 / 1.3323e-4, 1e-6);
  EXPECT_EQ(v[2].gyro[0], 0.0);
  EXPECT_NE(c->warning().find("1 samples outside"), std::string::npos) << c->warning();

  std::vector<ImuSample> none(4);
  auto refused = app::correct_to_reference_temperature(none, raw, counts);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, Errc::kInsufficientData);
  EXPECT_NE(refused.error().message.find("no die temperature"), std::string::npos);
}

}  // namespace
}  // namespace imucal
