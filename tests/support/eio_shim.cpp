// SPDX-License-Identifier: BSD-3-Clause
// An LD_PRELOAD shim that makes reads of one file fail with EIO part way through, as a failing
// disk or a network filesystem does: the file whose path ends with $IMUCAL_EIO_PATH returns EIO
// from the read that would go past $IMUCAL_EIO_AFTER bytes. Used by the import fault tests.
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <sys/types.h>
#include <unistd.h>

#include <cstdarg>
#include <cstdlib>
#include <cstring>

extern "C" {

static int g_fd = -1;
static long long g_done = 0;

static void watch(const char* path, int fd) {
  const char* want = std::getenv("IMUCAL_EIO_PATH");
  if (fd < 0 || want == nullptr || path == nullptr) return;
  const size_t n = strlen(path), m = strlen(want);
  if (n >= m && strcmp(path + n - m, want) == 0) {
    g_fd = fd;
    g_done = 0;
  }
}

#define OPEN_SHIM(name, ...)                                                                               \
  int name(const char* path, int flags, ...) {                                                             \
    static int (*real)(const char*, int, ...) = nullptr;                                                   \
    if (real == nullptr) real = reinterpret_cast<int (*)(const char*, int, ...)>(dlsym(RTLD_NEXT, #name)); \
    mode_t mode = 0;                                                                                       \
    if (flags & (O_CREAT | O_TMPFILE)) {                                                                   \
      va_list ap;                                                                                          \
      va_start(ap, flags);                                                                                 \
      mode = static_cast<mode_t>(va_arg(ap, int));                                                         \
      va_end(ap);                                                                                          \
    }                                                                                                      \
    const int fd = real(path, flags, mode);                                                                \
    watch(path, fd);                                                                                       \
    return fd;                                                                                             \
  }
OPEN_SHIM(open)
OPEN_SHIM(open64)

int openat(int dir, const char* path, int flags, ...) {
  static int (*real)(int, const char*, int, ...) = nullptr;
  if (real == nullptr)
    real = reinterpret_cast<int (*)(int, const char*, int, ...)>(dlsym(RTLD_NEXT, "openat"));
  mode_t mode = 0;
  if (flags & (O_CREAT | O_TMPFILE)) {
    va_list ap;
    va_start(ap, flags);
    mode = static_cast<mode_t>(va_arg(ap, int));
    va_end(ap);
  }
  const int fd = real(dir, path, flags, mode);
  watch(path, fd);
  return fd;
}

ssize_t read(int fd, void* buf, size_t count) {
  static ssize_t (*real)(int, void*, size_t) = nullptr;
  if (real == nullptr) real = reinterpret_cast<ssize_t (*)(int, void*, size_t)>(dlsym(RTLD_NEXT, "read"));
  if (fd == g_fd) {
    const char* after = std::getenv("IMUCAL_EIO_AFTER");
    const long long limit = after ? std::atoll(after) : 0;
    if (g_done + static_cast<long long>(count) > limit) {
      /* Hand out what lies before the failing spot first, as a disk would. */
      if (g_done < limit)
        count = static_cast<size_t>(limit - g_done);
      else {
        errno = EIO;
        return -1;
      }
    }
    const ssize_t r = real(fd, buf, count);
    if (r > 0) g_done += r;
    return r;
  }
  return real(fd, buf, count);
}

int close(int fd) {
  static int (*real)(int) = nullptr;
  if (real == nullptr) real = reinterpret_cast<int (*)(int)>(dlsym(RTLD_NEXT, "close"));
  if (fd == g_fd) g_fd = -1;
  return real(fd);
}

}  // extern "C"
