// SPDX-License-Identifier: BSD-3-Clause
// CRC-32 for frame data, and a thin SQLite VFS over the default one, used by the session log reader. SQLite
// fills a short read of a database page with zeros, so the partial last page of a truncated file would be
// decoded as (made-up) rows. Through this VFS such a read of the main database file fails
// instead, and the reader reports the page as lost.

#include <array>
#include <cstring>
#include <mutex>

#include "log/session_log_sqlite.hpp"

namespace imucal::log::sqlite {
namespace {

struct StrictFile {
  sqlite3_file base;
  sqlite3_file* real;  // the default VFS's file object, stored right after this struct
  bool main_db;
};

sqlite3_vfs g_vfs;
sqlite3_io_methods g_methods;

sqlite3_vfs* base_of(sqlite3_vfs* vfs) { return static_cast<sqlite3_vfs*>(vfs->pAppData); }
int strict_delete(sqlite3_vfs* vfs, const char* name, int sync_dir) {
  return base_of(vfs)->xDelete(base_of(vfs), name, sync_dir);
}
int strict_access(sqlite3_vfs* vfs, const char* name, int flags, int* out) {
  return base_of(vfs)->xAccess(base_of(vfs), name, flags, out);
}
int strict_full_pathname(sqlite3_vfs* vfs, const char* name, int n, char* out) {
  return base_of(vfs)->xFullPathname(base_of(vfs), name, n, out);
}
int strict_randomness(sqlite3_vfs* vfs, int n, char* out) {
  return base_of(vfs)->xRandomness(base_of(vfs), n, out);
}
int strict_sleep(sqlite3_vfs* vfs, int us) { return base_of(vfs)->xSleep(base_of(vfs), us); }
int strict_current_time(sqlite3_vfs* vfs, double* out) {
  return base_of(vfs)->xCurrentTime(base_of(vfs), out);
}
int strict_last_error(sqlite3_vfs* vfs, int n, char* out) {
  return base_of(vfs)->xGetLastError(base_of(vfs), n, out);
}
int strict_current_time_int64(sqlite3_vfs* vfs, sqlite3_int64* out) {
  return base_of(vfs)->xCurrentTimeInt64(base_of(vfs), out);
}

sqlite3_file* real(sqlite3_file* f) { return reinterpret_cast<StrictFile*>(f)->real; }

int strict_close(sqlite3_file* f) {
  return real(f)->pMethods ? real(f)->pMethods->xClose(real(f)) : SQLITE_OK;
}
int strict_read(sqlite3_file* f, void* buf, int amount, sqlite3_int64 offset) {
  const int rc = real(f)->pMethods->xRead(real(f), buf, amount, offset);
  // The header read at offset 0 may be short on an empty file; any other page must be whole.
  if (rc == SQLITE_IOERR_SHORT_READ && reinterpret_cast<StrictFile*>(f)->main_db && offset > 0)
    return SQLITE_IOERR_READ;
  return rc;
}
int strict_write(sqlite3_file* f, const void* buf, int amount, sqlite3_int64 offset) {
  return real(f)->pMethods->xWrite(real(f), buf, amount, offset);
}
int strict_truncate(sqlite3_file* f, sqlite3_int64 size) {
  return real(f)->pMethods->xTruncate(real(f), size);
}
int strict_sync(sqlite3_file* f, int flags) { return real(f)->pMethods->xSync(real(f), flags); }
int strict_file_size(sqlite3_file* f, sqlite3_int64* size) {
  return real(f)->pMethods->xFileSize(real(f), size);
}
int strict_lock(sqlite3_file* f, int lock) { return real(f)->pMethods->xLock(real(f), lock); }
int strict_unlock(sqlite3_file* f, int lock) { return real(f)->pMethods->xUnlock(real(f), lock); }
int strict_check_reserved(sqlite3_file* f, int* out) {
  return real(f)->pMethods->xCheckReservedLock(real(f), out);
}
int strict_file_control(sqlite3_file* f, int op, void* arg) {
  return real(f)->pMethods->xFileControl(real(f), op, arg);
}
int strict_sector_size(sqlite3_file* f) { return real(f)->pMethods->xSectorSize(real(f)); }
int strict_device_characteristics(sqlite3_file* f) {
  return real(f)->pMethods->xDeviceCharacteristics(real(f));
}
int strict_shm_map(sqlite3_file* f, int page, int size, int extend, void volatile** out) {
  return real(f)->pMethods->xShmMap(real(f), page, size, extend, out);
}
int strict_shm_lock(sqlite3_file* f, int offset, int n, int flags) {
  return real(f)->pMethods->xShmLock(real(f), offset, n, flags);
}
void strict_shm_barrier(sqlite3_file* f) { real(f)->pMethods->xShmBarrier(real(f)); }
int strict_shm_unmap(sqlite3_file* f, int delete_flag) {
  return real(f)->pMethods->xShmUnmap(real(f), delete_flag);
}
int strict_fetch(sqlite3_file* f, sqlite3_int64 offset, int amount, void** out) {
  *out = nullptr;  // no memory mapping: every page goes through xRead
  (void)f;
  (void)offset;
  (void)amount;
  return SQLITE_OK;
}
int strict_unfetch(sqlite3_file* f, sqlite3_int64 offset, void* p) {
  (void)f;
  (void)offset;
  (void)p;
  return SQLITE_OK;
}

int strict_open(sqlite3_vfs* vfs, const char* name, sqlite3_file* file, int flags, int* out_flags) {
  sqlite3_vfs* base = base_of(vfs);
  auto* strict = reinterpret_cast<StrictFile*>(file);
  std::memset(strict, 0, sizeof(StrictFile));
  strict->real = reinterpret_cast<sqlite3_file*>(strict + 1);
  strict->main_db = (flags & SQLITE_OPEN_MAIN_DB) != 0;
  const int rc = base->xOpen(base, name, strict->real, flags, out_flags);
  if (strict->real->pMethods) {
    file->pMethods = &g_methods;
  }
  return rc;
}

}  // namespace

std::uint32_t crc32(const std::uint8_t* data, std::size_t size) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < size; ++i) crc = table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

const char* strict_vfs_name() {
  static std::once_flag once;
  std::call_once(once, [] {
    sqlite3_vfs* base = sqlite3_vfs_find(nullptr);
    g_vfs = sqlite3_vfs{};
    g_vfs.iVersion = 2;
    g_vfs.szOsFile = static_cast<int>(sizeof(StrictFile)) + base->szOsFile;
    g_vfs.mxPathname = base->mxPathname;
    g_vfs.zName = "imucal-strict";
    g_vfs.pAppData = base;
    g_vfs.xOpen = strict_open;
    g_vfs.xDelete = strict_delete;
    g_vfs.xAccess = strict_access;
    g_vfs.xFullPathname = strict_full_pathname;
    g_vfs.xRandomness = strict_randomness;
    g_vfs.xSleep = strict_sleep;
    g_vfs.xCurrentTime = strict_current_time;
    g_vfs.xGetLastError = strict_last_error;
    g_vfs.xCurrentTimeInt64 = strict_current_time_int64;
    g_methods = sqlite3_io_methods{3,
                                   strict_close,
                                   strict_read,
                                   strict_write,
                                   strict_truncate,
                                   strict_sync,
                                   strict_file_size,
                                   strict_lock,
                                   strict_unlock,
                                   strict_check_reserved,
                                   strict_file_control,
                                   strict_sector_size,
                                   strict_device_characteristics,
                                   strict_shm_map,
                                   strict_shm_lock,
                                   strict_shm_barrier,
                                   strict_shm_unmap,
                                   strict_fetch,
                                   strict_unfetch};
    sqlite3_vfs_register(&g_vfs, 0);
  });
  return g_vfs.zName;
}

}  // namespace imucal::log::sqlite
