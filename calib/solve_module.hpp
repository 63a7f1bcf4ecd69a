// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The solver module, libimucal_solve.so: the estimators that need Ceres, loaded by the programs
// only in the commands that solve (app/module_loader.hpp). Tests and benchmarks link the
// estimators directly.

#include "calib/static_calibration.hpp"
#include "core/module.hpp"

namespace imucal::calib {

inline constexpr const char* kSolveModule = "imucal_solve";
inline constexpr const char* kSolveModuleEntry = "imucal_solve_module";

struct SolveModuleApi {
  ModuleHeader header;
  decltype(&calibrate_static) static_calibration;
};

}  // namespace imucal::calib
