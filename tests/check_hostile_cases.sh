#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Every test named in tests/hostile-cases.txt is a test of this build tree, so that
# `make hostile` runs what the list says. Usage: tests/check_hostile_cases.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src=$1
build=$2
known=$(ctest --test-dir "$build" -N | sed -n 's/^ *Test *#[0-9]*: *//p')
missing=0 listed=0
while read -r name; do
  listed=$((listed + 1))
  if ! grep -qxF "$name" <<< "$known"; then
    echo "tests/hostile-cases.txt names $name, which is no test of $build" >&2
    missing=$((missing + 1))
  fi
done < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' -e '/^$/d' "$src/tests/hostile-cases.txt")
[ "$listed" -gt 0 ] || { echo "tests/hostile-cases.txt lists no test" >&2; exit 1; }
[ "$missing" -eq 0 ] || exit 1
echo "hostile cases: all $listed listed tests exist"
