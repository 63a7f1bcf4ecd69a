#include "app/session/session_runner.hpp"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>

#include "app/report/report.hpp"
#include "app/result_writers.hpp"
#include "app/solvers.hpp"
#include "core/version.hpp"
#include "log/session_log.hpp"

namespace imucal::app::session {

using nlohmann::json;

namespace {

/// <rig>-YYYYmmddTHHMMSSZ, with -2, -3, ... when it exists already.
Result<std::string> make_session_dir(const std::string& state_dir, const std::string& rig) {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &tm);
  const std::filesystem::path base = std::filesystem::path(state_dir) / "sessions";
  std::error_code ec;
  std::filesystem::create_directories(base, ec);
  if (ec) {
    return make_error(Errc::kIo, "cannot create " + base.string() + ": " + ec.message() +
                                     " (check --state-dir and that the service may write there)");
  }
  for (int n = 1; n < 1000; ++n) {
    std::string name = rig + "-" + stamp + (n > 1 ? "-" + std::to_string(n) : "");
    const auto dir = base / name;
    if (std::filesystem::create_directory(dir, ec)) return dir.string();
    if (ec) return make_error(Errc::kIo, "cannot create " + dir.string() + ": " + ec.message());
  }
  return make_error(Errc::kAlreadyExists,
                    "too many sessions named " + rig + "-" + stamp + " in " + base.string());
}

}  // namespace

static SolveOutcome run_solve_timed(const SolveJob& job, const ImuStreamInfo& info, const std::string& dir,
                                    const std::function<void(double, const std::string&)>& progress);

SolveOutcome run_solve(const SolveJob& job, const ImuStreamInfo& info, const std::string& dir,
                       const std::function<void(double, const std::string&)>& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  SolveOutcome out = run_solve_timed(job, info, dir, progress);
  out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

static SolveOutcome run_solve_timed(const SolveJob& job, const ImuStreamInfo& info, const std::string& dir,
                                    const std::function<void(double, const std::string&)>& progress) {
  SolveOutcome out;
  if (progress) progress(0.0, "Static calibration of " + std::to_string(job.samples->size()) + " samples");
  auto result = app::calibrate_static(*job.samples, job.static_options);
  if (!result.ok()) {
    out.error = result.error().message;
    return out;
  }
  out.imu = std::move(*result);
  if (!job.final) return out;
  if (job.camimu) {
    out.error =
        "the camera-IMU solve is not run by the service; calibrate the session log with "
        "`imucal calibrate camimu`";
    return out;
  }
  if (progress) progress(0.9, "Writing the results");
  const std::string yaml_path = dir + "/imu-static.yaml", json_path = dir + "/imu-static.json";
  const std::map<std::string, std::string> meta = {{"software_version", kVersion}};
  Status s = write_text_file(yaml_path, static_result_yaml(*out.imu, info));
  if (s.ok()) s = write_text_file(json_path, static_result_json(*out.imu, info, "standard gravity", meta));
  if (!s.ok()) {
    out.error = "writing the results: " + s.error().message;
    return out;
  }
  out.result_files = {yaml_path, json_path};
  return out;
}

SessionRunner::SessionRunner(const RigConfig& config, const ImuStreamInfo& info, RunnerOptions options)
    : config_(config), info_(info), options_(std::move(options)), engine_(config, info, *this) {
  worker_ = std::thread([this] { worker_loop(); });
}

SessionRunner::~SessionRunner() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
  close_log();
}

void SessionRunner::worker_loop() {
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // stopping with nothing left
      job = std::move(jobs_.front());
      jobs_.pop_front();
      running_job_ = true;
    }
    job();
    {
      std::lock_guard lock(mutex_);
      running_job_ = false;
    }
    cv_.notify_all();
  }
}

void SessionRunner::run_on_worker(std::function<void()> work) {
  if (!options_.post) {
    work();
    return;
  }
  {
    std::lock_guard lock(mutex_);
    jobs_.push_back(std::move(work));
  }
  cv_.notify_all();
}

void SessionRunner::drain() {
  std::unique_lock lock(mutex_);
  cv_.wait(lock, [this] { return jobs_.empty() && !running_job_; });
}

bool SessionRunner::busy() {
  std::lock_guard lock(mutex_);
  return running_job_ || !jobs_.empty();
}

Status SessionRunner::start(const std::vector<std::string>& steps) {
  if (engine_.running()) return make_error(Errc::kAlreadyExists, "a session is running; abort it first");
  close_log();
  if (!options_.session_dir.empty()) {
    dir_ = options_.session_dir;
  } else {
    auto dir = make_session_dir(options_.state_dir, config_.name);
    if (!dir.ok()) return dir.error();
    dir_ = *dir;
  }
  if (options_.write_log) {
    auto writer = log::SessionLogWriter::create(log_path());
    if (!writer.ok()) return writer.error().context("creating the session log");
    log_ = std::move(*writer);
    for (const auto& [k, v] : options_.metadata) IMUCAL_TRY(log_->set_metadata(k, v));
    IMUCAL_TRY(log_->set_metadata("session", json{{"steps", steps}}.dump()));
    auto id = log_->add_imu_stream(info_);
    if (!id.ok()) return id.error().context("declaring the IMU stream");
    stream_id_ = *id;
  }
  recording_ = true;
  if (auto s = engine_.start(steps); !s.ok()) {
    close_log();
    return s;
  }
  return {};
}

void SessionRunner::on_samples(std::span<const ImuSample> samples) {
  for (const auto& s : samples) {
    if (recording_ && log_ && engine_.running()) {
      if (auto st = log_->append_imu(stream_id_, s); !st.ok()) {
        // The log is the session's record: without it nothing that follows could be replayed.
        recording_ = false;
        engine_.fault("log", st.error().message);
      }
    }
    engine_.on_sample(s);
  }
}

void SessionRunner::fault(const std::string& source, const std::string& text) { engine_.fault(source, text); }

void SessionRunner::emit(const json& message) {
  if (log_) {
    if (auto s = log_->append_event({engine_.now_ns(), "session", message.dump()}); !s.ok())
      warn("session log: " + s.error().message);
  }
  if (options_.broadcast) options_.broadcast(message);
  const std::string type = message.value("type", "");
  if (type == "done") {
    if (log_) (void)log_->flush();
    close_log();
  }
}

PreflightReport SessionRunner::preflight() {
  PreflightReport report;
  if (options_.preflight) report = options_.preflight();
  report.rig = config_.name;
  return report;
}

void SessionRunner::solve(const SolveJob& job) {
  const std::string dir = dir_;
  const ImuStreamInfo info = info_;
  const bool report = options_.report;
  auto make_payload = options_.make_payload;
  const std::string log = log_path();
  run_on_worker([this, job, dir, info, report, make_payload, log] {
    auto progress = [this](double f, const std::string& text) {
      if (options_.post) {
        options_.post([this, f, text] { engine_.solve_progress(f, text); });
      } else {
        engine_.solve_progress(f, text);
      }
    };
    SolveOutcome out = run_solve(
        job, info, dir, job.final ? std::function<void(double, const std::string&)>(progress) : nullptr);
    if (job.final && out.error.empty()) {
      if (make_payload) {
        auto payload = make_payload(out.result_files);
        if (payload.ok()) {
          out.payload = std::move(*payload);
        } else {
          out.error = "building the record: " + payload.error().message;
        }
      }
      if (report && out.error.empty()) {
        report::ReportOptions ro;
        ro.result_path = dir + "/imu-static.json";
        ro.log_path = options_.write_log ? log : std::string();
        ro.html_path = dir + "/report.html";
        ro.overwrite = true;
        ro.generator = std::string("imucal ") + kVersion;
        if (auto r = report::write_report(ro); r.ok()) {
          out.result_files.push_back(ro.html_path);
        } else {
          warn("the session report was not written: " + r.error().message);
        }
      }
    }
    auto apply = [this, id = job.id, out = std::move(out)]() mutable {
      engine_.solve_finished(id, std::move(out));
    };
    if (options_.post) {
      options_.post(std::move(apply));
    } else {
      apply();
    }
  });
}

void SessionRunner::write(const json& payload) {
  auto writer = options_.write_storage;
  run_on_worker([this, payload, writer] {
    Status status = writer ? writer(payload)
                           : Status(make_error(Errc::kUnsupported, "this host has no storage to write to"));
    auto apply = [this, status] { engine_.write_finished(status); };
    if (options_.post) {
      options_.post(apply);
    } else {
      apply();
    }
  });
}

void SessionRunner::warn(const std::string& text) const {
  if (options_.warn) {
    options_.warn(text);
  } else {
    std::fprintf(stderr, "%s\n", text.c_str());
  }
}

Status SessionRunner::recover() { return options_.recover ? options_.recover() : Status{}; }

void SessionRunner::recording_finished() {
  recording_ = false;
  if (log_) (void)log_->flush();
}

void SessionRunner::close_log() {
  if (!log_) return;
  if (auto s = log_->close(); !s.ok()) warn("closing the session log: " + s.error().message);
  log_.reset();
}

}  // namespace imucal::app::session
