// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// `imucal replay LOG`: runs a recorded session's logic again from its session log, with no
// devices. The samples are fed to a new engine (session_engine.hpp) and the operator's keys,
// the faults, the solve results and the write's outcome are applied at the sample times the log
// recorded them at, so the engine takes the same decisions; the solves run again on the same
// samples. The result is compared with the one the live session logged.
#include <optional>
#include <string>
#include <vector>

#include "app/session/session_engine.hpp"
#include "core/result.hpp"

namespace imucal::app::session {

struct ReplayOptions {
  std::string log_path;
  /// The replay's result files go here (created if missing); empty: a temporary folder.
  std::string out_dir;
  bool report = false;
};

struct ReplaySummary {
  SessionState state = SessionState::kIdle;
  std::string outcome;       // of the replayed session (written, rejected, aborted, ...)
  std::string live_outcome;  // as logged
  std::size_t samples = 0;
  int keys = 0, faults = 0, solves = 0;
  std::optional<StaticCalibrationResult> imu;
  bool live_result = false;     // the log holds the live session's result
  double max_difference = 0.0;  // largest |replayed - live| over the canonical model's entries
  std::vector<std::string> result_files;
  /// The live session's steps as logged: rig (sample) time from each step's start to the next's.
  struct StepTime {
    std::string step;
    double rig_s = 0.0;
  };
  std::vector<StepTime> step_times;
  double live_final_solve_wall_s = 0.0;  // wall time of the live session's final solve, as logged
  std::vector<std::string> notes;
};

/// Errors: the log's (kNotFound, kCorrupt), kInsufficientData for a log that is not a service
/// session (no session events), kInternal when the replay diverges from the log (a solve the
/// log applied was never requested).
[[nodiscard]] Result<ReplaySummary> replay_session(const ReplayOptions& options);

}  // namespace imucal::app::session
