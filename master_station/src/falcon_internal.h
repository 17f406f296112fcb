#pragma once
// Helpers shared by the Falcon backend's sources (falcon_ftdi.cc, falcon_protocol.cc,
// falcon.cc): the clock and deadline arithmetic of their blocking reads, and the FTDI control
// transfer timeout. Internal to master_station.

#include <chrono>

namespace ht::falcon::detail {

using Clock = std::chrono::steady_clock;

/// Milliseconds from now until `deadline`, truncated towards zero: 0 when less than 1 ms is left,
/// negative once it has passed.
int MsUntil(Clock::time_point deadline) noexcept;

/// Timeout of one FTDI control transfer, also used for the boot loader's bulk writes and echoes
/// (ms).
inline constexpr int kControlTimeoutMs = 1000;

}  // namespace ht::falcon::detail
