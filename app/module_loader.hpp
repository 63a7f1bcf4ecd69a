// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Loading the program's own shared modules at the point of use. The heavy dependencies live in
// modules so that a program pays for them only in the commands that need them: the static solver
// (Ceres with SuiteSparse, BLAS and LAPACK) in libimucal_solve.so, the camera renderer (OpenCV)
// in libimucal_render.so. `imucal --version`, `info` or `record` never load either
// (docs/architecture.md, "Modules loaded at use"; start-up figures in docs/benchmarks.md).
//
// Search order: the folder named by IMUCAL_MODULE_DIR when it is set (and only there), else the
// folder of the running executable (the build tree), then <exe>/../lib/imucal (an install).
// A module is loaded once per process and never unloaded.

#include <string>
#include <string_view>

#include "core/module.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// Loads lib<name>.so and returns the API struct its `entry` function returns. Fails with
/// kUnsupported (this installation cannot serve the request) when the module is in none of the
/// searched folders, cannot be loaded or is from another build; the message names the folders or
/// the loader's own reason, and what to do.
[[nodiscard]] Result<const void*> load_module_api(std::string_view name, const char* entry);

/// Typed form: `Api` starts with a ModuleHeader.
template <typename Api>
[[nodiscard]] Result<const Api*> load_module(std::string_view name, const char* entry) {
  auto api = load_module_api(name, entry);
  if (!api.ok()) return api.error();
  return static_cast<const Api*>(*api);
}

}  // namespace imucal::app
