// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/storage/storage_device.hpp"

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <thread>

namespace imucal::drivers {
namespace {

std::string errno_text(int err) { return std::strerror(err); }

// A file descriptor on a regular file or a sysfs attribute, read and written with pread/pwrite.
class FdStorage final : public StorageDevice {
 public:
  FdStorage(int fd, std::uint64_t size, std::string name, std::size_t chunk, bool nvmem)
      : fd_(fd), size_(size), name_(std::move(name)), chunk_(chunk), nvmem_(nvmem) {}
  ~FdStorage() override { ::close(fd_); }
  FdStorage(const FdStorage&) = delete;
  FdStorage& operator=(const FdStorage&) = delete;

  std::uint64_t size() const override { return size_; }
  std::string name() const override { return name_; }

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) override {
    IMUCAL_TRY(check_range(name_, size_, offset, out.size()));
    std::size_t done = 0;
    while (done < out.size()) {
      const ssize_t r = ::pread(fd_, out.data() + done, std::min(chunk_, out.size() - done),
                                static_cast<off_t>(offset + done));
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return io_error("read", offset + done, errno);
      if (r == 0) {
        return make_error(Errc::kCorrupt, name_ + ": ends at byte " + std::to_string(offset + done) +
                                              ", before the " + std::to_string(size_) +
                                              " bytes it had when opened");
      }
      done += static_cast<std::size_t>(r);
    }
    return {};
  }

  Status write(std::uint64_t offset, std::span<const std::uint8_t> data) override {
    IMUCAL_TRY(check_range(name_, size_, offset, data.size()));
    std::size_t done = 0;
    while (done < data.size()) {
      const ssize_t r = ::pwrite(fd_, data.data() + done, std::min(chunk_, data.size() - done),
                                 static_cast<off_t>(offset + done));
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return io_error("write", offset + done, errno);
      if (r == 0)
        return make_error(Errc::kIo,
                          name_ + ": the device took no bytes at " + std::to_string(offset + done));
      done += static_cast<std::size_t>(r);
    }
    return {};
  }

  Status sync() override {
    if (::fsync(fd_) == 0) return {};
    // sysfs attributes have nothing to flush (at24 finished each write cycle in write()).
    if (nvmem_ && (errno == EINVAL || errno == EROFS)) return {};
    return io_error("fsync", 0, errno);
  }

 private:
  Error io_error(const char* what, std::uint64_t at, int err) const {
    std::string msg = name_ + ": " + what + " at byte " + std::to_string(at) + " failed: " + errno_text(err);
    if (nvmem_ && (err == EIO || err == ETIMEDOUT || err == ENXIO || err == EREMOTEIO)) {
      msg += " (the EEPROM did not answer: check its wiring and power, and its write-protect pin)";
      return make_error(Errc::kDevice, msg);
    }
    if (err == ENOSPC || err == EDQUOT) msg += " (the file system is full)";
    return make_error(nvmem_ ? Errc::kDevice : Errc::kIo, msg);
  }

  int fd_;
  std::uint64_t size_;
  std::string name_;
  std::size_t chunk_;
  bool nvmem_;
};

Error open_error(const std::string& what, const std::string& path, int err, bool device) {
  std::string msg = "cannot open " + what + " " + path + ": " + errno_text(err);
  // A path that cannot name a file (a loop of symbolic links, a file where a folder should be,
  // a name too long) is the configuration's to fix, like a FIFO there: not an I/O failure.
  if (!device && (err == ELOOP || err == ENOTDIR || err == ENAMETOOLONG))
    return make_error(Errc::kInvalidArgument, msg + ": fix storage.path");
  if (err == EACCES || err == EPERM || err == EROFS) {
    msg += ". Run as a user that may write it (see `ls -l " + path + "`)";
    msg += device ? "; nvmem files of at24 are root-only unless a udev rule changes their mode" : "";
    return make_error(device ? Errc::kDevice : Errc::kIo, msg);
  }
  return make_error(device ? Errc::kDevice : Errc::kIo, msg);
}

Status fsync_dir(const std::filesystem::path& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0)
    return make_error(Errc::kIo, "cannot open folder " + dir.string() + " to sync it: " + errno_text(errno));
  const int r = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (r != 0) return make_error(Errc::kIo, "cannot sync folder " + dir.string() + ": " + errno_text(err));
  return {};
}

// Creates `path` at `size` bytes of zeros, durable with its name. EEXIST (another process was
// quicker) is not an error: the caller opens what is there.
Status create_file(const std::string& path, std::uint64_t size) {
  const std::filesystem::path p(path);
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    if (errno == EEXIST) return {};
    if (errno == ENOENT) {
      return make_error(Errc::kNotFound, "cannot create " + path + ": the folder " +
                                             p.parent_path().string() +
                                             " does not exist; create it or set storage.path");
    }
    return open_error("calibration file", path, errno, false);
  }
  Status st;
  if (::ftruncate(fd, static_cast<off_t>(size)) != 0 || ::fsync(fd) != 0) {
    st = make_error(Errc::kIo,
                    "cannot create " + path + " at " + std::to_string(size) + " bytes: " + errno_text(errno));
  }
  ::close(fd);
  if (!st.ok()) {
    ::unlink(path.c_str());
    return st;
  }
  return fsync_dir(p.parent_path());
}

}  // namespace

Status check_range(const std::string& name, std::uint64_t size, std::uint64_t offset, std::uint64_t n) {
  if (offset > size || n > size - offset) {
    return make_error(Errc::kInvalidArgument, name + ": bytes " + std::to_string(offset) + ".." +
                                                  std::to_string(offset + n) + " lie outside its " +
                                                  std::to_string(size) + " bytes");
  }
  return {};
}

Result<std::unique_ptr<StorageDevice>> open_file_storage(const std::string& path, std::uint64_t min_size,
                                                         StorageAccess access) {
  if (path.empty()) return make_error(Errc::kInvalidArgument, "no storage file given; set storage.path");
  const bool write = access == StorageAccess::kWrite;
  if (write) IMUCAL_TRY(create_file(path, min_size));
  // O_NONBLOCK: opening a FIFO for reading would wait for a writer (store read, and imucald's
  // event loop, hung); a regular file ignores the flag.
  const int fd = ::open(path.c_str(), (write ? O_RDWR : O_RDONLY) | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) {
    if (errno == ENOENT) {
      return make_error(Errc::kNotFound, "no calibration file at " + path +
                                             ": nothing was stored yet (imucal store write creates it)");
    }
    return open_error("calibration file", path, errno, false);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return make_error(Errc::kInvalidArgument,
                      path +
                          " is not a regular file (a FIFO, device, socket or folder); storage.backend file "
                          "needs one: fix storage.path");
  }
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size < min_size) {
    ::close(fd);
    return make_error(
        Errc::kInvalidArgument,
        path + " is " + std::to_string(size) + " bytes, the configured region needs " +
            std::to_string(min_size) +
            " (storage.offset_bytes + storage.size_bytes): fix those keys, or move the file away "
            "so that a new one is created");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  return std::unique_ptr<StorageDevice>(new FdStorage(fd, size, "file " + path, 1 << 20, false));
}

Result<std::unique_ptr<StorageDevice>> open_nvmem_storage(const std::string& path, std::uint64_t min_size,
                                                          StorageAccess access, std::size_t chunk_bytes) {
  if (path.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "no nvmem file given; set storage.path (e.g. /sys/bus/nvmem/devices/1-00500/nvmem)");
  }
  const int fd = ::open(path.c_str(), (access == StorageAccess::kWrite ? O_RDWR : O_RDONLY) | O_CLOEXEC |
                                          O_NONBLOCK | O_NOCTTY);
  if (fd < 0) {
    if (errno == ENOENT || errno == ENODEV || errno == ENXIO) {
      return make_error(Errc::kDevice,
                        "no nvmem file " + path + ": " + errno_text(errno) +
                            ". Check that the EEPROM is bound to at24 (device tree, or `echo 24c32 "
                            "0x50 > /sys/bus/i2c/devices/i2c-1/new_device`) and see `ls "
                            "/sys/bus/nvmem/devices`");
    }
    return open_error("nvmem file", path, errno, true);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    return make_error(Errc::kDevice, "cannot stat " + path + ": " + errno_text(err));
  }
  if (S_ISFIFO(st.st_mode) || S_ISSOCK(st.st_mode) || S_ISDIR(st.st_mode)) {
    ::close(fd);
    return make_error(Errc::kInvalidArgument,
                      path + " is a FIFO, socket or folder, not an nvmem file: fix storage.path");
  }
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size < min_size) {
    ::close(fd);
    return make_error(
        Errc::kInvalidArgument,
        path + " holds " + std::to_string(size) + " bytes, the configured region needs " +
            std::to_string(min_size) +
            " (storage.offset_bytes + storage.size_bytes): is it the right EEPROM? Lower those keys "
            "to fit it");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  return std::unique_ptr<StorageDevice>(
      new FdStorage(fd, size, "nvmem " + path, std::max<std::size_t>(chunk_bytes, 1), true));
}

Result<std::unique_ptr<StorageDevice>> open_storage_device(const StorageConfig& c, StorageAccess access) {
  if (c.size_bytes <= 0 || c.offset_bytes < 0) {
    return make_error(Errc::kInvalidArgument,
                      "storage.size_bytes must be positive and storage.offset_bytes not negative");
  }
  const auto end = static_cast<std::uint64_t>(c.offset_bytes) + static_cast<std::uint64_t>(c.size_bytes);
  switch (c.backend) {
    case StorageBackend::kFile:
      return open_file_storage(c.path, end, access);
    case StorageBackend::kNvmem:
      return open_nvmem_storage(c.path, end, access);
    case StorageBackend::kI2cEeprom: {
      I2cEepromOptions o;
      o.address = static_cast<std::uint8_t>(c.i2c_address);
      o.size_bytes = end;
      o.page_bytes = static_cast<std::size_t>(c.page_bytes);
      o.address_bytes = c.address_bytes;
      return open_i2c_eeprom_storage(c.i2c_device, o);
    }
  }
  return make_error(Errc::kInternal, "unknown storage backend");
}

}  // namespace imucal::drivers
