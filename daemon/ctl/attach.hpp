// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// imucalctl attach: the operator console on a terminal, or one line per message when stdout is
// not one. Keys are read raw from the terminal (no echo, no line buffering); the terminal is
// restored on every way out, signals included.

#include "daemon/ctl/client.hpp"

namespace imucal::ctl {

struct AttachOptions {
  bool observe = false;  // attach as an observer: see everything, send nothing
};

/// Runs until the operator detaches (q), a signal arrives or the service goes away. Returns
/// the exit code: 0 after a detach or signal, 1 when the service refused or closed.
int attach(Connection& connection, const AttachOptions& options);

}  // namespace imucal::ctl
