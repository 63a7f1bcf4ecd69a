#include "app/results/output.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "log/dataset_io.hpp"

namespace imucal::app {

Status check_output(const std::string& path, const OutputPolicy& policy) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (const auto& input : policy.inputs) {
    if (fs::exists(path, ec) && fs::equivalent(path, input, ec)) {
      return make_error(Errc::kInvalidArgument,
                        path + " is an input of this command; write the result to another file");
    }
  }
  if (fs::is_directory(path, ec))
    return make_error(Errc::kInvalidArgument, path + " is a folder, not a file");
  IMUCAL_TRY(log::check_replaceable(path));
  if (!policy.overwrite && fs::exists(path, ec)) return make_error(Errc::kAlreadyExists, path + " exists");
  return {};
}

Status write_text_file(const std::string& path, const std::string& text, const OutputPolicy& policy) {
  IMUCAL_TRY(check_output(path, policy));
  const std::string temp = path + ".tmp-" + std::to_string(::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(errno) +
                                     " (check the folder exists and is writable)");
  }
  std::size_t done = 0;
  int err = 0;
  while (done < text.size()) {
    const ssize_t w = ::write(fd, text.data() + done, text.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) {
      err = errno;
      break;
    }
    done += static_cast<std::size_t>(w);
  }
  if (err == 0 && ::fsync(fd) != 0) err = errno;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0) {
    if (Status moved = log::rename_into_place(temp, path, policy.overwrite); !moved.ok()) {
      ::unlink(temp.c_str());
      return moved.error();
    }
  }
  if (err != 0) {
    ::unlink(temp.c_str());
    return make_error(Errc::kIo, "could not write " + path + ": " + std::strerror(err) +
                                     (err == ENOSPC ? " (the disk is full)" : "") + "; nothing was replaced");
  }
  return {};
}

}  // namespace imucal::app
