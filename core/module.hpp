// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What every imucal shared module (libimucal_solve.so, libimucal_render.so) and the programs that
// load them (app/module_loader.hpp) agree on.

namespace imucal {

/// Every module exports one C function `const void* <entry>()` returning a pointer to its API
/// struct; the struct's first member is this header, which must match the program's.
struct ModuleHeader {
  const char* version;  // core/version.hpp kVersion of the build that made the module
  int abi;              // kModuleAbi of that build
};

/// Raised whenever the API structs or the types they pass change shape.
inline constexpr int kModuleAbi = 7;

}  // namespace imucal
