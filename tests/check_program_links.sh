#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Checks what an installed program links.
#  - No program depends on the solver, renderer or camera libraries: Ceres (static, but it brings
#    glog, SuiteSparse, BLAS and LAPACK), OpenCV, libapriltag, Aravis (with glib and libusb),
#    libcamera. They are loaded in modules by the commands that use them (app/module_loader.hpp),
#    so that start-up stays cheap (docs/benchmarks.md).
#  - With --no-simulator, the program carries no code of the simulator or the device fakes
#    (namespaces imucal::sim, imucal::fake, imucal::drivers::camera::fake): the rig's service and its
#    client. imucald's virtual rig is the module libimucal_virtual_rig.so; the one piece of sim/ it
#    includes is the module's interface (sim/service_rig.hpp), whose types are all of it that may
#    appear.
# Usage: check_program_links.sh [--no-simulator] PROGRAM
set -euo pipefail
no_sim=0
if [ "${1:-}" = "--no-simulator" ]; then
  no_sim=1
  shift
fi
program=${1:?usage: check_program_links.sh [--no-simulator] PROGRAM}
name=$(basename "$program")
needed=$(readelf -d "$program" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
[ -n "$needed" ] || { echo "check_program_links: no NEEDED entries read from $program" >&2; exit 1; }
bad=$(grep -E 'ceres|glog|gflags|spqr|cholmod|cxsparse|lapack|blas|opencv|apriltag|gdal|poppler|hdf5|aravis|glib|gobject|gio-|libcamera|libusb' <<< "$needed" || true)
if [ -n "$bad" ]; then
  echo "$name depends on libraries that belong in its modules:" >&2
  echo "$bad" >&2
  exit 1
fi
echo "$name needs $(wc -l <<< "$needed") libraries, none of the solver's, renderer's or cameras':"
echo "$needed"
if [ "$no_sim" = 1 ]; then
  code=$(nm -C --defined-only "$program" | grep -E ' [TtWw] ' || true)
  [ -n "$code" ] || { echo "check_program_links: no symbols read from $program (stripped?)" >&2; exit 1; }
  # The interface's own types (sim/service_rig.hpp) may appear, in the functions and template
  # instances that pass them; any other name of sim/ or of a fake is simulator code.
  sim=$(sed -E 's/imucal::sim::(ServiceRig|ServiceRigOptions|ServiceRigTick|VirtualRigModuleApi)\b//g' <<< "$code" |
    grep -E 'imucal::(sim|fake)::|imucal::drivers::camera::fake::' || true)
  if [ -n "$sim" ]; then
    echo "$name carries code of the simulator or the device fakes ($(wc -l <<< "$sim") functions), which" >&2
    echo "belongs in libimucal_virtual_rig.so; for example:" >&2
    head -5 <<< "$sim" >&2
    exit 1
  fi
  echo "$name carries no code of the simulator or the device fakes."
fi
