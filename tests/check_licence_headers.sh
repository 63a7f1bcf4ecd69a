#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# Every source file of the repository states its licence in its first lines as an SPDX
# identifier: BSD-3-Clause (LICENSE), except the out-of-tree kernel module the QEMU tests build
# (tests/qemu/kmod/), which is GPL-2.0 as the kernel's symbols it uses require. A file without the
# line, or with another licence, is named and the check fails.
#
#   check_licence_headers.sh SOURCE_DIR
set -u
src=${1:-.}
cd "$src" || exit 1
if ! command -v git >/dev/null 2>&1 || ! git rev-parse --git-dir >/dev/null 2>&1; then
  echo "SKIP: not a git checkout (the check lists the tracked files)"
  exit 77
fi
fail=0
count=0
for f in $(git ls-files '*.cpp' '*.hpp' '*.c' '*.sh' '*.bash' '*CMakeLists.txt' '*.cmake' Makefile \
  packaging/debian/postinst packaging/debian/postrm packaging/debian/prerm); do
  [ -f "$f" ] || continue
  count=$((count + 1))
  want=BSD-3-Clause
  case "$f" in tests/qemu/kmod/*.c) want=GPL-2.0 ;; esac
  if ! head -n 3 "$f" | grep -q "SPDX-License-Identifier: $want\$"; then
    echo "FAIL: $f: no 'SPDX-License-Identifier: $want' in its first three lines"
    fail=1
  fi
done
echo "$count files checked"
exit $fail
