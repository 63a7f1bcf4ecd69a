// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What every imucal shared module (libimucal_solve.so, libimucal_render.so) and the programs that
// load them (app/module_loader.hpp) agree on.

#include "core/option_words.hpp"

namespace imucal {

/// Every module exports one C function `const void* <entry>()` returning a pointer to its API
/// struct; the struct's first member is this header, which must match the program's.
struct ModuleHeader {
  const char* version;  // core/version.hpp kVersion of the build that made the module
  int abi;              // kModuleAbi of that build
  /// The module's own set_option_vocabulary (its copy of core's state): the loader hands it the
  /// program's vocabulary each time the module is asked for, so that calib's messages inside
  /// the module speak the program's words.
  OptionVocabulary (*use_vocabulary)(OptionVocabulary) = &set_option_vocabulary;
};

/// Raised whenever the API structs or the types they pass change shape.
inline constexpr int kModuleAbi = 8;

}  // namespace imucal
