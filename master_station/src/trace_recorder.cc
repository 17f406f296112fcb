#include "trace_recorder.h"

namespace ht::station {

void WriteTraceHeader(std::FILE* f) {
  std::fputs(
      "t_s,phase,tool_x,tool_y,tool_z,tool_rx,tool_ry,tool_rz,fx,fy,fz,tx,ty,tz,contacts,"
      "model_age_ms,hand_x,hand_y,hand_z,device_fx,device_fy,device_fz,device_tx,device_ty,"
      "device_tz,depth_m,tick_compute_us,remote_collision_us,remote_texture_us,remote_step_us,"
      "passivity_removed_n,device_fx_M,device_fy_M,device_fz_M\n",
      f);
}

long WriteTraceRow(std::FILE* f, const TraceRow& r, const std::vector<std::string>& phases) {
  const glm::dvec3 rv = RotationVectorFromQuaternion(r.X_WT.rotation);
  const glm::dvec3& p = r.X_WT.translation;
  const char* phase = r.phase >= 0 && r.phase < static_cast<int>(phases.size())
                          ? phases[r.phase].c_str()
                          : "unknown";
  const int n = std::fprintf(
      f,
      "%.6f,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%.4f,"
      "%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.2f,%.2f,%.2f,%.2f,%.6g,%.6g,%.6g,%.6g\n",
      r.t_s, phase, p.x, p.y, p.z, rv.x, rv.y, rv.z, r.F_contact_T_W.force.x,
      r.F_contact_T_W.force.y, r.F_contact_T_W.force.z, r.F_contact_T_W.torque.x,
      r.F_contact_T_W.torque.y, r.F_contact_T_W.torque.z, r.contacts, r.model_age_ms, r.p_WH.x,
      r.p_WH.y, r.p_WH.z, r.F_H_W.force.x, r.F_H_W.force.y, r.F_H_W.force.z, r.F_H_W.torque.x,
      r.F_H_W.torque.y, r.F_H_W.torque.z, r.depth_m, static_cast<double>(r.tick_compute_us),
      static_cast<double>(r.remote_collision_us), static_cast<double>(r.remote_texture_us),
      static_cast<double>(r.remote_step_us), r.passivity_removed_n, r.f_H_M.x, r.f_H_M.y,
      r.f_H_M.z);
  return n < 0 ? 0 : n;
}

}  // namespace ht::station
