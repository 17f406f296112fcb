#pragma once
// Helpers shared by the SpaceMouse backend's sources (hid_descriptor.cc, spacemouse_report.cc,
// spacemouse_pose.cc, spacemouse.cc): message formatting and the check of an axis map. Internal
// to master_station.

#include <cstdio>
#include <string>

#include "master_station/spacemouse_report.h"

namespace ht::detail {

/// snprintf into a std::string (messages of at most 255 characters; longer ones are cut).
std::string Format(const char* fmt, auto... args) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

/// Throws std::invalid_argument unless map.source is a permutation of 0..5 and every map.sign is
/// finite and non-zero.
void ValidateAxisMap(const SpaceMouseAxisMap& map);

}  // namespace ht::detail
