#!/usr/bin/env bash
# The imucal program must not depend on the solver, renderer or camera libraries: Ceres (static,
# but it brings glog, SuiteSparse, BLAS and LAPACK), OpenCV, libapriltag, Aravis (with glib and
# libusb), libcamera. They are loaded in modules by the commands that use them
# (app/module_loader.hpp), so that start-up stays cheap (docs/benchmarks.md).
# Usage: check_program_links.sh PROGRAM
set -euo pipefail
program=$1
needed=$(readelf -d "$program" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
[ -n "$needed" ] || { echo "check_program_links: no NEEDED entries read from $program" >&2; exit 1; }
bad=$(grep -E 'ceres|glog|gflags|spqr|cholmod|cxsparse|lapack|blas|opencv|apriltag|gdal|poppler|hdf5|aravis|glib|gobject|gio-|libcamera|libusb' <<< "$needed" || true)
if [ -n "$bad" ]; then
  echo "$program depends on libraries that belong in its modules:" >&2
  echo "$bad" >&2
  exit 1
fi
echo "$program needs $(wc -l <<< "$needed") libraries, none of the solver's, renderer's or cameras':"
echo "$needed"
