#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Fails when a file includes a header, or (given a build's link_graph.txt) a target links a
# library, that docs/layers.md does not allow. The rules are the tables of docs/layers.md only;
# the checking is check_layering.py's.
#   usage: check_layering.sh SOURCE_DIR [BUILD_DIR/link_graph.txt]
set -eu
here=$(cd "$(dirname "$0")" && pwd)
exec python3 "$here/check_layering.py" "$@"
