// SPDX-License-Identifier: BSD-3-Clause
// The entry point of libimucal_virtual_rig.so (sim/service_rig.hpp). Everything else in the
// module is hidden: it carries its own copies of the imucal libraries it needs.

#include "core/version.hpp"
#include "sim/service_rig.hpp"

extern "C" __attribute__((visibility("default"))) const void* imucal_virtual_rig_module() {
  static const imucal::sim::VirtualRigModuleApi api{{imucal::kVersion, imucal::kModuleAbi},
                                                    &imucal::sim::make_service_rig};
  return &api;
}
