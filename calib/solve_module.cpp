// SPDX-License-Identifier: BSD-3-Clause
// The entry point of libimucal_solve.so (calib/solve_module.hpp). Everything else in the module
// is hidden: it carries its own copies of the imucal libraries it needs.

#include "calib/solve_module.hpp"

#include "core/version.hpp"

extern "C" __attribute__((visibility("default"))) const void* imucal_solve_module() {
  static const imucal::calib::SolveModuleApi api{{imucal::kVersion, imucal::kModuleAbi},
                                                 &imucal::calib::calibrate_static};
  return &api;
}
