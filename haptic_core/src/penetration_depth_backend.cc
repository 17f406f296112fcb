#include "haptic_core/penetration_depth_backend.h"

namespace ht {

bool CpuPenetrationDepthBackend::LinearizeBatch(const HapticModel& tool, const RigidTransform& X_WT,
                                                std::span<const ContactQuery> queries,
                                                std::span<ContactLinearization> out,
                                                std::span<DepthSample> samples_out) noexcept {
  if (out.size() < queries.size()) return false;
  const bool want_samples = samples_out.size() >= queries.size() * kGradientSamples;
  for (size_t i = 0; i < queries.size(); ++i) {
    const ContactQuery& q = queries[i];
    out[i] =
        solver_.Linearize(tool, X_WT, *q.environment, q.X_WO, q.window, q.stiffness_n_per_m,
                          want_samples ? samples_out.subspan(i * kGradientSamples, kGradientSamples)
                                       : std::span<DepthSample>{});
  }
  return true;
}

}  // namespace ht
