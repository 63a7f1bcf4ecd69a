// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// A ROS 1 bag where a command takes a session log: imported once into the user's cache and read
// from there (docs/datasets.md, "ROS 1 bags").

#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace imucal::cli {

/// The cache folder of the session logs imported from bags: $IMUCAL_CACHE_DIR, else
/// $XDG_CACHE_HOME/imucal, else $HOME/.cache/imucal, with "/bags"; empty when none is set.
std::string bag_cache_dir();

/// The session log a command reads for its LOG argument: `path` itself, or, when `path` is a ROS 1
/// bag or a ROS 2 bag (a rosbag2 folder, .db3 or .mcap file), the log it is imported into (`topics` as
/// `imucal import bag --topics`, every Imu and image topic when empty). The import is kept in bag_cache_dir()
/// under a name made of the bag's path, size, modification time and the topics, and reused while the bag is
/// unchanged; without a cache folder, or with `use_cache` false (--no-cache), it goes into a temporary folder
/// removed when the program ends. What the import says is printed on stderr. A bag that does not import ends
/// the program with its exit code.
std::string log_of_input(const std::string& path, const std::vector<std::string>& topics,
                         bool use_cache = true);

/// `--topics` for a command that takes a log: the topics to import when the log is a ROS bag.
void add_bag_topics_option(CLI::App* cmd, std::vector<std::string>* topics);

/// `options` with its log_path the log to read (log_of_input of log_path and topics), for the
/// work after a command has checked its outputs against its inputs as given (the bag itself).
template <class Options>
Options with_log_of_input(const Options& options) {
  Options out = options;
  bool use_cache = true;
  if constexpr (requires { options.detections.no_cache; }) use_cache = !options.detections.no_cache;
  out.log_path = log_of_input(options.log_path, options.topics, use_cache);
  return out;
}

}  // namespace imucal::cli
