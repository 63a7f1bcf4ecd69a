// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/cli/bag_input.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>

#include "daemon/cli/calibrate_group.hpp"
#include "daemon/cli/command.hpp"
#include "log/dataset_io.hpp"
#include "log/rosbag2.hpp"
#include "log/session_log.hpp"

namespace imucal::cli {
namespace {

namespace fs = std::filesystem;

/// A ROS 1 bag (by its magic) or a rosbag2 (a folder with metadata.yaml, an .mcap or a .db3).
bool is_bag(const std::string& path) {
  std::error_code ec;
  // Only files and folders are looked into: opening a FIFO would wait for a writer (the command's
  // own reading refuses what is neither).
  if (!fs::is_regular_file(path, ec) && !fs::is_directory(path, ec)) return false;
  std::ifstream in(path, std::ios::binary);
  char head[9] = {};
  if (in.read(head, sizeof head) && std::string(head, sizeof head) == "#ROSBAG V") return true;
  return log::rosbag2::is_rosbag2(path);
}

/// A temporary folder removed at exit, for imports without a cache folder.
class TempFolder {
 public:
  const std::string& path() {
    if (path_.empty()) {
      std::string tmpl = (fs::temp_directory_path() / "imucal-bag-XXXXXX").string();
      if (::mkdtemp(tmpl.data()) == nullptr)
        throw CliExit{kExitIo, "cannot make a temporary folder for a bag's import"};
      path_ = tmpl;
    }
    return path_;
  }
  ~TempFolder() {
    std::error_code ec;
    if (!path_.empty()) fs::remove_all(path_, ec);
  }

 private:
  std::string path_;
};

/// Whether `path` is a log an earlier import closed.
bool complete_log(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return false;
  auto r = log::SessionLogReader::open(path);
  return r.ok() && (*r)->health().complete && !(*r)->health().damaged;
}

}  // namespace

std::string bag_cache_dir() {
  const std::string base = user_cache_dir();
  return base.empty() ? std::string() : base + "/bags";
}

std::string log_of_input(const std::string& path, const std::vector<std::string>& topics, bool use_cache) {
  if (!is_bag(path)) return path;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return path;  // the command's own reading says why
  std::error_code ec;
  std::string key = fs::absolute(path, ec).string() + "\n" + std::to_string(st.st_size) + "\n" +
                    std::to_string(st.st_mtim.tv_sec) + "." + std::to_string(st.st_mtim.tv_nsec);
  if (fs::is_directory(path, ec)) {  // a rosbag2 folder: its files' sizes and times too, by name
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(path, ec)) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      struct stat fst {};
      if (::stat(f.c_str(), &fst) == 0) {
        key += "\n" + f.filename().string() + " " + std::to_string(fst.st_size) + " " +
               std::to_string(fst.st_mtim.tv_sec) + "." + std::to_string(fst.st_mtim.tv_nsec);
      }
    }
  }
  for (const auto& t : topics) key += "\n" + t;
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(std::hash<std::string>{}(key)));
  static TempFolder temp;
  std::string folder = use_cache ? bag_cache_dir() : std::string();
  if (!folder.empty()) {
    fs::create_directories(folder, ec);
    if (ec) folder.clear();
  }
  if (folder.empty()) folder = temp.path();
  const std::string log = folder + "/" + fs::path(path).stem().string() + "-" + hex + ".imulog";
  if (complete_log(log)) {
    std::cerr << "imucal: " << path << " is a ROS bag; reading the log imported from it before: " << log
              << "\n";
    return log;
  }
  log::BagImport in;
  in.path = path;
  in.topics = topics;
  Progress progress("importing " + fs::path(path).filename().string(), 1.0);
  log::OutputOptions options;
  options.force = true;  // a stale or partial import of this key
  options.progress = [&progress](double f) { progress.update(f); };
  auto summary = log::import_bag(in, log, options);
  progress.finish();
  if (!summary.ok()) {
    Error e = summary.error();
    e.remedies.clear();  // the import's own options are imucal import bag's
    if (e.code == Errc::kCorrupt && e.message.find("is damaged") != std::string::npos)
      e.message += " (imucal import bag --allow-damaged imports them into a log to give here)";
    fail(e, "importing the ROS bag " + path);
  }
  std::cerr << "imucal: " << path << " is a ROS bag: imported " << summary->imu_samples << " IMU samples and "
            << summary->frames << " frames into " << log << "\n";
  for (const auto& note : summary->notes) std::cerr << "imucal: note: " << note << "\n";
  return log;
}

void add_bag_topics_option(CLI::App* cmd, std::vector<std::string>* topics) {
  cmd->add_option("--topics", *topics,
                  "When the log is a ROS bag: the topics to import, in stream order (imucal import bag "
                  "--topics; default every Imu, Image and CompressedImage topic)")
      ->expected(1, -1);
}

}  // namespace imucal::cli
