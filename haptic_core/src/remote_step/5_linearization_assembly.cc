// Stage 5 of the remote step (contact_linearization.h): a contact's linearization from its
// eleven depth samples (central differences, the lever form), the gradient sample poses, the
// bearing edge's rotation slope.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_linearization.h"

namespace ht {

void UseBearingEdgeRotationSlope(const ContactWindow& w, std::span<const DepthSample> samples,
                                 const glm::dvec3& p_WT, ContactLinearization& lin) noexcept {
  if (samples.size() < static_cast<std::size_t>(kGradientSamples) || !std::isfinite(lin.depth_m) ||
      samples[0].cell < 0) {
    return;
  }
  const glm::dvec3& J_x = lin.gradient.d_translation_W;
  // The slope about axis a of the depth of cell c: its lever r_c × ∂δ/∂x along a.
  const auto slope = [&](int cell, const glm::dvec3& a) {
    return glm::dot(glm::cross(w.CellCenter(cell) - p_WT, J_x), a);
  };
  const glm::dvec3 axes[2] = {w.axis_u_W, w.axis_v_W};
  glm::dvec3 d_rotation = lin.gradient.d_rotation_W;
  for (int a = 0; a < 2; ++a) {
    // Samples 5, 6: ±h_θ about u; 7, 8: about v (GradientSamplePoses).
    const DepthSample& plus = samples[static_cast<std::size_t>(5 + 2 * a)];
    const DepthSample& minus = samples[static_cast<std::size_t>(6 + 2 * a)];
    if (plus.cell < 0 || minus.cell < 0 || plus.cell == minus.cell) continue;
    const double arm_plus = slope(plus.cell, axes[a]);
    const double arm_minus = slope(minus.cell, axes[a]);
    // A V: tilted either way, the deepest cell is one that rises with that tilt.
    if (!(arm_plus > 0.0 && arm_minus < 0.0)) continue;
    const double s0 = slope(samples[0].cell, axes[a]);
    if (!std::isfinite(s0)) continue;
    const double off_plus = std::abs(s0 - arm_plus) / std::abs(arm_plus);
    const double off_minus = std::abs(s0 - arm_minus) / std::abs(arm_minus);
    // A sharp V: tilted by h_θ the face still bears on the same edge as at q0.
    if (!(std::min(off_plus, off_minus) <= 0.1)) continue;
    d_rotation += (s0 - glm::dot(d_rotation, axes[a])) * axes[a];
  }
  lin.gradient.d_rotation_W = d_rotation;
}

std::array<RigidTransform, kGradientSamples> GradientSamplePoses(const RigidTransform& X_WT,
                                                                 const ContactWindow& w) noexcept {
  return GradientSamplePoses(X_WT, w, GradientSteps::For(w));
}

std::array<RigidTransform, kGradientSamples> GradientSamplePoses(const RigidTransform& X_WT,
                                                                 const ContactWindow& w,
                                                                 const GradientSteps& h) noexcept {
  const glm::dvec3 u = w.axis_u_W, v = w.axis_v_W, n = w.normal_W, zero(0.0);
  const Twist steps[5] = {{h.h_x * u, zero},
                          {h.h_x * v, zero},
                          {zero, h.h_theta * u},
                          {zero, h.h_theta * v},
                          {zero, h.h_theta * n}};
  std::array<RigidTransform, kGradientSamples> poses;
  poses[0] = X_WT;
  for (int i = 0; i < 5; ++i) {
    poses[1 + 2 * i] = Displace(X_WT, steps[i]);
    poses[2 + 2 * i] = Displace(X_WT, {-steps[i].linear, -steps[i].angular});
  }
  return poses;
}

namespace {

// The central difference of samples 1 + 2i and 2 + 2i (one-sided, and counted in `faults`, where
// one of them has no overlap), and ∂δ/∂x from the first two: what the rendered and the lever
// linearizations share.
struct Differences {
  const ContactWindow& w;
  std::span<const DepthSample> samples;
  LinearizationFaults& faults;
  double Central(int i, double step) const noexcept {
    const DepthSample& base = samples[0];
    const DepthSample& plus = samples[1 + 2 * i];
    const DepthSample& minus = samples[2 + 2 * i];
    if (plus.cell >= 0 && minus.cell >= 0) return (plus.depth_m - minus.depth_m) / (2.0 * step);
    ++faults.missing_overlap;
    if (plus.cell >= 0) return (plus.depth_m - base.depth_m) / step;
    if (minus.cell >= 0) return (base.depth_m - minus.depth_m) / step;
    return 0.0;
  }
  // ∂δ/∂x: central differences along u and v; moving the tool along +n lifts every tool height
  // by the same amount, so ∂δ/∂x_n = −1 exactly.
  glm::dvec3 Translation(double h_x) const noexcept {
    return Central(0, h_x) * w.axis_u_W + Central(1, h_x) * w.axis_v_W - w.normal_W;
  }
};

// δ0, the point and the normal of a linearization from the base sample; false (depth_m = −∞ or
// the base's depth, no gradient) when `samples` is shorter than `needed` or the base has no
// overlap.
bool StartLinearization(const ContactWindow& w, std::span<const DepthSample> samples,
                        std::size_t needed, double stiffness_n_per_m,
                        ContactLinearization& out) noexcept {
  out.stiffness_n_per_m = stiffness_n_per_m;
  out.normal_W = w.normal_W;
  out.point_W = w.center_W;
  out.depth_m = -std::numeric_limits<double>::infinity();
  if (samples.size() < needed) return false;
  out.depth_m = samples[0].depth_m;
  if (samples[0].cell < 0) return false;
  out.point_W = w.CellCenter(samples[0].cell);
  return true;
}

}  // namespace

ContactLinearization AssembleLinearization(const ContactWindow& w,
                                           std::span<const DepthSample> samples,
                                           double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept {
  const GradientSteps h = GradientSteps::For(w);
  return AssembleLinearization(w, samples, h.h_x, h.h_theta, h.h_theta, stiffness_n_per_m, faults);
}

ContactLinearization AssembleLinearization(const ContactWindow& w,
                                           std::span<const DepthSample> samples, double h_x,
                                           double h_tilt, double h_yaw, double stiffness_n_per_m,
                                           LinearizationFaults& faults) noexcept {
  ContactLinearization out;
  if (!StartLinearization(w, samples, kGradientSamples, stiffness_n_per_m, out)) return out;
  const Differences d{w, samples, faults};
  out.gradient.d_translation_W = d.Translation(h_x);
  out.gradient.d_rotation_W = d.Central(2, h_tilt) * w.axis_u_W +
                              d.Central(3, h_tilt) * w.axis_v_W + d.Central(4, h_yaw) * w.normal_W;
  return out;
}

}  // namespace ht
