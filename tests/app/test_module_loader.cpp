// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>
#include <stdlib.h>

#include <fstream>
#include <string>
#include <vector>

#include "app/module_loader.hpp"
#include "app/solvers.hpp"
#include "calib/solve_module.hpp"
#include "core/version.hpp"
#include "sim/render_module.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

/// Sets IMUCAL_MODULE_DIR for the scope of one test.
TEST(ModuleLoader, LoadsTheSolverModuleAndCallsThroughIt) {
  test::ScopedModuleDir dir(IMUCAL_MODULE_BUILD_DIR);
  auto api = app::load_module<calib::SolveModuleApi>(calib::kSolveModule, calib::kSolveModuleEntry);
  ASSERT_TRUE(api.ok()) << api.error().message;
  EXPECT_STREQ((*api)->header.version, kVersion);
  EXPECT_EQ((*api)->header.abi, kModuleAbi);
  // Loaded once: the second call returns the same table.
  auto again = app::load_module<calib::SolveModuleApi>(calib::kSolveModule, calib::kSolveModuleEntry);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*api, *again);
  // The call crosses into the module and its error comes back whole.
  const std::vector<ImuSample> none;
  auto res = app::calibrate_static(none, calib::StaticCalibrationOptions{});
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.error().code, Errc::kInsufficientData) << res.error().message;
}

TEST(ModuleLoader, LoadsTheRendererModule) {
  test::ScopedModuleDir dir(IMUCAL_MODULE_BUILD_DIR);
  auto api = app::load_module<sim::RenderModuleApi>(sim::kRenderModule, sim::kRenderModuleEntry);
  ASSERT_TRUE(api.ok()) << api.error().message;
  EXPECT_NE((*api)->camimu_session, nullptr);
}

TEST(ModuleLoader, MissingModuleNamesWhereItLookedAndWhatToDo) {
  const std::string empty = test::scratch_dir();
  test::ScopedModuleDir dir(empty);
  auto api = app::load_module_api("imucal_nosuch", "imucal_nosuch_module");
  ASSERT_FALSE(api.ok());
  EXPECT_EQ(api.error().code, Errc::kUnsupported);
  EXPECT_NE(api.error().message.find("libimucal_nosuch.so"), std::string::npos) << api.error().message;
  EXPECT_NE(api.error().message.find(empty), std::string::npos) << api.error().message;
  EXPECT_NE(api.error().message.find("IMUCAL_MODULE_DIR"), std::string::npos) << api.error().message;
  EXPECT_NE(api.error().message.find("reinstall imucal"), std::string::npos) << api.error().message;
  // A camera backend comes in a package of its own: the message names it.
  for (const char* backend : {"aravis", "libcamera"}) {
    const std::string name = std::string("imucal_") + backend;
    auto missing = app::load_module_api(name, (name + "_module").c_str());
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.error().message.find(std::string("apt-get install imucal-") + backend),
              std::string::npos)
        << missing.error().message;
  }
}

TEST(ModuleLoader, ABrokenFileIsRefusedWithTheLoadersReason) {
  const std::string scratch = test::scratch_dir();
  std::ofstream(scratch + "/libimucal_junk.so") << "not an ELF file\n";
  test::ScopedModuleDir dir(scratch);
  auto api = app::load_module_api("imucal_junk", "imucal_junk_module");
  ASSERT_FALSE(api.ok());
  EXPECT_EQ(api.error().code, Errc::kUnsupported);
  EXPECT_NE(api.error().message.find("cannot load"), std::string::npos) << api.error().message;
}

TEST(ModuleLoader, AModuleWithoutTheEntryIsRefused) {
  test::ScopedModuleDir dir(IMUCAL_MODULE_BUILD_DIR);
  // The renderer module asked for the solver's entry point.
  auto api = app::load_module_api(sim::kRenderModule, calib::kSolveModuleEntry);
  ASSERT_FALSE(api.ok());
  EXPECT_EQ(api.error().code, Errc::kUnsupported);
  EXPECT_NE(api.error().message.find("no entry point imucal_solve_module"), std::string::npos)
      << api.error().message;
}

}  // namespace
}  // namespace imucal
