#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Fails when a module includes a header of a module it must not depend on. The rules are the
# table in docs/architecture.md:
#   core          nothing of ours
#   drivers       core; real backends never include a fake (drivers/*/fake/)
#   log           core
#   acquisition   core, drivers (no fakes), log
#   calib         core
#   sim           everything below app (it drives the fakes through drivers and acquisition)
#   app           core, drivers (no fakes), log, acquisition, calib: it is on the rig's path
#   daemon/common core (what the programs share: option checks)
#   daemon/service core (the control socket and the protocol's words; no session logic)
#   daemon/ctl    core, the protocol's words (daemon/service/protocol.hpp) and nothing else of
#                 the service: the client is a separate program
#   daemon/imucald core, drivers (no fakes), acquisition, app, daemon/service, daemon/common, and
#                 of sim/ only the virtual rig module's interface (sim/service_rig.hpp): the
#                 rig's service loads the virtual rig, it does not link it
#   daemon/cli    everything but the other programs (daemon/imucald, daemon/ctl, daemon/service)
set -u
root=${1:?usage: check_layering.sh SOURCE_DIR}
cd "$root" || exit 2
bad=0
# check WHAT PATTERN [FILES...]: none of FILES (default: the folder WHAT) may include a header
# whose path matches PATTERN.
check() {
  local what=$1 pattern=$2 hits
  shift 2
  if [ $# -eq 0 ]; then
    [ -d "$what" ] || return 0
    set -- "$what"
  fi
  hits=$(grep -rnE "#include [<\"]($pattern)" "$@" --include='*.hpp' --include='*.cpp' 2>/dev/null)
  if [ -n "$hits" ]; then
    echo "layering violation: $what must not include $pattern:"
    echo "$hits"
    bad=1
  fi
}
# only_header WHAT MODULE HEADER: of MODULE's headers, the folder WHAT may include only HEADER.
only_header() {
  local what=$1 module=$2 header=$3 hits
  hits=$(grep -rnE "#include [<\"]$module" "$what" --include='*.hpp' --include='*.cpp' 2>/dev/null |
    grep -v "$header")
  if [ -n "$hits" ]; then
    echo "layering violation: $what may use only $header of $module:"
    echo "$hits"
    bad=1
  fi
}
others='app/|daemon/'
check core "drivers/|log/|acquisition/|calib/|sim/|$others"
check log "drivers/|acquisition/|calib/|sim/|$others"
check calib "drivers/|acquisition/|log/|sim/|$others"
check drivers "log/|acquisition/|calib/|sim/|$others"
real_drivers=$(find drivers -name '*.?pp' -not -path '*/fake/*')
# shellcheck disable=SC2086
check "drivers (real backends)" "drivers/[a-z0-9_]+/fake/" $real_drivers
check acquisition "calib/|sim/|drivers/[a-z0-9_]+/fake/|$others"
check sim "$others"
check app "sim/|daemon/|drivers/[a-z0-9_]+/fake/"
programs='daemon/cli/|daemon/ctl/|daemon/imucald/|daemon/service/'
check daemon/common "drivers/|log/|acquisition/|calib/|sim/|app/|$programs"
check daemon/service "drivers/|log/|acquisition/|calib/|sim/|app/|daemon/cli/|daemon/ctl/|daemon/imucald/|daemon/common/"
only_header daemon/ctl daemon/service/ daemon/service/protocol.hpp
check daemon/ctl "drivers/|log/|acquisition/|calib/|sim/|app/|daemon/cli/|daemon/imucald/|daemon/common/"
only_header daemon/imucald sim/ sim/service_rig.hpp
check daemon/imucald "log/|calib/|drivers/[a-z0-9_]+/fake/|daemon/cli/|daemon/ctl/"
check daemon/cli "daemon/imucald/|daemon/ctl/|daemon/service/"
[ "$bad" = 0 ] && echo "layering OK"
exit $bad
