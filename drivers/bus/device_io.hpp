// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What the Linux bus drivers (SpidevBus, I2cDevBus) share: the system calls they make on their
// device node, behind an interface so that tests can substitute a fake kernel, and the hex
// formatting of register numbers and addresses in their messages.

#include <memory>
#include <string>

#include "core/text_format.hpp"

namespace imucal::drivers {

/// The system calls a bus makes on its device node. The default forwards to the kernel; tests
/// substitute a fake to check the transfers a bus builds without a controller or adapter.
class DeviceIo {
 public:
  virtual ~DeviceIo() = default;
  /// open(2) read-write: a file descriptor, or -errno.
  virtual int open(const std::string& path) = 0;
  virtual void close(int fd) = 0;
  /// ioctl(2): the ioctl's result, or -errno.
  virtual int ioctl(int fd, unsigned long request, void* arg) = 0;
};

/// The kernel's open(2), close(2) and ioctl(2).
std::unique_ptr<DeviceIo> system_device_io();

/// A device node opened through a DeviceIo. It owns the descriptor: close() and the destructor
/// close it, and so does open() before opening again.
class DeviceFile {
 public:
  /// A `path` without a directory is a node in /dev. A null `io` means system_device_io().
  DeviceFile(std::string path, std::unique_ptr<DeviceIo> io);
  ~DeviceFile() { close(); }
  DeviceFile(const DeviceFile&) = delete;
  DeviceFile& operator=(const DeviceFile&) = delete;

  /// Opens the node read-write: 0, or -errno.
  int open();
  void close();
  bool is_open() const { return fd_ >= 0; }
  /// ioctl(2) on the open node: its result, or -errno (-EBADF when closed).
  int ioctl(unsigned long request, void* arg);

  const std::string& path() const { return path_; }
  /// The node's file name: "spidev0.0" for /dev/spidev0.0.
  std::string node_name() const;

 private:
  std::string path_;
  std::unique_ptr<DeviceIo> io_;
  int fd_ = -1;
};

}  // namespace imucal::drivers
