#pragma once
// trace.csv of the operator station (one concern of RunOperatorStation): one row per
// haptic tick, filled by the loop and written by the recorder thread. Internal to master_station.

#include <cstdio>
#include <string>
#include <vector>

#include "haptic_core/spatial.h"

namespace ht::station {

/// One row of trace.csv (one per tick), filled by the loop and written by the recorder thread.
struct TraceRow {
  double t_s = 0.0;
  int phase = 0;
  RigidTransform X_WT;
  Wrench F_contact_T_W;
  int contacts = 0;
  double model_age_ms = -1.0;
  glm::dvec3 p_WH{0.0};
  Wrench F_H_W;
  double depth_m = 0.0;
  float tick_compute_us = 0.0f;
  float remote_collision_us = 0.0f;
  float remote_texture_us = 0.0f;
  float remote_step_us = 0.0f;
  double passivity_removed_n = 0.0;  ///< OperatorTickOutput::passivity_removed_n (N)
  /// The force commanded to the device in its own frame M (x, y in the device's plane, z the
  /// scene's up): what the operator feels, whatever the scene's axes (N).
  glm::dvec3 f_H_M{0.0};
};

/// Writes the header line of trace.csv.
void WriteTraceHeader(std::FILE* f);
/// Writes one row; `phases` names the experiment's phases. Returns the bytes written (0 when the
/// write failed), so that the trace's size cap needs no ftell per row.
long WriteTraceRow(std::FILE* f, const TraceRow& r, const std::vector<std::string>& phases);

}  // namespace ht::station
