#pragma once
// The loop's side of a vendor backend's exchange with its device thread or servo callback
// (force_dimension.h, openhaptics.h): the newest handle reading through a TripleBuffer, refused
// when stale, and the wrench command the other way. No lock, no allocation (1 kHz loop).

#include <cstdint>
#include <glm/mat3x3.hpp>

#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

namespace ht {

/// Takes the newest reading from `samples` into `last` (`have` set once one came) and, when it is
/// valid and at most `stale_after_s` (s) older than `now_ns` (ns, the readings' clock), copies its
/// pose X_MH, twist V_MH_M (M: +z up), buttons and time into `state` and returns true; false
/// otherwise (`state` untouched). `Sample` has X_MH, V_MH_M, buttons, valid and t_ns.
template <class Sample>
bool ReadFreshSample(TripleBuffer<Sample>& samples, Sample& last, bool& have, std::int64_t now_ns,
                     double stale_after_s, DeviceState& state) noexcept {
  Sample s;
  if (samples.Read(s)) {
    last = s;
    have = true;
  }
  if (!have || !last.valid) return false;
  if (now_ns - last.t_ns > static_cast<std::int64_t>(stale_after_s * 1e9)) return false;
  state.X_MH = last.X_MH;
  state.V_MH_M = last.V_MH_M;
  state.buttons = last.buttons;
  state.timestamp_ns = last.t_ns;
  return true;
}

/// Publishes the loop's wrench F_H_M (N, N·m at the handle, in M) on `commands`, turned into the
/// vendor's base frame V by R_VM and stored in the command's member `F_H_V`, with its time
/// `now_ns`. A non-finite wrench publishes zero and returns false. `Command` has t_ns and valid.
template <class Command>
bool WriteVendorWrench(TripleBuffer<Command>& commands, Wrench Command::*F_H_V,
                       const glm::dmat3& R_VM, const Wrench& F_H_M, std::int64_t now_ns) noexcept {
  Command command;
  command.t_ns = now_ns;
  command.valid = true;
  if (!IsFinite(F_H_M)) {
    commands.Write(command);  // zero
    return false;
  }
  command.*F_H_V = Wrench{R_VM * F_H_M.force, R_VM * F_H_M.torque};
  commands.Write(command);
  return true;
}

}  // namespace ht
