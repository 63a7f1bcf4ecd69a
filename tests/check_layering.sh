#!/usr/bin/env bash
# Fails when a module includes a header from a layer it must not depend on
# (see docs/architecture.md): calib sees neither drivers nor acquisition; drivers and core
# never see calib, acquisition or daemon; acquisition never sees calib.
set -u
root=${1:?usage: check_layering.sh SOURCE_DIR}
cd "$root" || exit 2
bad=0
check() {  # check DIR PATTERN
  local hits
  hits=$(grep -rnE "#include [<\"]($2)/" "$1" --include='*.hpp' --include='*.cpp' 2>/dev/null)
  if [ -n "$hits" ]; then
    echo "layering violation: $1 must not include $2:"; echo "$hits"; bad=1
  fi
}
check calib 'drivers|acquisition|daemon'
check drivers 'calib|acquisition|daemon'
check core 'calib|acquisition|daemon|drivers'
check acquisition 'calib|daemon'
[ "$bad" = 0 ] && echo "layering OK"
exit $bad
