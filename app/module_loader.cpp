// SPDX-License-Identifier: BSD-3-Clause
#include "app/module_loader.hpp"

#include <dlfcn.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <system_error>
#include <vector>

#include "core/version.hpp"

namespace imucal::app {
namespace {

namespace fs = std::filesystem;

std::vector<fs::path> search_dirs() {
  if (const char* dir = std::getenv("IMUCAL_MODULE_DIR"); dir != nullptr && *dir != '\0')
    return {fs::path(dir)};
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  const fs::path dir = exe.parent_path();
  return {dir, dir.parent_path() / "lib" / "imucal"};
}

/// The Debian package a module comes in: the camera backends have packages of their own
/// (cmake/packaging.cmake), so that a rig without such a camera does not pull in its libraries.
std::string package_of(std::string_view name) {
  if (name == "imucal_aravis") return "imucal-aravis";
  if (name == "imucal_libcamera") return "imucal-libcamera";
  return "imucal";
}

Result<const void*> load_uncached(std::string_view name, const char* entry) {
  const std::string file = "lib" + std::string(name) + ".so";
  const auto dirs = search_dirs();
  std::string tried;
  for (const auto& dir : dirs) {
    const fs::path path = dir / file;
    std::error_code ec;
    if (!fs::exists(path, ec)) {
      tried += (tried.empty() ? "" : ", ") + dir.string();
      continue;
    }
    // RTLD_LOCAL: the module's own copies of the libraries stay private to it.
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* why = dlerror();
      return make_error(Errc::kUnsupported,
                        "cannot load " + path.string() + ": " + (why ? why : "unknown reason") +
                            "; reinstall imucal (the module or a library it needs is broken)");
    }
    using EntryFn = const void* (*)();
    auto fn = reinterpret_cast<EntryFn>(dlsym(handle, entry));
    if (fn == nullptr) {
      return make_error(Errc::kUnsupported, path.string() + " has no entry point " + entry +
                                                "; it is not an imucal module of this kind");
    }
    const void* api = fn();
    const auto* header = static_cast<const ModuleHeader*>(api);
    if (header == nullptr || header->abi != kModuleAbi || header->version == nullptr ||
        std::strcmp(header->version, kVersion) != 0) {
      return make_error(Errc::kUnsupported,
                        path.string() + " is from another build of imucal (version " +
                            (header && header->version ? header->version : "unknown") + ", this program is " +
                            kVersion + "); reinstall imucal so that the program and its modules match");
    }
    return api;
  }
  const std::string package = package_of(name);
  const std::string remedy = package == "imucal"
                                 ? "reinstall imucal"
                                 : "install the package " + package + " (apt-get install " + package + ")";
  return make_error(Errc::kUnsupported, "the module " + file + " is not in " +
                                            (tried.empty() ? "any folder" : tried) + "; " + remedy +
                                            ", or set IMUCAL_MODULE_DIR to the folder that holds it");
}

}  // namespace

Result<const void*> load_module_api(std::string_view name, const char* entry) {
  static std::mutex mutex;
  static std::map<std::string, const void*, std::less<>> loaded;
  const std::lock_guard lock(mutex);
  const std::string key = std::string(name) + "/" + entry;
  auto it = loaded.find(key);
  if (it == loaded.end()) {
    auto api = load_uncached(name, entry);
    if (!api.ok()) return api;
    it = loaded.emplace(key, *api).first;
  }
  // The module's messages in the program's words, as they are now (core/option_words.hpp).
  static_cast<const ModuleHeader*>(it->second)->use_vocabulary(option_vocabulary());
  return it->second;
}

}  // namespace imucal::app
