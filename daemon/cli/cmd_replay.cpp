// SPDX-License-Identifier: BSD-3-Clause
// imucal replay LOG: runs a whole service session's logic again from its session log, with no
// devices, and compares the result with the one the live session reached (docs/service-session.md).

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "app/session/option_words.hpp"
#include "app/session/session_replay.hpp"
#include "daemon/cli/command.hpp"

namespace imucal::cli {
namespace {

struct ReplayArgs {
  app::session::ReplayOptions options;
  double tolerance = 1e-9;
  bool json = false;
};

void run(const ReplayArgs& a) {
  // The replayed session says what the live one said, in the session's words.
  set_option_vocabulary(&app::session::session_option_words);
  auto summary = app::session::replay_session(a.options);
  if (!summary.ok()) fail(summary.error(), "replay of " + a.options.log_path);
  const auto& s = *summary;
  const bool same_outcome = s.outcome == s.live_outcome;
  const bool same_result = !s.live_result || s.max_difference <= a.tolerance;
  if (a.json) {
    nlohmann::json j = {{"log", a.options.log_path},
                        {"samples", s.samples},
                        {"keys", s.keys},
                        {"faults", s.faults},
                        {"solves", s.solves},
                        {"outcome", s.outcome},
                        {"live_outcome", s.live_outcome},
                        {"live_result", s.live_result},
                        {"max_difference", std::isfinite(s.max_difference) ? nlohmann::json(s.max_difference)
                                                                           : nlohmann::json("inf")},
                        {"result_files", s.result_files},
                        {"notes", s.notes},
                        {"same", same_outcome && same_result},
                        {"live_final_solve_wall_s", s.live_final_solve_wall_s}};
    nlohmann::json steps = nlohmann::json::array();
    for (const auto& st : s.step_times) steps.push_back({{"step", st.step}, {"rig_s", st.rig_s}});
    j["live_step_times"] = steps;
    std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    std::printf("replayed %s: %zu samples, %d keys, %d faults, %d solves applied\n",
                a.options.log_path.c_str(), s.samples, s.keys, s.faults, s.solves);
    std::printf("outcome: %s (live session: %s)\n", s.outcome.empty() ? "none" : s.outcome.c_str(),
                s.live_outcome.empty() ? "none logged" : s.live_outcome.c_str());
    if (s.live_result) {
      std::printf("result: largest difference to the live session's %.3g (tolerance %.3g)\n",
                  s.max_difference, a.tolerance);
    } else {
      std::printf("result: the live session logged none to compare with\n");
    }
    if (!s.step_times.empty()) {
      std::printf("live session, rig time per step:");
      for (const auto& st : s.step_times) std::printf(" %s %.1f s", st.step.c_str(), st.rig_s);
      std::printf("; final solve %.2f s of wall time\n", s.live_final_solve_wall_s);
    }
    for (const auto& f : s.result_files) std::printf("  wrote %s\n", f.c_str());
    for (const auto& n : s.notes) std::printf("  note: %s\n", n.c_str());
  }
  if (!same_outcome || !same_result) {
    const auto named = [](const std::string& outcome, const char* none) {
      return outcome.empty() ? std::string(none) : outcome;
    };
    throw CliExit{
        kExitSolver,
        "replay: the replayed session differs from the live one (outcome " +
            named(s.outcome, "none: the replay did not reach the end") + " vs " +
            named(s.live_outcome, "none logged: the live session was killed or stopped before its end") +
            (same_result ? std::string() : "; the results differ") + ")"};
  }
}

void setup(CLI::App& root) {
  CLI::App* cmd = root.add_subcommand(
      "replay", "Run a recorded service session again from its log, with no devices, and compare the result");
  auto a = std::make_shared<ReplayArgs>();
  cmd->add_option("LOG", a->options.log_path, "A session log written by imucald (sessions/*/session.imulog)")
      ->required();
  cmd->add_option("-o,--output", a->options.out_dir,
                  "Folder for the replay's result files (default: a new temporary folder)");
  cmd->add_option("--tolerance", a->tolerance,
                  "Largest difference to the live result accepted, per canonical model entry (default 1e-9)")
      ->check(kNonNegative);
  cmd->add_flag("--json", a->json, "Print the summary as JSON");
  cmd->callback([a] { run(*a); });
}

const CommandRegistrar registrar(85, setup);

}  // namespace
}  // namespace imucal::cli
