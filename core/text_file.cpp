// SPDX-License-Identifier: BSD-3-Clause
#include "core/text_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <utility>

namespace imucal {

namespace {

/// Opens `path` for reading when it is a regular file; `st` receives its status.
Result<int> open_regular_file(const std::string& path, struct stat& st) {
  // O_NONBLOCK: opening a FIFO without a writer returns at once (and is refused below) instead
  // of blocking; it does not change reads of a regular file.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    return make_error(Errc::kNotFound,
                      "cannot open " + path + ": " + std::strerror(errno) + " (check the path)");
  }
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const bool dir = S_ISDIR(st.st_mode);
    ::close(fd);
    return make_error(Errc::kNotFound,
                      path + (dir ? " is a folder, expected a file" : " is not a regular file"));
  }
  return fd;
}

}  // namespace

Result<std::string> read_text_file(const std::string& path, std::size_t max_bytes) {
  // One read of the known size into one buffer: no stream growing and copying, and a read error
  // is an error, not an early end of the file.
  struct stat st {};
  auto opened = open_regular_file(path, st);
  if (!opened.ok()) return opened.error();
  const int fd = *opened;
  if (static_cast<std::size_t>(st.st_size) > max_bytes) {
    ::close(fd);
    return make_error(Errc::kInvalidArgument, path + " is " + std::to_string(st.st_size) +
                                                  " bytes, more than such a file can be (" +
                                                  std::to_string(max_bytes) + "); check the path");
  }
  std::string text(static_cast<std::size_t>(st.st_size), '\0');
  std::size_t got = 0;
  while (got < text.size()) {
    const ssize_t r = ::read(fd, text.data() + got, text.size() - got);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      const int err = errno;
      ::close(fd);
      // An input that cannot be read is an input problem (exit 3), like a damaged one.
      return make_error(Errc::kCorrupt, "cannot read " + path + " (after " + std::to_string(got) +
                                            " bytes): " + std::strerror(err));
    }
    if (r == 0) break;  // the file shrank while being read
    got += static_cast<std::size_t>(r);
  }
  ::close(fd);
  text.resize(got);
  return text;
}

Result<std::unique_ptr<TextLineReader>> TextLineReader::open(const std::string& path,
                                                             std::size_t chunk_bytes) {
  struct stat st {};
  auto fd = open_regular_file(path, st);
  if (!fd.ok()) return fd.error();
  return std::unique_ptr<TextLineReader>(new TextLineReader(*fd, path, static_cast<std::uint64_t>(st.st_size),
                                                            std::max<std::size_t>(chunk_bytes, 1)));
}

TextLineReader::TextLineReader(int fd, std::string path, std::uint64_t size, std::size_t chunk_bytes)
    : fd_(fd), path_(std::move(path)), size_(size), chunk_bytes_(chunk_bytes) {}

TextLineReader::~TextLineReader() { ::close(fd_); }

bool TextLineReader::fill() {
  if (eof_ || error_) return false;
  buffer_.erase(0, pos_);  // keep only the unread part (a line begun in the last chunk)
  pos_ = 0;
  const std::size_t old_size = buffer_.size();
  buffer_.resize(old_size + chunk_bytes_);
  ssize_t r = 0;
  do {
    r = ::read(fd_, buffer_.data() + old_size, chunk_bytes_);
  } while (r < 0 && errno == EINTR);
  if (r < 0) {
    const int err = errno;
    buffer_.resize(old_size);
    // An input that cannot be read is an input problem (exit 3), like a damaged one.
    error_ = make_error(Errc::kCorrupt, "cannot read " + path_ + " (after " +
                                            std::to_string(consumed_ + old_size) +
                                            " bytes): " + std::strerror(err));
    return false;
  }
  buffer_.resize(old_size + static_cast<std::size_t>(r));
  if (r == 0) eof_ = true;
  return r > 0;
}

bool TextLineReader::next(std::string_view& line) {
  std::size_t searched = pos_;
  while (true) {
    const std::size_t end = buffer_.find('\n', searched);
    if (end != std::string::npos) {
      line = std::string_view(buffer_).substr(pos_, end - pos_);
      consumed_ += end + 1 - pos_;
      pos_ = end + 1;
      return true;
    }
    if (buffer_.size() - pos_ > kMaxLineBytes) {
      error_ = make_error(Errc::kCorrupt, path_ + ": a line at byte " + std::to_string(consumed_) +
                                              " is longer than " + std::to_string(kMaxLineBytes) +
                                              " bytes: not a text dataset");
      return false;
    }
    searched = buffer_.size() - pos_;  // relative to pos_, which fill() moves to 0
    if (!fill()) {
      if (error_) return false;
      if (pos_ >= buffer_.size()) return false;       // the end, after the last '\n'
      line = std::string_view(buffer_).substr(pos_);  // a last line without '\n'
      consumed_ += buffer_.size() - pos_;
      pos_ = buffer_.size();
      return true;
    }
  }
}

namespace {

/// Length of the UTF-8 sequence at text[i], or 0 when it is not well-formed.
std::size_t utf8_length(std::string_view text, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned char c = byte(i);
  if (c < 0x80) return 1;
  std::size_t n = 0;
  std::uint32_t cp = 0;
  if ((c & 0xe0) == 0xc0) {
    n = 2;
    cp = c & 0x1f;
  } else if ((c & 0xf0) == 0xe0) {
    n = 3;
    cp = c & 0x0f;
  } else if ((c & 0xf8) == 0xf0) {
    n = 4;
    cp = c & 0x07;
  } else {
    return 0;
  }
  if (i + n > text.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    if ((byte(i + k) & 0xc0) != 0x80) return 0;
    cp = (cp << 6) | (byte(i + k) & 0x3f);
  }
  static constexpr std::uint32_t kMin[5] = {0, 0, 0x80, 0x800, 0x10000};
  if (cp < kMin[n] || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff)) return 0;
  return n;
}

}  // namespace

bool valid_utf8(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t n = utf8_length(text, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

std::string printable(std::string_view text, std::size_t max_chars) {
  std::string out;
  std::size_t chars = 0;
  for (std::size_t i = 0; i < text.size(); ++chars) {
    if (chars == max_chars) return out + "...";
    const std::size_t n = utf8_length(text, i);
    const bool bom = n == 3 && text.substr(i, 3) == "\xef\xbb\xbf";
    if (n == 0 || bom || (n == 1 && (static_cast<unsigned char>(text[i]) < 0x20 || text[i] == 0x7f))) {
      for (std::size_t k = 0; k < std::max<std::size_t>(n, 1); ++k) {
        char hex[8];
        std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned char>(text[i + k]));
        out += hex;
      }
      i += std::max<std::size_t>(n, 1);
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
  }
  return out;
}

}  // namespace imucal
