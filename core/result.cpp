// SPDX-License-Identifier: BSD-3-Clause
#include "core/result.hpp"

namespace imucal {

const char* errc_name(Errc code) {
  switch (code) {
    case Errc::kInvalidArgument:
      return "invalid argument";
    case Errc::kNotFound:
      return "not found";
    case Errc::kIo:
      return "I/O error";
    case Errc::kCorrupt:
      return "corrupt data";
    case Errc::kUnsupported:
      return "unsupported";
    case Errc::kDevice:
      return "device error";
    case Errc::kTimeout:
      return "timeout";
    case Errc::kInsufficientData:
      return "insufficient data";
    case Errc::kSolverFailed:
      return "solver failed";
    case Errc::kAlreadyExists:
      return "already exists";
    case Errc::kNewerVersion:
      return "written by a newer imucal";
    case Errc::kInternal:
      return "internal error";
  }
  return "unknown error";
}

}  // namespace imucal
