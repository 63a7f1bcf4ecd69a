// SPDX-License-Identifier: BSD-3-Clause
// The session messages' encoder and decoder (core/session_messages.hpp): every kind decoded from
// the JSON the engine writes and encoded back to the same bytes; messages from an older or newer
// version, or damaged, give errors that name the problem.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/session_messages.hpp"

namespace imucal::session_msg {
namespace {

// One line per kind and variant, as the engine and imucald write them (keys sorted, NaN as null).
const std::vector<std::string>& wire_lines() {
  static const std::
      vector<std::string>
          lines =
              {
                  R"j({"event":"start","steps":["preflight","poses","solve"],"t":100.25,"type":"session"})j",
                  R"j({"event":"start","steps":[],"t":0.0,"type":"session"})j",
                  R"j({"elapsed_s":0.0,"poses":0,"rig":"sim","state":"running","step":"preflight","steps":[{"name":"preflight","state":"active"},{"name":"poses","state":"pending"}],"t":100.25,"type":"status"})j",
                  R"j({"elapsed_s":12.5,"poses":3,"rig":"sim","state":"idle","step":"","steps":[],"type":"status"})j",
                  R"j({"devices":{"cameras":[{"error":"","faults":0,"frames":12,"name":"cam0","state":"closed"}],"imu":{"error":"","faults":1,"gyro_offsets":"cleared","rate_hz":200.0,"samples":4000,"sim":true,"state":"open"},"storage":"file x.bin"},"elapsed_s":1.5,"poses":0,"recorded_bytes":48312345,"rig":"sim","session_dir":"/var/lib/imucal/sessions/a","state":"done","step":"","steps":[{"name":"write","state":"done"}],"type":"status","version":"1.2.3"})j",
                  R"j({"keys":["continue","abort"],"step":"preflight","t":100.25,"text":"Rig 'sim': every device answers. Press c to begin","type":"prompt"})j",
                  R"j({"art":["  +--+","  |  |"],"keys":["continue","redo","abort"],"step":"poses","t":126.75,"text":"Turn the rig","type":"prompt","up":[0.0,0.0,-1.0]})j",
                  R"j({"keys":[],"step":"write","t":214.2,"text":"Writing the calibration to the rig's storage","type":"prompt"})j",
                  R"j({"figures":{"devices":[{"detail":"virtual MPU-6000","name":"imu","ok":true},{"advice":"hold the rig still","detail":"self-test failed","name":"imu2","ok":false}],"rig":"sim","stored":null},"lines":["ok    imu: virtual MPU-6000","stored calibration: none"],"progress":1.0,"step":"preflight","t":100.25,"type":"live"})j",
                  R"j({"figures":{"rate_c_per_min":0.0,"temperature_c":34.73294117647059},"lines":["Temperature 34.73 C"],"progress":0.0,"step":"warmup","t":101.67,"type":"live"})j",
                  R"j({"figures":{"accel_slope_mps2_per_c":[null,null,null],"gyro_slope_dps_per_c":[0.001,-0.002,0.0],"range_c":[30.0,31.5],"rate_c_per_min":0.5,"temperature_c":31.5},"lines":["Temperature 31.50 C"],"progress":0.75,"step":"thermal","t":300.0,"type":"live"})j",
                  R"j({"figures":{"missing":["+X","-X"],"poses":0,"scale_sigma":null,"still":true},"lines":["Captured: turn to a new orientation"],"progress":0.0,"step":"poses","t":126.79,"type":"live"})j",
                  R"j({"figures":{"camera_frames":[100,98],"camera_frames_seen":[80,70],"frames":100,"frames_seen":80,"frames_seen_by_every_camera":60,"gyro_rms_dps":[40.0,35.5,20.25]},"lines":["Rotation RMS"],"progress":0.5,"step":"motion","t":400.0,"type":"live"})j",
                  R"j({"figures":{"camera_frames":[100],"camera_frames_seen":[80],"coverage":[{"cells":[0,3,1,0,0,2],"cols":3,"rows":2,"size":0.25,"skew":0.0,"views":4,"x":0.5,"y":1.0}],"frames":100,"frames_seen":80,"frames_seen_by_every_camera":80,"gyro_rms_dps":[40.0,35.5,20.25]},"lines":["Rotation RMS"],"progress":0.5,"step":"motion","t":400.0,"type":"live"})j",
                  R"j({"devices":{"cameras":[],"imu":{"error":"","faults":0,"gyro_offsets":"off","rate_hz":200.0,"samples":4000,"sim":true,"state":"open"},"storage":"file x.bin"},"elapsed_s":1.5,"live_view":{"token_file":"/var/lib/imucal/live-view.token","url":"http://127.0.0.1:8421/"},"poses":0,"recorded_bytes":0,"rig":"sim","session_dir":"","state":"idle","step":"","steps":[],"type":"status","version":"1.2.3"})j",
                  R"j({"lines":["Still: 0.1 of 10 s"],"progress":0.014720934500000001,"step":"still","t":116.9,"type":"live"})j",
                  R"j({"level":"info","t":116.748123754,"text":"Warm: 34.77 C, changing 0.13 C/min","type":"message"})j",
                  R"j({"level":"warning","t":120.0,"text":"Too close to pose 1","type":"message"})j",
                  R"j({"advice":"What was recorded is kept. Fix the cam0 and press r to redo the step, or a to abort","source":"cam0","step":"motion","t":410.0,"text":"disconnected","type":"fault"})j",
                  R"j({"report":{"devices":[{"detail":"MPU-6000","name":"imu","ok":true}],"rig":"sim","stored":null,"stored_unreadable":"no key imu"},"t":100.25,"type":"preflight"})j",
                  R"j({"key":"continue","t":101.66690970500001,"type":"key"})j",
                  R"j({"reason":"SIGTERM","t":5.0,"type":"stop"})j",
                  R"j({"final":false,"id":1,"samples":10632,"t":170.71766624900002,"type":"solve"})j",
                  R"j({"camimu":true,"final":true,"id":12,"samples":19045,"t":213.4,"thermal_means":0,"type":"solve"})j",
                  R"j({"error":"","id":12,"t":214.0,"type":"applied","wall_s":0.75})j",
                  R"j({"files":["a/imu-static.yaml"],"imu":{"A_a":[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]],"A_g":[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]],"G":[[0.0,0.0,0.0],[0.0,0.0,0.0],[0.0,0.0,0.0]],"b_a":[0.1,0.2,0.3],"b_g":[-0.1,-0.2,-0.3]},"t":213.4,"type":"result"})j",
                  R"j({"cameras":[{"name":"cam0","q_cam_imu_wxyz":[1.0,0.0,0.0,0.0],"reprojection_rms_px":0.25,"t_cam_imu_m":[0.01,0.02,0.03],"timeshift_cam_imu_s":0.004}],"files":[],"self_check":{"advice":"","summary":"agree","verdict":"agree"},"t":1.0,"thermal":{"determined":true,"reference_c":35.0,"valid_range_c":[30.0,40.0]},"type":"result"})j",
                  R"j({"files":[],"t":1.0,"thermal":{"determined":false,"reason":"span too small"},"type":"result"})j",
                  R"j({"error":"","ok":true,"t":214.2,"type":"written","where":"slot B, sequence 4"})j",
                  R"j({"error":"no space","ok":false,"t":214.2,"type":"written"})j",
                  R"j({"index":1,"t":131.458790131,"type":"pose","up":[0.6931851421610691,-0.48751084786920024,0.5308743089442094]})j",
                  R"j({"face":"+X","t":140.0,"type":"face","up":[0.99,0.01,0.0]})j",
                  R"j({"difference_to_stored":null,"files":["f"],"gates":[{"digits":4,"limit":0.05,"name":"gravity residual RMS (m/s^2)","pass":true,"value":0.00102898324260714},{"limit":0.0,"name":"cam0 extrinsics without a sigma","pass":false,"value":null}],"lines":["Accel bias: 0.1"],"pass":false,"t":213.4,"type":"review"})j",
                  R"j({"difference_to_stored":{"b_a":[0.1,0.0,0.0],"b_g":[0.0,0.2,0.0],"scale_a":[0.001,0.0,0.0],"scale_g":[0.0,0.0,0.002]},"files":[],"gates":[],"lines":[],"pass":true,"t":213.4,"type":"review"})j",
                  R"j({"outcome":"written","reports":["a/report.html"],"session_dir":"a","stored":"slot B","t":214.2,"text":"The calibration was written, read back and verified.","type":"done"})j",
                  R"j({"outcome":"aborted","t":3.0,"text":"Aborted by the operator.","type":"done"})j",
              };
  return lines;
}

TEST(SessionMessages, EveryKindEncodesBackToTheSameJson) {
  std::vector<std::string> types;
  for (const std::string& line : wire_lines()) {
    auto message = parse(line);
    ASSERT_TRUE(message.ok()) << line << ": " << message.error().message;
    EXPECT_EQ(dump(*message), line);
    types.emplace_back(type_name(*message));
  }
  // Every alternative of the variant is among the lines.
  for (const char* type :
       {"session", "status", "prompt", "live", "message", "fault", "preflight", "key", "stop", "solve",
        "applied", "result", "written", "pose", "face", "review", "done"}) {
    EXPECT_NE(std::find(types.begin(), types.end(), type), types.end()) << type;
  }
  EXPECT_EQ(std::variant_size_v<SessionMessage>, 17u);
}

TEST(SessionMessages, DecodedFieldsAreTyped) {
  auto prompt = parse(wire_lines()[6]);
  ASSERT_TRUE(prompt.ok());
  const auto& p = std::get<Prompt>(*prompt);
  EXPECT_EQ(p.step, StepId::kPoses);
  EXPECT_EQ(p.keys,
            (std::vector<OperatorKey>{OperatorKey::kContinue, OperatorKey::kRedo, OperatorKey::kAbort}));
  EXPECT_TRUE(p.offers(OperatorKey::kRedo));
  EXPECT_FALSE(p.offers(OperatorKey::kSkip));
  ASSERT_TRUE(p.up.has_value());
  EXPECT_EQ(*p.up, Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(p.t, 126.75);

  // The service's devices: their states are values of one table.
  auto with_devices = parse(wire_lines()[4]);
  ASSERT_TRUE(with_devices.ok());
  const auto& service = std::get<Status>(*with_devices).service;
  ASSERT_TRUE(service.has_value());
  EXPECT_EQ(service->devices.imu.state, DeviceState::kOpen);
  ASSERT_EQ(service->devices.cameras.size(), 1u);
  EXPECT_EQ(service->devices.cameras[0].state, DeviceState::kClosed);
  EXPECT_EQ(service->recorded_bytes, 48312345);

  auto live = parse(wire_lines()[11]);
  ASSERT_TRUE(live.ok());
  const auto& figures = std::get<PoseFigures>(std::get<Live>(*live).figures);
  EXPECT_TRUE(std::isnan(figures.scale_sigma));
  EXPECT_EQ(figures.missing, (std::vector<std::string>{"+X", "-X"}));
  EXPECT_EQ(figures.poses_needed, 0u);  // not said in a log from before it: 0, and not written back

  // Said: it goes through the wire and back.
  Live with_needed;
  with_needed.step = StepId::kPoses;
  with_needed.figures = PoseFigures{7, true, {}, 0.5, 12};
  auto back = parse(encode(SessionMessage(with_needed)).dump());
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(std::get<PoseFigures>(std::get<Live>(*back).figures).poses_needed, 12u);

  auto status = parse(wire_lines()[3]);
  ASSERT_TRUE(status.ok());
  EXPECT_FALSE(std::get<Status>(*status).t.has_value());
  EXPECT_FALSE(std::get<Status>(*status).step.has_value());
  EXPECT_EQ(std::get<Status>(*status).state, SessionState::kIdle);

  auto done = parse(wire_lines().back());
  ASSERT_TRUE(done.ok());
  EXPECT_EQ(std::get<Done>(*done).outcome, Outcome::kAborted);
}

// The stored record reaches the engine typed: the wire carries its JSON form and summary, and a
// record that does not read is said, not dropped.
TEST(SessionMessages, ThePreflightCarriesTheStoredRecordTyped) {
  PreflightReport report;
  report.rig = "sim";
  CalibrationRecord record;
  record.created_utc = "2026-12-04T15:00:00Z";
  record.imu.stream = "imu0";
  record.imu.input_units = "raw";
  record.imu.model.b_a = Eigen::Vector3d(-359.02, 84.8, -86.05);
  record.gravity_mps2 = 9.80665;
  report.stored = PreflightReport::Stored{record, "sequence 4 in slot B"};
  auto back = parse(encode(SessionMessage(Preflight{100.25, report})).dump());
  ASSERT_TRUE(back.ok()) << back.error().message;
  const PreflightReport& got = std::get<Preflight>(*back).report;
  ASSERT_TRUE(got.stored.has_value());
  EXPECT_EQ(got.stored->summary, "sequence 4 in slot B");
  EXPECT_EQ(got.stored->record.imu.model.b_a, record.imu.model.b_a);
  EXPECT_EQ(calibration_record_json(got.stored->record), calibration_record_json(record));
  EXPECT_TRUE(got.stored_unreadable.empty());

  // A record that does not read: no record, and why.
  auto bad = parse(
      R"j({"report":{"devices":[],"rig":"sim","stored":{"imu":{"b_a":[1,2,3]},"summary":"s"}},"t":1.0,"type":"preflight"})j");
  ASSERT_TRUE(bad.ok()) << bad.error().message;
  const PreflightReport& unread = std::get<Preflight>(*bad).report;
  EXPECT_FALSE(unread.stored.has_value());
  EXPECT_FALSE(unread.stored_unreadable.empty());
}

TEST(SessionMessages, TheOperatorKeysHaveOneTable) {
  EXPECT_EQ(key_list(), "continue, redo, abort, accept, reject, skip");
  for (OperatorKey k : all_keys()) {
    auto back = parse_key(key_name(k));
    ASSERT_TRUE(back.ok());
    EXPECT_EQ(*back, k);
    EXPECT_EQ(key_of_letter(key_letter(k)), k);  // the console reads its letters from the same table
  }
  EXPECT_EQ(key_of_letter('q'), std::nullopt);
  EXPECT_EQ(key_letter(OperatorKey::kAccept), 'y');
  EXPECT_EQ(key_letter(OperatorKey::kReject), 'n');
  auto bad = parse_key("pause");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("continue, redo, abort, accept, reject, skip"), std::string::npos);
  for (StepId s : all_steps()) EXPECT_EQ(*parse_step(step_name(s)), s);
}

void expect_error(const std::string& line, const std::string& words) {
  auto message = parse(line);
  ASSERT_FALSE(message.ok()) << line;
  EXPECT_EQ(message.error().code, Errc::kCorrupt);
  EXPECT_NE(message.error().message.find(words), std::string::npos) << message.error().message;
}

TEST(SessionMessages, DamagedOrForeignMessagesGiveErrorsNotCrashes) {
  expect_error("not json", "not valid JSON");
  expect_error("[1,2]", "not a JSON object");
  expect_error(R"j({"text":"x"})j", "has no type");
  expect_error(R"j({"type":7})j", "has no type");
  // A newer service's message kind.
  expect_error(R"j({"type":"weather","t":1.0})j", "\"weather\", which this version does not know");
  // An older one without a field this version needs.
  expect_error(R"j({"type":"key","t":1.0})j", "(key) has no \"key\"");
  expect_error(R"j({"type":"prompt","step":"poses","keys":["continue"]})j", "(prompt) has no \"text\"");
  expect_error(R"j({"type":"done","text":"x"})j", "(done) has no \"outcome\"");
  expect_error(R"j({"type":"applied","error":""})j", "(applied) has no \"id\"");
  // Wrong kinds and names outside their tables.
  expect_error(R"j({"type":"live","step":"still","lines":[1,"ok"],"progress":0.5})j",
               "\"lines\" that is not a string");
  expect_error(R"j({"type":"live","step":"still","lines":[],"progress":"half"})j", "\"progress\" is string");
  expect_error(R"j({"type":"prompt","step":"poses","text":"x","keys":["pause"]})j", "'pause' is not a key");
  expect_error(R"j({"type":"prompt","step":"dance","text":"x","keys":[]})j", "'dance' is not a session step");
  expect_error(R"j({"type":"status","state":"sleeping"})j", "'sleeping' is not a session state");
  expect_error(
      R"j({"type":"status","state":"idle","devices":{"imu":{"state":"opened","sim":false,"samples":0,"faults":0,"rate_hz":0,"gyro_offsets":"","error":""},"storage":"x"}})j",
      "'opened' is not a device state");
  expect_error(R"j({"type":"review","pass":"yes"})j", "\"pass\" is string");
  expect_error(R"j({"type":"review","pass":true,"gates":[{"pass":1}]})j", "a gate has no \"name\"");
  expect_error(R"j({"type":"pose","index":1,"up":[1,2]})j", "\"up\" that is not 3 numbers");
  expect_error(R"j({"type":"result","imu":{"A_a":[[1,0,0],[0,1,0]]}})j", "\"A_a\" that is not 3x3");
  expect_error(R"j({"type":"live","step":"poses","lines":[],"figures":{"poses":-1}})j", "negative \"poses\"");
}

TEST(SessionMessages, FieldsAddedOverTimeAreOptional) {
  // A gate without "digits" and a write without "where", as older services wrote them.
  auto review =
      parse(R"j({"type":"review","pass":true,"gates":[{"name":"g","value":1.0,"limit":2.0,"pass":true}]})j");
  ASSERT_TRUE(review.ok()) << review.error().message;
  EXPECT_FALSE(std::get<Review>(*review).gates.at(0).digits.has_value());
  auto written = parse(R"j({"type":"written","ok":true,"error":""})j");
  ASSERT_TRUE(written.ok()) << written.error().message;
  EXPECT_FALSE(std::get<Written>(*written).where.has_value());
  // Fields a newer version adds are ignored.
  auto key = parse(R"j({"type":"key","key":"skip","by":"imucalctl"})j");
  ASSERT_TRUE(key.ok());
  EXPECT_EQ(std::get<Key>(*key).key, OperatorKey::kSkip);
}

TEST(SessionMessages, FrameEventsRoundTrip) {
  const FrameEvent e{1, 1234567890123, true};
  EXPECT_EQ(dump(e), R"j({"camera":1,"seen":true,"t_ns":1234567890123})j");
  auto back = parse_frame_event(dump(e));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->camera, 1u);
  EXPECT_EQ(back->t_ns, 1234567890123);
  EXPECT_TRUE(back->seen);
  auto bad = parse_frame_event(R"j({"camera":0,"seen":true})j");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("has no \"t_ns\""), std::string::npos);
}

}  // namespace
TEST(SessionMessages, ACoverageWhoseCellsAreNotItsGridIsRefused) {
  const auto m = decode(nlohmann::json::parse(
      R"j({"figures":{"camera_frames":[1],"camera_frames_seen":[1],"coverage":[{"cells":[1,2,3],"cols":2,"rows":2,"size":0.0,"skew":0.0,"views":1,"x":0.0,"y":0.0}],"frames":1,"frames_seen":1,"frames_seen_by_every_camera":1,"gyro_rms_dps":[1.0,1.0,1.0]},"lines":[],"progress":0.5,"step":"motion","type":"live"})j"));
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().message.find("3 cells, not cols x rows"), std::string::npos) << m.error().message;
  const auto ok = decode(nlohmann::json::parse(
      R"j({"figures":{"camera_frames":[1],"camera_frames_seen":[1],"coverage":[{"cells":[1,2,3,4],"cols":2,"rows":2,"size":0.1,"skew":0.2,"views":1,"x":0.3,"y":0.4}],"frames":1,"frames_seen":1,"frames_seen_by_every_camera":1,"gyro_rms_dps":[1.0,1.0,1.0]},"lines":[],"progress":0.5,"step":"motion","type":"live"})j"));
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  const auto& f = std::get<MotionFigures>(std::get<Live>(*ok).figures);
  ASSERT_EQ(f.coverage.size(), 1u);
  EXPECT_EQ(f.coverage[0].cells[3], 4);
  EXPECT_DOUBLE_EQ(f.coverage[0].y, 0.4);
}

}  // namespace imucal::session_msg
