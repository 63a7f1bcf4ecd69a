// SPDX-License-Identifier: BSD-3-Clause
// The guided session end to end on the virtual rig: the engine and its runner (app/session), the
// emulated MPU-6000 behind the real driver and acquisition (sim/session_rig.hpp) moved by the
// scripted operator, the static solve through the solver module, the session log, and replay.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "app/results/thermal_results.hpp"
#include "app/rig/rig.hpp"
#include "app/session/session_replay.hpp"
#include "app/session/session_runner.hpp"
#include "core/rig_config.hpp"
#include "core/text_format.hpp"
#include "log/frame_codec.hpp"
#include "log/session_log.hpp"
#include "sim/session_rig.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

using app::session::SessionRunner;
using nlohmann::json;

class ModuleDir {
 public:
  ModuleDir() { setenv("IMUCAL_MODULE_DIR", IMUCAL_MODULE_BUILD_DIR, 1); }
  ~ModuleDir() { unsetenv("IMUCAL_MODULE_DIR"); }
};

RigConfig session_config(const std::vector<std::string>& steps) {
  auto config = load_rig_config(test::source_path("config/rig.yaml"));
  EXPECT_TRUE(config.ok());
  RigConfig c = *config;
  c.session.steps = steps;
  return c;
}

/// A service session on the virtual rig, run the way imucald runs it: samples in 20 ms batches,
/// solves and writes on the runner's worker, their results posted back between batches.
class SimSession {
 public:
  explicit SimSession(RigConfig config, std::uint64_t seed = 3,
                      std::optional<sim::ImuModelParams> params = std::nullopt)
      : config_(std::move(config)), dir_(test::scratch_dir()) {
    auto settings = app::driver_settings(config_.imu);
    EXPECT_TRUE(settings.ok());
    sim::SessionRigOptions ro;
    ro.settings = *settings;
    ro.seed = seed;
    ro.params = std::move(params);
    auto rig = sim::SessionRig::create(ro);
    EXPECT_TRUE(rig.ok()) << rig.error().message;
    rig_ = std::move(*rig);
    app::session::RunnerOptions o;
    o.state_dir = dir_;
    o.post = [this](std::function<void()> f) {
      std::lock_guard lock(mutex_);
      posted_.push_back(std::move(f));
    };
    o.broadcast = [this](const session_msg::SessionMessage& typed) {
      // Kept as the socket's JSON: the tests check what a client sees.
      const json m = session_msg::encode(typed);
      // Every message the engine emits decodes back to itself (the log and the socket's form).
      auto decoded = session_msg::decode(m);
      EXPECT_TRUE(decoded.ok()) << m.dump() << ": " << (decoded.ok() ? "" : decoded.error().message);
      if (decoded.ok()) {
        EXPECT_EQ(session_msg::dump(*decoded), m.dump(-1, ' ', false, json::error_handler_t::replace));
      }
      messages_.push_back(m);
      if (m.value("type", "") == "prompt" && first_prompt_ns_ < 0) first_prompt_ns_ = rig_->now_ns();
      if (m.value("type", "") == "review") review_ns_ = rig_->now_ns();
      if (m.value("type", "") == "fault" && redo_faults_)
        keys_.emplace_back(rig_->now_ns() + 2'000'000'000, "redo");
      const bool review_prompt = m.value("type", "") == "prompt" && m.value("step", "") == "review";
      if (scripted_ && (answer_review_ || !review_prompt)) op_->on_message(typed, rig_->now_ns());
      if (!scripted_ && m.value("type", "") == "prompt" && m.value("step", "") == "preflight")
        keys_.emplace_back(rig_->now_ns() + 500'000'000, "continue");
    };
    o.preflight = [this] {
      app::session::PreflightReport r;
      if (failing_self_tests_ > 0) {
        --failing_self_tests_;
        r.devices.push_back({"imu", false, "MPU-6000 emulator, SELF-TEST FAILED (accel x 31 %)",
                             "the self-test fails when the rig moves during it: hold the rig still"});
      } else {
        r.devices.push_back({"imu", true, "MPU-6000 emulator, WHO_AM_I 0x68", {}});
      }
      r.devices.push_back({"storage", true, "file", {}});
      return r;
    };
    o.recover = [this] {
      ++recoveries_;
      return Status{};
    };
    o.complete_record = [this](CalibrationRecord& record) -> Status {
      ++completions_;
      record.notes.push_back("completed by the host");
      for (const auto& note : host_notes_) record.notes.push_back(note);
      return {};
    };
    o.write_storage = [this](const CalibrationRecord& payload) -> Result<std::string> {
      ++write_calls_;
      if (fail_writes_ > 0) {
        --fail_writes_;
        return make_error(Errc::kIo, "EEPROM did not acknowledge");
      }
      written_ = payload;
      return std::string("test storage, slot A, sequence ") + std::to_string(write_calls_);
    };
    o.metadata = {{"rig_config", rig_config_to_json(config_)}};
    o.frames_wait_for_encoder = true;  // frames come as fast as the loop runs, as in imucald --sim
    runner_ = std::make_unique<SessionRunner>(config_, rig_->stream_info(), o);
    sim::ScriptedOperatorOptions oo;
    oo.abort_on_fault = false;  // the tests press redo themselves
    op_ = std::make_unique<sim::ScriptedOperator>(rig_->trajectory(), oo,
                                                  [this](session_msg::OperatorKey key) { press(key); });
  }

  void press(session_msg::OperatorKey key) { (void)runner_->engine().key(key); }
  void press(const std::string& key) { press(*session_msg::parse_key(key)); }

  /// Runs until the session ends or `max_s` of rig time passed.
  void run(double max_s, const std::function<void(SimSession&)>& each_batch = nullptr) {
    const TimeNs end = rig_->now_ns() + static_cast<TimeNs>(max_s * 1e9);
    std::vector<ImuSample> batch;
    while (rig_->now_ns() < end && (runner_->engine().running() || !started_)) {
      started_ = true;
      batch.clear();
      ASSERT_TRUE(rig_->advance(20'000'000, batch).ok());
      runner_->on_samples(batch);
      runner_->drain();
      std::vector<std::function<void()>> posted;
      {
        std::lock_guard lock(mutex_);
        posted.swap(posted_);
      }
      for (auto& f : posted) f();
      op_->on_time(rig_->now_ns());
      while (!keys_.empty() && keys_.front().first <= rig_->now_ns()) {
        press(keys_.front().second);
        keys_.erase(keys_.begin());
      }
      if (each_batch) each_batch(*this);
    }
    std::printf("run ended at rig time %.2f s, session %s\n", ns_to_s(rig_->now_ns()),
                session_msg::session_state_name(runner_->engine().status().state));
  }

  /// `imucal replay` of the session's log into <dir>/replay.
  auto replay() const {
    app::session::ReplayOptions ro;
    ro.log_path = runner_->log_path();
    ro.out_dir = dir_ + "/replay";
    return app::session::replay_session(ro);
  }

  std::vector<json> of_type(const std::string& type) const {
    std::vector<json> out;
    for (const auto& m : messages_)
      if (m.value("type", "") == type) out.push_back(m);
    return out;
  }
  bool said(const std::string& fragment) const {
    for (const auto& m : messages_)
      if (m.value("text", "").find(fragment) != std::string::npos) return true;
    return false;
  }
  std::string outcome() const {
    const auto done = of_type("done");
    return done.empty() ? "" : done.back().value("outcome", "");
  }

  RigConfig config_;
  std::string dir_;
  std::unique_ptr<sim::SessionRig> rig_;
  std::unique_ptr<SessionRunner> runner_;
  std::unique_ptr<sim::ScriptedOperator> op_;
  std::mutex mutex_;
  std::vector<std::function<void()>> posted_;
  std::vector<json> messages_;
  std::vector<std::pair<TimeNs, std::string>> keys_;
  TimeNs first_prompt_ns_ = -1, review_ns_ = -1;
  bool started_ = false, redo_faults_ = true, scripted_ = true;
  bool answer_review_ = true;  // the scripted operator accepts the review
  int recoveries_ = 0, write_calls_ = 0, fail_writes_ = 0;
  int failing_self_tests_ = 0;  // preflights that report a self-test spoilt by motion
  std::optional<CalibrationRecord> written_;
  int completions_ = 0;
  std::vector<std::string> host_notes_;  // added to the record by complete_record
};

const std::vector<std::string> kImuSteps = {"preflight", "warmup", "still", "poses",
                                            "solve",     "review", "write"};

TEST(Session, FullSimulatedSessionWritesAVerifiedRecordAndReplaysToTheSameResult) {
  ModuleDir modules;
  SimSession s(session_config(kImuSteps));
  // What the service's keep_stored_cameras says of a stored thermal model it cannot keep.
  const std::string thermal_note =
      "the stored thermal model (sequence 3, reference 41.0 deg C) is not kept: this session's IMU "
      "calibration was not corrected to its reference temperature; run the thermal step (or calibrate "
      "thermal) again to store one";
  s.host_notes_ = {thermal_note};
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(400.0);
  if (s.outcome() != "written")
    for (const auto& m : s.messages_) std::printf("%s\n", m.dump().c_str());
  ASSERT_EQ(s.outcome(), "written");
  EXPECT_EQ(s.write_calls_, 1);
  // The end names where the record went and the session's folder.
  const json done = s.of_type("done").back();
  EXPECT_EQ(done.value("text", ""), "The calibration was written, read back and verified.");
  EXPECT_EQ(done.value("stored", ""), "test storage, slot A, sequence 1");
  EXPECT_EQ(done.value("session_dir", ""), s.runner_->session_dir());
  // The record written is the solve's static result, as the host completed it.
  ASSERT_TRUE(s.written_);
  EXPECT_EQ(s.completions_, 1);
  EXPECT_EQ(s.written_->imu.source, "static");
  EXPECT_EQ(s.written_->imu.stream, s.rig_->stream_info().name);
  EXPECT_EQ(s.written_->imu.input_units, "raw");
  ASSERT_EQ(s.written_->notes.size(), 2u);
  EXPECT_EQ(s.written_->notes[0], "completed by the host");
  EXPECT_EQ(s.written_->notes[1], thermal_note);
  ASSERT_EQ(s.written_->files.size(), 1u);
  EXPECT_EQ(s.written_->files[0].path, s.runner_->session_dir() + "/imu-static.yaml");
  EXPECT_GE(s.runner_->engine().poses().size(), 18u);
  const auto review = s.of_type("review");
  ASSERT_EQ(review.size(), 1u);
  EXPECT_TRUE(review[0].value("pass", false)) << review[0].dump();
  {
    // The review states every figure in its unit: the biases as the correction removes them
    // (A b, in m/s^2 and deg/s), the model's counts beside; the gates with their own decimals.
    const CanonicalImuModel& m = s.written_->imu.model;
    auto three = [](const Eigen::Vector3d& v, double k, int d) {
      return fixed(v.x() * k, d) + " " + fixed(v.y() * k, d) + " " + fixed(v.z() * k, d);
    };
    const Eigen::Vector3d b_a = m.A_a * m.b_a, b_g = m.A_g * m.b_g;
    // Each with its sigma: the model's b is minus Tedaldi's bias, whose sigma the record keeps;
    // through A, each entry independent.
    ASSERT_TRUE(s.written_->imu.sigma.accel && s.written_->imu.sigma.gyro);
    const Eigen::Vector3d s_a = s.written_->imu.sigma.accel->bias, s_g = s.written_->imu.sigma.gyro->bias;
    const Eigen::Vector3d s_a_si = (m.A_a.cwiseAbs2() * s_a.cwiseAbs2()).cwiseSqrt(),
                          s_g_si = (m.A_g.cwiseAbs2() * s_g.cwiseAbs2()).cwiseSqrt();
    EXPECT_TRUE((s_a.array() > 0).all() && (s_g.array() > 0).all());
    std::vector<std::string> lines;
    for (const auto& l : review[0]["lines"]) lines.push_back(l.get<std::string>());
    const auto has_line = [&](const std::string& want) {
      return std::find(lines.begin(), lines.end(), want) != lines.end();
    };
    EXPECT_TRUE(has_line("Accel bias: " + three(b_a, 1.0, 4) + " +- " + three(s_a_si, 1.0, 4) + " m/s^2 (" +
                         three(m.b_a, 1.0, 1) + " +- " + three(s_a, 1.0, 1) + " counts)"))
        << review[0].dump(1);
    EXPECT_TRUE(has_line("Gyro bias: " + three(b_g, 180.0 / M_PI, 3) + " +- " +
                         three(s_g_si, 180.0 / M_PI, 3) + " deg/s (" + three(m.b_g, 1.0, 1) + " +- " +
                         three(s_g, 1.0, 1) + " counts)"))
        << review[0].dump(1);
    // The stored thermal model the record does not keep is said in the review, before the accept.
    EXPECT_TRUE(has_line("Thermal: " + thermal_note)) << review[0].dump(1);
    // An accelerometer bias of a few hundred counts is a fraction of a m/s^2 (the virtual rig's
    // MPU-6000 at +-4 g: 1/8192 g a count), a gyro bias of a few counts a few deg/s at most.
    EXPECT_LT(b_a.norm(), 1.0);
    EXPECT_GT(m.b_a.norm(), 50.0);
    EXPECT_LT(b_g.norm() * 180.0 / M_PI, 5.0);
    for (const auto& g : review[0]["gates"]) {
      if (g.value("name", "") == "distinct attitudes") {
        EXPECT_EQ(g.value("digits", -1), 0) << g.dump();
      }
      if (g.value("name", "").starts_with("largest scale sigma")) {
        EXPECT_EQ(g.value("digits", -1), 2) << g.dump();
        EXPECT_GT(g.value("value", 0.0), 0.01) << "shown in units of 1e-3: " << g.dump();
      }
    }
  }
  // Rig time from the first prompt to the review: the protocol's budget is 3 minutes.
  const double rig_s = static_cast<double>(s.review_ns_ - s.first_prompt_ns_) * 1e-9;
  std::printf("rig time first prompt -> review: %.1f s, %zu poses\n", rig_s,
              s.runner_->engine().poses().size());
  EXPECT_LT(rig_s, 180.0);
  // The warm-up showed the die temperature, which rises on the virtual rig (a slowly settling
  // first-order warm-up) but slower than the step's threshold.
  std::vector<double> temps;
  for (const auto& m : s.of_type("live"))
    if (m.value("step", "") == "warmup") temps.push_back(m["figures"].value("temperature_c", 0.0));
  ASSERT_GE(temps.size(), 10u);
  std::printf("warm-up temperature %.3f -> %.3f C\n", temps.front(), temps.back());
  EXPECT_GT(temps.back(), temps.front());
  EXPECT_TRUE(std::filesystem::exists(s.runner_->session_dir() + "/imu-static.yaml"));
  EXPECT_TRUE(std::filesystem::exists(s.runner_->session_dir() + "/report.html"));

  // The log is complete and holds the operator's keys.
  auto reader = log::SessionLogReader::open(s.runner_->log_path());
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  auto events = (*reader)->events();
  ASSERT_TRUE(events.ok());
  int keys = 0;
  for (const auto& e : *events) keys += e.message.find("\"type\":\"key\"") != std::string::npos;
  EXPECT_GE(keys, 2);  // continue at preflight, accept at review

  // Replay reaches the same result, bit for bit.
  auto replay = s.replay();
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  EXPECT_EQ(replay->outcome, "written");
  EXPECT_TRUE(replay->live_result);
  EXPECT_EQ(replay->max_difference, 0.0);
  EXPECT_GE(replay->keys, 2);
}

TEST(Session, AnImuFaultStopsTheStepAndRedoContinuesWithTheRecordedPoses) {
  ModuleDir modules;
  SimSession s(session_config(kImuSteps));
  ASSERT_TRUE(s.runner_->start({}).ok());
  bool injected = false;
  std::size_t poses_at_fault = 0;
  s.run(500.0, [&](SimSession& ss) {
    if (!injected && ss.runner_->engine().poses().size() == 5) {
      injected = true;
      poses_at_fault = 5;
      ss.runner_->fault("imu", "FIFO read failed: bus error");
    }
  });
  ASSERT_TRUE(injected);
  EXPECT_EQ(s.recoveries_, 1);
  EXPECT_TRUE(s.said("Redoing step poses"));
  EXPECT_GE(s.runner_->engine().poses().size(), poses_at_fault + 13);
  EXPECT_EQ(s.outcome(), "written");
  ASSERT_EQ(s.of_type("fault").size(), 1u);
  EXPECT_NE(s.of_type("fault")[0].value("advice", "").find("recorded is kept"), std::string::npos);
  // The step list follows: failed at the fault, active again after the redo (no stale mark).
  auto poses_state = [](const json& status) {
    for (const auto& step : status.value("steps", json::array()))
      if (step.value("name", "") == "poses") return step.value("state", "");
    return std::string();
  };
  std::vector<std::string> states;
  for (const auto& status : s.of_type("status")) states.push_back(poses_state(status));
  const auto failed = std::find(states.begin(), states.end(), "failed");
  ASSERT_NE(failed, states.end()) << "a status after the fault marks the step failed";
  ASSERT_NE(failed + 1, states.end());
  EXPECT_EQ(*(failed + 1), "active") << "the redo's status clears the mark";
}

TEST(Session, AStorageErrorLeavesTheStoredRecordAloneAndRedoWritesAgain) {
  ModuleDir modules;
  SimSession s(session_config(kImuSteps));
  s.fail_writes_ = 1;
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(500.0);
  EXPECT_EQ(s.write_calls_, 2);
  EXPECT_EQ(s.outcome(), "written");
  const auto faults = s.of_type("fault");
  ASSERT_EQ(faults.size(), 1u);
  EXPECT_EQ(faults[0].value("source", ""), "storage");
}

TEST(Session, AbortKeepsTheRecordingAndWritesNothing) {
  ModuleDir modules;
  SimSession s(session_config(kImuSteps));
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(500.0, [](SimSession& ss) {
    if (ss.runner_->engine().poses().size() == 3) ss.press("abort");
  });
  EXPECT_EQ(s.outcome(), "aborted");
  EXPECT_EQ(s.write_calls_, 0);
  auto reader = log::SessionLogReader::open(s.runner_->log_path());
  ASSERT_TRUE(reader.ok());
  EXPECT_TRUE((*reader)->health().complete);
  auto id = (*reader)->find_imu_stream();
  ASSERT_TRUE(id.ok());
  auto n = (*reader)->imu_count(*id);
  ASSERT_TRUE(n.ok());
  EXPECT_GT(*n, 200 * 20);  // warm-up, still start and three poses at 200 Hz
}

TEST(Session, ASessionThatEndedKeepsTheTimeItTook) {
  ModuleDir modules;
  SimSession s(session_config(kImuSteps));
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(500.0, [](SimSession& ss) {
    if (ss.runner_->engine().poses().size() == 2) ss.press("abort");
  });
  ASSERT_EQ(s.outcome(), "aborted");
  const double took = s.runner_->engine().status().elapsed_s;
  EXPECT_GT(took, 10.0);
  // Samples go on coming after the end (the IMU streams while the service runs): the session's
  // elapsed time does not grow with them.
  std::vector<ImuSample> batch;
  for (int i = 0; i < 100; ++i) {  // 2 s
    batch.clear();
    ASSERT_TRUE(s.rig_->advance(20'000'000, batch).ok());
    s.runner_->on_samples(batch);
  }
  EXPECT_DOUBLE_EQ(s.runner_->engine().status().elapsed_s, took);
}

TEST(Session, MotionDuringTheStillStartRestartsTheCountdown) {
  ModuleDir modules;
  SimSession s(session_config({"preflight", "still", "poses"}));
  s.config_.session.poses = 9;
  ASSERT_TRUE(s.runner_->start({}).ok());
  bool bumped = false;
  s.run(60.0, [&](SimSession& ss) {
    const auto st = ss.runner_->engine().status();
    if (!bumped && st.step == session_msg::StepId::kStill && ss.of_type("live").size() > 0 &&
        ss.of_type("live").back().value("progress", 0.0) > 0.5) {
      bumped = true;
      ss.rig_->trajectory().turn(ss.rig_->now_ns(), 1.0,
                                 Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX())));
    }
    if (st.step == session_msg::StepId::kPoses) ss.press("abort");
  });
  ASSERT_TRUE(bumped);
  EXPECT_TRUE(s.said("Motion detected"));
}

TEST(Session, APoseTooCloseToAnEarlierOneIsRefused) {
  ModuleDir modules;
  SimSession s(session_config({"preflight", "still", "poses"}));
  s.scripted_ = false;
  ASSERT_TRUE(s.runner_->start({}).ok());
  // A first pose 60 deg from the rest attitude, then a turn of 5 deg and a hold: refused.
  bool first = false, second = false;
  auto turn = [](SimSession& ss, double deg) {
    const Eigen::Quaterniond q =
        ss.rig_->trajectory().final_orientation() *
        Eigen::Quaterniond(Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
    ss.rig_->trajectory().turn(ss.rig_->now_ns() + 100'000'000, 1.0, q);
  };
  s.run(120.0, [&](SimSession& ss) {
    const auto status_step = ss.runner_->engine().status().step;
    const std::string step = status_step ? session_msg::step_name(*status_step) : "";
    if (!first && step == "poses") {
      first = true;
      turn(ss, 60.0);
    }
    if (!second && ss.runner_->engine().poses().size() == 1) {
      second = true;
      turn(ss, 5.0);
    }
    if (ss.said("Too close")) ss.press("abort");
  });
  EXPECT_TRUE(s.said("Too close to pose 1"));
  EXPECT_EQ(s.runner_->engine().poses().size(), 1u);
}

/// A rig switched on cold: the die warms from 20 C towards 45 C (time constant 200 s) and the
/// biases follow a quadratic in temperature drawn from `seed`.
sim::ImuModelParams cold_start(std::uint64_t seed) {
  sim::ImuModelParams p = sim::ImuModelParams::draw(seed);
  p.temp_start_c = 20.0;
  p.temp_final_c = 45.0;
  p.temp_time_constant_s = 200.0;
  p.draw_temperature_coefficients(seed, 2);
  return p;
}

/// Ends the thermal step with the operator's c once it has recorded `seconds`.
std::function<void(SimSession&)> end_thermal_after(double seconds) {
  return [seconds, pressed = false](SimSession& ss) mutable {
    const auto& e = ss.runner_->engine();
    if (!pressed && e.current_step() == app::session::StepId::kThermal &&
        ns_to_s(e.now_ns() - e.step_start_ns()) > seconds) {
      pressed = true;
      ss.press("continue");
    }
  };
}

TEST(Session, AThermalRecordingAloneFitsTheBiasAgainstTemperatureOfAColdStart) {
  ModuleDir modules;
  const sim::ImuModelParams truth = cold_start(5);
  SimSession s(session_config({"preflight", "thermal", "solve", "review"}), 5, truth);
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(600.0, end_thermal_after(240.0));
  ASSERT_EQ(s.outcome(), "completed");
  EXPECT_TRUE(s.said("Thermal recording ended by the operator: "));
  // The live view showed the temperature rising and the gyro's change against it.
  std::vector<double> temps;
  json last;
  for (const auto& m : s.of_type("live"))
    if (m.value("step", "") == "thermal") temps.push_back(m["figures"].value("temperature_c", 0.0)), last = m;
  ASSERT_GE(temps.size(), 100u);
  std::printf("thermal step: die %.2f -> %.2f C\n", temps.front(), temps.back());
  EXPECT_GT(temps.back() - temps.front(), 8.0);
  ASSERT_TRUE(last["figures"].contains("gyro_slope_dps_per_c")) << last.dump();
  // The model: written in the `calibrate thermal` format, drawn, shown in the review.
  const std::string yaml = s.runner_->session_dir() + "/thermal.yaml";
  auto file = app::read_thermal_file(yaml);
  ASSERT_TRUE(file.ok()) << file.error().message;
  EXPECT_TRUE(std::filesystem::exists(s.runner_->session_dir() + "/report-thermal.html"));
  EXPECT_FALSE(std::filesystem::exists(s.runner_->session_dir() + "/imu-static.yaml"));
  const auto& r = file->result;
  // The bins' range: 20 s means of a die warming by up to 3 C a minute.
  EXPECT_NEAR(r.temp_min_c, temps.front(), 1.5);
  EXPECT_NEAR(r.temp_max_c, temps.back(), 1.5);
  // The fitted change over the range against the truth. The fit is on the nominal conversion of
  // the raw counts (the rig's scale errors are 1-3 %), so the truth is compared within its
  // sigma and 5 % of the change.
  // The bias random walk over the recording: where the truth's change is not larger, the data
  // cannot tell it (order 0 may be chosen, honestly).
  const double walk = truth.gyro_bias_random_walk * std::sqrt(r.duration_s);
  double worst = 0.0;
  int fitted = 0;
  for (int a = 0; a < 3; ++a) {
    const auto& fit = r.gyro[a];
    ASSERT_TRUE(fit.determined) << fit.reason;
    const double truth_change =
        truth.gyro_bias_temp(r.temp_max_c)[a] - truth.gyro_bias_temp(r.reference_c)[a];
    const double change = fit.change(r.temp_max_c, r.reference_c);
    const double sigma = fit.change_sigma(r.temp_max_c, r.reference_c);
    std::printf("gyro %c: change to %.1f C fitted %.3e, truth %.3e, sigma %.1e rad/s\n", "xyz"[a],
                r.temp_max_c, change, truth_change, sigma);
    if (std::abs(truth_change) < 3.0 * walk) {
      EXPECT_LT(std::abs(change - truth_change), 4.0 * sigma + 0.05 * std::abs(truth_change) + walk)
          << "axis " << a;
      continue;
    }
    ++fitted;
    EXPECT_GE(fit.order, 1) << "axis " << a;
    EXPECT_LT(std::abs(change - truth_change), 4.0 * sigma + 0.05 * std::abs(truth_change)) << "axis " << a;
    worst = std::max(worst, std::abs(change - truth_change) / std::abs(truth_change));
  }
  std::printf(
      "random walk over the recording %.1e rad/s; worst relative error of the gyro's change "
      "where the change is above 3 times that: %.3f (%d axes)\n",
      walk, worst, fitted);
  EXPECT_GE(fitted, 2);
  const auto review = s.of_type("review");
  ASSERT_EQ(review.size(), 1u);
  EXPECT_NE(review[0]["lines"][0].get<std::string>().find("Thermal model: reference "), std::string::npos)
      << review[0].dump(1);
  const auto results = s.of_type("result");
  ASSERT_EQ(results.size(), 1u);
  EXPECT_TRUE(results[0]["thermal"].value("determined", false)) << results[0].dump();
}

TEST(Session, AThermalStepBeforeThePosesCorrectsTheSamplesAndTheRecordCarriesTheModel) {
  ModuleDir modules;
  SimSession s(session_config({"preflight", "thermal", "still", "poses", "solve", "review", "write"}), 5,
               cold_start(5));
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(900.0, end_thermal_after(150.0));
  ASSERT_EQ(s.outcome(), "written");
  ASSERT_TRUE(s.written_);
  ASSERT_EQ(s.of_type("review").size(), 1u);
  ASSERT_TRUE(s.written_->thermal) << s.of_type("review")[0]["lines"].dump(1);
  auto file = app::read_thermal_file(s.runner_->session_dir() + "/thermal.yaml");
  ASSERT_TRUE(file.ok()) << file.error().message;
  EXPECT_NEAR(s.written_->thermal->reference_c, file->result.reference_c, 1e-9);  // YAML keeps 12 digits
  // The record's model is on the stream's raw counts: the SI model divided by the nominal scale.
  const auto& info = s.rig_->stream_info();
  for (int a = 0; a < 3; ++a) {
    const auto& si = file->model.gyro[a];
    const auto& counts = s.written_->thermal->gyro[a];
    ASSERT_EQ(si.coeffs.size(), counts.coeffs.size());
    if (si.coeffs.size() > 0) {
      EXPECT_NEAR(counts.coeffs[0], si.coeffs[0] / info.gyro.scale[a],
                  1e-9 * std::abs(counts.coeffs[0]) + 1e-15);
    }
  }
  // The static result states the reference temperature its biases are at.
  std::ifstream in(s.runner_->session_dir() + "/imu-static.yaml");
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_NE(text.str().find("reference_temperature_c"), std::string::npos);
  EXPECT_TRUE(s.said("Thermal recording ended by the operator"));
  bool stated = false, beyond = false, uncertainty = false;
  const auto review = s.of_type("review");
  for (const auto& l : review.at(0)["lines"]) {
    stated = stated || l.get<std::string>().starts_with("The biases above are those at ");
    // The die went on warming after the operator ended the recording: the poses are above the
    // model's range, and the review says what that leaves.
    beyond =
        beyond || l.get<std::string>().find("samples outside the thermal model's range") != std::string::npos;
    uncertainty = uncertainty || l.get<std::string>().find("leave out the thermal model's own uncertainty") !=
                                     std::string::npos;
  }
  EXPECT_TRUE(stated) << review.at(0)["lines"].dump(1);
  EXPECT_TRUE(beyond) << review.at(0)["lines"].dump(1);
  EXPECT_TRUE(uncertainty) << review.at(0)["lines"].dump(1);

  // Replay takes the same thermal recording from the log and reaches the same result.
  auto replay = s.replay();
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  EXPECT_EQ(replay->outcome, "written");
  EXPECT_EQ(replay->max_difference, 0.0);
  auto replayed = app::read_thermal_file(s.dir_ + "/replay/thermal.yaml");
  ASSERT_TRUE(replayed.ok()) << replayed.error().message;
  EXPECT_EQ(replayed->result.reference_c, file->result.reference_c);
}

TEST(Session, MotionDuringTheThermalRecordingStartsItAgainAndASmallSpanGivesNoModel) {
  ModuleDir modules;
  // The virtual rig's usual die: 1.5 C below its working temperature, too little for a model.
  SimSession s(session_config({"preflight", "thermal", "solve", "review"}), 3);
  ASSERT_TRUE(s.runner_->start({}).ok());
  bool bumped = false;
  s.run(400.0, [&](SimSession& ss) {
    const auto& e = ss.runner_->engine();
    if (!bumped && e.current_step() == app::session::StepId::kThermal &&
        ns_to_s(e.now_ns() - e.step_start_ns()) > 5.0) {
      bumped = true;
      ss.rig_->trajectory().turn(ss.rig_->now_ns(), 1.0,
                                 Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX())));
    }
  });
  ASSERT_TRUE(bumped);
  EXPECT_TRUE(s.said("Motion during the thermal recording: it starts again from here"));
  EXPECT_TRUE(s.said("less than session.thermal_min_span_c (3.0 C): no thermal model"));
  EXPECT_FALSE(std::filesystem::exists(s.runner_->session_dir() + "/thermal.yaml"));
  // With no poses either, there is nothing to solve: said, and the recording is kept.
  EXPECT_EQ(s.outcome(), "failed");
  EXPECT_TRUE(s.said("nothing to solve: the session has no poses and its thermal recording gave no model"));
  EXPECT_TRUE(std::filesystem::exists(s.runner_->log_path()));
}

TEST(Session, StartRefusesStepsOutOfOrderOrWithoutTheirInputs) {
  SimSession s(session_config(kImuSteps));
  EXPECT_FALSE(s.runner_->engine().start({"poses", "still"}).ok());
  EXPECT_FALSE(s.runner_->engine().start({"preflight", "review"}).ok());
  EXPECT_FALSE(s.runner_->engine().start({"solve"}).ok());
  EXPECT_FALSE(s.runner_->engine().start({"nonsense"}).ok());
  // A thermal recording alone is solved and reviewed, but not written: its model goes to storage
  // with the IMU calibration whose biases it refers to its reference temperature.
  const auto alone = s.runner_->engine().plan({"preflight", "thermal", "solve", "review", "write"});
  ASSERT_FALSE(alone.ok());
  EXPECT_NE(alone.error().message.find("step 'write' needs the 'poses' step"), std::string::npos)
      << alone.error().message;
  EXPECT_TRUE(s.runner_->engine().plan({"preflight", "thermal", "solve", "review"}).ok());
  // Thermal is opt-in: not among the steps run when the configuration lists none.
  for (auto id : app::session::configured_steps(session_config({})))
    EXPECT_NE(id, app::session::StepId::kThermal);
  RigConfig no_cam = session_config({});
  no_cam.cameras.clear();
  SimSession t(no_cam);
  EXPECT_FALSE(t.runner_->engine().start({"motion"}).ok());
  // A refused start leaves no session folder behind for the status to point at.
  EXPECT_FALSE(t.runner_->start({"nonsense"}).ok());
  EXPECT_FALSE(t.runner_->start({"preflight", "review"}).ok());
  EXPECT_FALSE(std::filesystem::exists(t.dir_ + "/sessions") &&
               !std::filesystem::is_empty(t.dir_ + "/sessions"));
  EXPECT_TRUE(t.runner_->session_dir().empty());
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(Session, MotionStepShowsExcitationDetectionAndSaturation) {
  ModuleDir modules;
  RigConfig config = session_config({"preflight", "motion"});
  config.session.motion_s = 12.0;
  SimSession s(config);
  s.scripted_ = false;
  ASSERT_TRUE(s.runner_->start({}).ok());
  bool turned = false;
  s.run(60.0, [&](SimSession& ss) {
    auto& engine = ss.runner_->engine();
    if (engine.status().step != session_msg::StepId::kMotion) return;
    const TimeNs t = ss.rig_->now_ns();
    // The target is seen for the first 4 s, then lost.
    const bool seen =
        !ss.of_type("prompt").empty() &&
        t - static_cast<TimeNs>(ss.of_type("prompt").back().value("t", 0.0) * 1e9) < 4'000'000'000;
    engine.on_frame(0, t, seen);
    if (!turned) {
      turned = true;
      // Half a turn in 0.2 s: about 1700 deg/s at its peak, far beyond the +-500 deg/s range.
      ss.rig_->trajectory().turn(
          t + 200'000'000, 0.2,
          ss.rig_->trajectory().final_orientation() *
              Eigen::Quaterniond(Eigen::AngleAxisd(M_PI * 0.999, Eigen::Vector3d::UnitX())));
    }
  });
  EXPECT_EQ(s.outcome(), "recorded");
  EXPECT_TRUE(s.said("Too fast: the IMU saturates"));
  bool lost = false, counted = false;
  for (const auto& m : s.of_type("live")) {
    for (const auto& line : m.value("lines", json::array())) {
      const std::string l = line.get<std::string>();
      lost = lost || l.find("Target lost") != std::string::npos;
      counted = counted || l.find("Target seen in") != std::string::npos;
    }
  }
  EXPECT_TRUE(lost);
  EXPECT_TRUE(counted);
}

// Two cameras: the motion step shows each one's detection rate and the share of instants both see
// the target, and asks to keep it where every camera sees it when that share is low.
TEST(Session, MotionStepWithTwoCamerasShowsEachRateAndTheSharedShare) {
  ModuleDir modules;
  RigConfig config = session_config({"preflight", "motion"});
  config.session.motion_s = 14.0;
  ASSERT_EQ(config.cameras.size(), 1u);
  config.cameras.push_back(config.cameras[0]);
  config.cameras[1].name = "cam1";
  SimSession s(config);
  s.scripted_ = false;
  ASSERT_TRUE(s.runner_->start({}).ok());
  TimeNs last_frame = -1;
  s.run(60.0, [&](SimSession& ss) {
    auto& engine = ss.runner_->engine();
    if (engine.status().step != session_msg::StepId::kMotion || ss.of_type("prompt").empty()) return;
    const TimeNs t = ss.rig_->now_ns();
    if (last_frame >= 0 && t - last_frame < 50'000'000) return;  // both cameras at their 20 Hz
    last_frame = t;
    // cam0 sees the target throughout, cam1 only in the first 4 s of the step.
    const bool early =
        t - static_cast<TimeNs>(ss.of_type("prompt").back().value("t", 0.0) * 1e9) < 4'000'000'000;
    engine.on_frame(0, t, true);
    engine.on_frame(1, t, early);
  });
  EXPECT_EQ(s.outcome(), "recorded");
  bool rates = false, advice = false;
  json last;
  for (const auto& m : s.of_type("live")) {
    for (const auto& line : m.value("lines", json::array())) {
      const std::string l = line.get<std::string>();
      rates = rates || (l.find("Target seen: cam0 100 % cam1 ") != std::string::npos &&
                        l.find("all cameras at once") != std::string::npos);
      advice = advice || l.find("Keep the target where every camera sees it") != std::string::npos;
    }
    if (m.contains("figures") && m["figures"].contains("frames_seen_by_every_camera")) last = m["figures"];
  }
  EXPECT_TRUE(rates);
  EXPECT_TRUE(advice);
  ASSERT_FALSE(last.is_null());
  const long both = last["frames_seen_by_every_camera"].get<long>();
  const long cam0 = last["camera_frames_seen"][0].get<long>();
  const long cam1 = last["camera_frames_seen"][1].get<long>();
  EXPECT_GT(both, 0);
  EXPECT_EQ(both, cam1);  // every instant cam1 saw the target, cam0 saw it too
  EXPECT_LT(2 * cam1, cam0);
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

TEST(Session, SixFaceHoldsArePromptedAndChecked) {
  ModuleDir modules;
  SimSession s(session_config({"preflight", "still", "gsens"}));
  ASSERT_TRUE(s.runner_->start({}).ok());
  bool wrong = false;
  s.run(300.0, [&](SimSession& ss) {
    // Once, the operator puts the wrong face up for the second face: the engine names it.
    if (!wrong && ss.of_type("face").size() == 1) {
      wrong = true;
      ss.rig_->trajectory().turn(
          ss.rig_->now_ns() + 500'000'000, 1.5,
          Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()));
    }
  });
  EXPECT_EQ(s.outcome(), "recorded");
  const auto faces = s.of_type("face");
  ASSERT_EQ(faces.size(), 6u);
  const char* names[] = {"+X", "-X", "+Y", "-Y", "+Z", "-Z"};
  for (int f = 0; f < 6; ++f) EXPECT_EQ(faces[f].value("face", ""), names[f]);
  EXPECT_TRUE(s.said("This is +Y up"));
  EXPECT_TRUE(s.said("All six faces held"));
  // Without named sides the prompts name the IMU's axes, with a drawing of the rig.
  const auto prompts = s.of_type("prompt");
  ASSERT_FALSE(prompts.empty());
  EXPECT_TRUE(s.said("Six-face holds, 2 of 6: Turn the rig so that the IMU's -X axis points up"));
  EXPECT_TRUE(prompts.back().contains("art") || s.said("6 of 6"));
}

TEST(Session, AFailedSelfTestSaysToHoldTheRigStillAndRedoChecksAgain) {
  ModuleDir modules;  // a session loads its solver modules when it starts
  SimSession s(session_config({"preflight", "still"}));
  s.failing_self_tests_ = 1;
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(1.0);
  const auto prompts = s.of_type("prompt");
  ASSERT_FALSE(prompts.empty());
  EXPECT_EQ(prompts.back().value("text", ""),
            "A device failed its check: imu: the self-test fails when the rig moves during it: hold the rig "
            "still. Then press r to check again, or a to abort");
  ASSERT_TRUE(s.runner_->engine().key(session_msg::OperatorKey::kRedo).ok());
  EXPECT_TRUE(s.said("every device answers"));
}

// A session that waits for a key it needs (here a failed preflight's redo) and uses no sample
// ends after session.operator_wait_s of sample time, saying why, instead of recording without end
// (about 1 GB a day at real time, 16 GB in 21 minutes at time-scale 0); the replay ends the same.
// The motion step is planned but never reached: the replay needs no motion log (before, it
// refused the folder for the motion log the session never wrote).
TEST(Session, ASessionWaitingForAKeyStopsAfterTheOperatorWait) {
  ModuleDir modules;  // a session loads its solver modules when it starts
  RigConfig config = session_config({"preflight", "still", "motion"});
  config.session.operator_wait_s = 60.0;
  SimSession s(config);
  s.scripted_ = false;  // nobody presses redo: only the unscripted continue at the preflight
  s.failing_self_tests_ = 1;
  ASSERT_TRUE(s.runner_->start({}).ok());
  const TimeNs started = s.rig_->now_ns();
  s.run(300.0);
  EXPECT_EQ(s.outcome(), "aborted");
  EXPECT_TRUE(s.said("no key for 60 s while the session waited for one (session.operator_wait_s)"));
  EXPECT_LT(ns_to_s(s.rig_->now_ns() - started), 65.0);
  EXPECT_FALSE(std::filesystem::exists(s.runner_->session_dir() + "/motion.imulog"));
  auto reader = log::SessionLogReader::open(s.runner_->log_path());
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  auto replay = s.replay();
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  EXPECT_EQ(replay->live_outcome, "aborted");
  EXPECT_EQ(replay->outcome, "aborted");
}

// The other two waits for a key: the review nobody answers, and a failed step (the storage
// write) nobody redoes or aborts. Each ends after session.operator_wait_s, says so and keeps
// what was recorded; at the review the results stay in the session folder.
TEST(Session, TheReviewAndAFailedStepAlsoStopAfterTheOperatorWait) {
  ModuleDir modules;
  for (const bool review : {true, false}) {
    SCOPED_TRACE(review ? "the review unanswered" : "a failed write nobody redoes");
    RigConfig config = session_config({"preflight", "still", "poses", "solve", "review", "write"});
    config.session.operator_wait_s = 60.0;
    SimSession s(config);
    if (review) {
      s.answer_review_ = false;
    } else {
      s.fail_writes_ = 1;
      s.redo_faults_ = false;
    }
    ASSERT_TRUE(s.runner_->start({}).ok());
    s.run(900.0);
    EXPECT_EQ(s.outcome(), "aborted");
    EXPECT_TRUE(s.said("no key for 60 s while the session waited for one (session.operator_wait_s)"));
    ASSERT_GE(s.review_ns_, 0) << "the session reached its review";
    // From the review (or the failed write just after it) to the end: the wait, and no more.
    EXPECT_LT(ns_to_s(s.rig_->now_ns() - s.review_ns_), 60.0 + 15.0);
    EXPECT_EQ(s.write_calls_, review ? 0 : 1);
    EXPECT_TRUE(s.said("The results stay in the session folder"));  // a failed write keeps them too
    auto reader = log::SessionLogReader::open(s.runner_->log_path());
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    EXPECT_TRUE((*reader)->health().complete);
  }
}

TEST(Session, PoseGuidanceNamesTheRigsSidesWhenTheConfigurationDoes) {
  ModuleDir modules;
  RigConfig config = session_config({"preflight", "still", "gsens"});
  config.sides = RigSides{};  // front +x, left +y, top +z
  SimSession s(config);
  ASSERT_TRUE(s.runner_->start({}).ok());
  s.run(300.0);
  EXPECT_EQ(s.outcome(), "recorded");
  EXPECT_TRUE(s.said("Six-face holds, 1 of 6: Put the rig on its back side, front side up"));
  EXPECT_TRUE(s.said("Six-face holds, 3 of 6: Put the rig on its right side, left side up"));
  EXPECT_TRUE(s.said("Six-face holds, 5 of 6: Stand the rig upright (top side up)"));
  EXPECT_TRUE(s.said("Six-face holds, 6 of 6: Turn the rig upside down (bottom side up)"));
  bool drawn = false;
  for (const auto& prompt : s.of_type("prompt")) {
    if (prompt.value("text", "").find("left side up") == std::string::npos) continue;
    const std::string art = prompt.value("art", json::array()).dump();
    drawn = art.find("LEFT") != std::string::npos && art.find("FRONT") != std::string::npos &&
            art.find("right: BOTTOM") != std::string::npos;
  }
  EXPECT_TRUE(drawn) << "the drawing for 'left side up' shows LEFT on top, FRONT to the operator, BOTTOM on "
                        "the operator's right";
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

/// A YUYV frame of the camera, stamped at the start of its exposure as some V4L2 drivers do; its
/// luma is a pattern of the frame number. Counts the releases of its buffer.
struct YuyvFrame {
  std::vector<std::uint8_t> bytes;
  int released = 0;

  static std::uint8_t luma(int x, int y, std::uint32_t n) {
    return static_cast<std::uint8_t>(x + 3 * y + 7 * n);
  }

  drivers::camera::Frame make(int width, int height, std::uint32_t n, TimeNs t_ns) {
    const std::size_t stride = static_cast<std::size_t>(width) * 2 + 16;  // padded rows
    bytes.assign(stride * static_cast<std::size_t>(height), 128);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) bytes[static_cast<std::size_t>(y) * stride + 2 * x] = luma(x, y, n);
    drivers::camera::Frame f;
    f.t_ns = t_ns;
    f.exposure_ns = 4'000'000;
    f.sequence = n;
    f.width = width;
    f.height = height;
    f.pixel_format = "YUYV";
    f.stride = stride;
    f.data = bytes;
    f.set_release([this] { ++released; });
    return f;
  }
};

TEST(Session, TheServicesFramesGoThroughTheCameraStreamIntoTheMotionLog) {
  ModuleDir modules;
  RigConfig config = session_config({"preflight", "motion"});
  config.session.motion_s = 3.0;
  SimSession s(config);
  s.scripted_ = false;
  ASSERT_TRUE(s.runner_->start({}).ok());
  const int w = config.cameras[0].width, h = config.cameras[0].height;
  YuyvFrame source;
  std::uint32_t fed = 0;
  std::vector<TimeNs> stamps;
  s.run(30.0, [&](SimSession& ss) {
    if (!ss.runner_->wants_frames()) return;
    const TimeNs t = ss.rig_->now_ns() - 10'000'000;
    auto frame = source.make(w, h, fed, t);
    ss.runner_->on_frame(0, frame, drivers::camera::TimestampMeaning::kStartOfExposure);
    EXPECT_EQ(source.released, static_cast<int>(fed) + 1) << "the device buffer is given back at once";
    stamps.push_back(t + 2'000'000);  // mid-exposure
    ++fed;
  });
  ASSERT_EQ(s.outcome(), "recorded");
  ASSERT_GT(fed, 100u);  // 3 s of 20 ms batches

  auto reader = log::SessionLogReader::open(s.runner_->session_dir() + "/" + app::session::kMotionLogFile);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->health().complete);
  auto id = (*reader)->find_camera_stream("cam0");
  ASSERT_TRUE(id.ok());
  const CameraStreamInfo& info = (*reader)->camera_streams().at(*id);
  EXPECT_EQ(info.timestamp_source, "mid-exposure");
  EXPECT_EQ(info.width, w);
  // Every frame, in order, stamped at mid-exposure, its luma exactly.
  std::uint32_t n = 0;
  ASSERT_TRUE(
      (*reader)
          ->for_each_frame(
              *id, 0, std::numeric_limits<TimeNs>::max(),
              [&](const CameraFrame& f) {
                EXPECT_EQ(f.t_ns, stamps.at(n));
                EXPECT_EQ(f.sequence, n);
                auto image = log::decode_image(f.data);
                EXPECT_TRUE(image.ok());
                if (!image.ok()) return false;
                EXPECT_EQ(image->channels, 1);
                for (int y = 0; y < h; y += 37)
                  for (int x = 0; x < w; x += 41)
                    EXPECT_EQ(image->data[static_cast<std::size_t>(y * w + x)], YuyvFrame::luma(x, y, n))
                        << "frame " << n << " at " << x << "," << y;
                ++n;
                return true;
              })
          .ok());
  EXPECT_EQ(n, fed);
  // The engine counted each one, and the session log says so for replay.
  auto session = log::SessionLogReader::open(s.runner_->log_path());
  ASSERT_TRUE(session.ok());
  auto events = (*session)->events();
  ASSERT_TRUE(events.ok());
  std::uint32_t frame_events = 0;
  for (const auto& e : *events) frame_events += e.kind == "frame" ? 1u : 0u;
  EXPECT_EQ(frame_events, fed);
}

TEST(Session, ACameraInAFormatTheStreamCannotRecordIsAFaultThatSaysWhichToSet) {
  ModuleDir modules;
  RigConfig config = session_config({"preflight", "motion"});
  config.session.motion_s = 3.0;
  SimSession s(config);
  s.scripted_ = false;
  s.redo_faults_ = false;
  ASSERT_TRUE(s.runner_->start({}).ok());
  YuyvFrame source;
  bool fed = false;
  s.run(10.0, [&](SimSession& ss) {
    if (fed || !ss.runner_->wants_frames()) return;
    fed = true;
    auto frame = source.make(64, 48, 0, ss.rig_->now_ns());
    frame.pixel_format = "MJPG";
    ss.runner_->on_frame(0, frame, drivers::camera::TimestampMeaning::kMidExposure);
    EXPECT_EQ(source.released, 1);
    ss.press("abort");
  });
  ASSERT_TRUE(fed);
  const auto faults = s.of_type("fault");
  ASSERT_FALSE(faults.empty());
  EXPECT_NE(faults[0].value("text", "").find("MJPG"), std::string::npos) << faults[0].dump();
  EXPECT_NE(faults[0].value("text", "").find("GREY"), std::string::npos) << faults[0].dump();
}

}  // namespace
}  // namespace imucal
