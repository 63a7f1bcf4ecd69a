#!/usr/bin/env bash
# The main job on the built-in simulated rig. Grows with the product.
set -euo pipefail
IMUCAL=${1:-build/release/daemon/imucal}
"$IMUCAL" --version
