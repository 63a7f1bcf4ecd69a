#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# imucald --check, the dry run, and the exit status of a configuration that cannot be used:
#  - the virtual rig's configuration passes with exit 0 and a summary, and so does the SPI
#    example with --devices-may-appear-later (no device opened; its nodes, not on this machine,
#    are reported; without the option they exit 69, tests/daemon/test_imucald.cpp);
#  - a missing file and an invalid one exit 78 (EX_CONFIG) with a message that names the file;
#  - the service itself (no --check) exits 78 on a missing configuration, the status the unit's
#    RestartPreventExitStatus= names;
#  - a FIFO at storage.path exits 78, naming it (nothing is opened, so nothing waits on it).
#
#   check_imucald_check.sh IMUCALD SOURCE_DIR
set -u
imucald=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
unset IMUCAL_MODULE_DIR

# expect CODE TEXT -- ARGS...: imucald ARGS exits CODE and its output holds TEXT.
expect() {
  code=$1 text=$2
  shift 3
  "$imucald" "$@" >"$tmp/out" 2>&1
  rc=$?
  if [ "$rc" -ne "$code" ] || ! grep -qF -- "$text" "$tmp/out"; then
    echo "FAIL: imucald $* exited $rc (expected $code, with '$text'):"
    sed 's/^/  /' "$tmp/out"
    fail=1
  else
    echo "ok: imucald $* -> $rc"
  fi
}

expect 0 "configuration $src/config/rig.yaml: valid" -- --config "$src/config/rig.yaml" --state-dir "$tmp" --check
grep -q "modules .*imucal_virtual_rig.*: loaded" "$tmp/out" || { echo "FAIL: the virtual rig's module not loaded"; fail=1; }
expect 0 "state dir $tmp: exists, writable" -- --config "$src/config/rig.yaml" --state-dir "$tmp" --check
expect 0 "imu       spi /dev/spidev0.0" -- --config "$src/config/rig-spi-example.yaml" --state-dir "$tmp/none" --check --devices-may-appear-later
grep -q "state dir $tmp/none: does not exist yet" "$tmp/out" || { echo "FAIL: a missing state dir is not reported"; fail=1; }

expect 78 "Edit $tmp/missing.yaml" -- --config "$tmp/missing.yaml" --check
sed "s/^name: spi-rig-example/&\nnot_a_key: 1/" "$src/config/rig-spi-example.yaml" >"$tmp/bad.yaml"
expect 78 "the rig configuration $tmp/bad.yaml cannot be used" -- --config "$tmp/bad.yaml" --check
grep -q "not_a_key" "$tmp/out" || { echo "FAIL: the message does not name the bad key"; fail=1; }
expect 78 "Edit $tmp/missing.yaml" -- --config "$tmp/missing.yaml" --socket "$tmp/s.sock" --state-dir "$tmp"

# A FIFO at storage.path is no storage file: --check said "present" (and the service's event loop
# then waited on it for good).
mkfifo "$tmp/calibration.fifo"
cp "$src/config/checkerboard-7x6.yaml" "$tmp/"  # the target file the configuration names
sed "s|^  path: /var/lib/imucal/calibration.bin|  path: $tmp/calibration.fifo|" "$src/config/rig.yaml" >"$tmp/fifo.yaml"
grep -q "calibration.fifo" "$tmp/fifo.yaml" || { echo "FAIL: the storage path was not replaced"; fail=1; }
expect 78 "storage.path $tmp/calibration.fifo is not a regular file" -- --config "$tmp/fifo.yaml" --state-dir "$tmp" --check
exit $fail
