// Stage 5 of the remote step (contact_linearization.h): a contact's linearization from its
// eleven depth samples (central differences, the lever form), the gradient sample poses, the
// kink planes, and the rotation gradient's names.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_linearization.h"

namespace ht {

int AddKinkPlanes(const ContactWindow& w, std::span<const DepthSample> samples,
                  const glm::dvec3& p_WT, ContactLinearization& lin, bool own_slope,
                  bool hang_other_arm) noexcept {
  lin.num_kink_planes = std::clamp(lin.num_kink_planes, 0, kMaxKinkPlanes);
  if (samples.size() < static_cast<std::size_t>(kGradientSamples) || !std::isfinite(lin.depth_m) ||
      samples[0].cell < 0) {
    return lin.num_kink_planes;
  }
  const double h = GradientSteps::For(w).h_theta;
  const glm::dvec3& J_x = lin.gradient.d_translation_W;
  // The slope about axis a of the depth of cell c: its lever r_c × ∂δ/∂x along a.
  const auto slope = [&](int cell, const glm::dvec3& a) {
    return glm::dot(glm::cross(w.CellCenter(cell) - p_WT, J_x), a);
  };
  const glm::dvec3 axes[2] = {w.axis_u_W, w.axis_v_W};
  bool kinked[2] = {false, false};
  double arm_slope[2][2] = {{0.0, 0.0}, {0.0, 0.0}};  // [axis][plus, minus]
  for (int a = 0; a < 2; ++a) {
    // Samples 5, 6: ±h_θ about u; 7, 8: about v (GradientSamplePoses).
    const DepthSample& plus = samples[static_cast<std::size_t>(5 + 2 * a)];
    const DepthSample& minus = samples[static_cast<std::size_t>(6 + 2 * a)];
    if (plus.cell < 0 || minus.cell < 0 || plus.cell == minus.cell) continue;
    arm_slope[a][0] = slope(plus.cell, axes[a]);
    arm_slope[a][1] = slope(minus.cell, axes[a]);
    // A V: tilted either way, the deepest cell is one that rises with that tilt (a resting face
    // whose two edges bear in turn). Elsewhere the secant of the samples stays.
    kinked[a] = arm_slope[a][0] > 0.0 && arm_slope[a][1] < 0.0;
  }
  // At q0 the deepest cell's own slope is the gradient along a kinked axis: the secant across the
  // V's vertex reads the two arms' mean. Only where the deepest cell bears like one of the arms
  // (its slope within 10 % of that arm's: a sharp V, tilted by h_θ the face still bears on the
  // same edge); on a rounded contact the deepest cell moves with any tilt, and its single cell's
  // slope is the noisier estimate. bearing[a]: the arm it bears like (0: plus, 1: minus), or −1.
  glm::dvec3 d_rotation = lin.gradient.d_rotation_W;
  int bearing[2] = {-1, -1};
  for (int a = 0; a < 2 && own_slope; ++a) {
    if (!kinked[a]) continue;
    const double s0 = slope(samples[0].cell, axes[a]);
    if (!std::isfinite(s0)) continue;
    const double off_plus = std::abs(s0 - arm_slope[a][0]) / std::abs(arm_slope[a][0]);
    const double off_minus = std::abs(s0 - arm_slope[a][1]) / std::abs(arm_slope[a][1]);
    if (!(std::min(off_plus, off_minus) <= 0.1)) continue;
    bearing[a] = off_plus <= off_minus ? 0 : 1;
    d_rotation += (s0 - glm::dot(d_rotation, axes[a])) * axes[a];
  }
  // The planes already held share the contact's rotation slope.
  for (int m = 0; m < lin.num_kink_planes; ++m) {
    lin.kink_planes[static_cast<std::size_t>(m)].d_rotation_W +=
        d_rotation - lin.gradient.d_rotation_W;
  }
  lin.gradient.d_rotation_W = d_rotation;
  for (int a = 0; a < 2; ++a) {
    if (!kinked[a]) continue;
    // Each arm at q0: A± = δ(±h_θ) ∓ h_θ·s±, its plane through its sample (m).
    const double arm_at_q0[2] = {
        samples[static_cast<std::size_t>(5 + 2 * a)].depth_m - h * arm_slope[a][0],
        samples[static_cast<std::size_t>(6 + 2 * a)].depth_m + h * arm_slope[a][1]};
    for (int side = 0; side < 2 && lin.num_kink_planes < kMaxKinkPlanes; ++side) {
      KinkPlane p;
      p.d_rotation_W = d_rotation + (arm_slope[a][side] - glm::dot(d_rotation, axes[a])) * axes[a];
      if (hang_other_arm && bearing[a] >= 0) {
        if (side == bearing[a]) continue;  // the contact's own plane
        // The other arm below δ0 by the arms' gap at q0 (none where it reads deeper: a tie): the
        // V's shape from its two samples, hung from δ0, so that the arms tie where the samples'
        // arms cross. Each A alone is off by its lever's error times h_θ.
        p.depth_m = lin.depth_m - std::max(arm_at_q0[bearing[a]] - arm_at_q0[side], 0.0);
      } else {
        // The contact's own plane already.
        if (samples[static_cast<std::size_t>(5 + 2 * a + side)].cell == samples[0].cell) continue;
        // Through the sample: δ_m(q0 ⊕ ±h_θ·a) = δ(±h_θ); never above δ0 at q0.
        p.depth_m = std::min(arm_at_q0[side], lin.depth_m);
      }
      if (!std::isfinite(p.depth_m) || !std::isfinite(p.d_rotation_W.x) ||
          !std::isfinite(p.d_rotation_W.y) || !std::isfinite(p.d_rotation_W.z)) {
        continue;
      }
      lin.kink_planes[static_cast<std::size_t>(lin.num_kink_planes++)] = p;
    }
  }
  return lin.num_kink_planes;
}

const char* ToString(RotationGradient r) noexcept {
  switch (r) {
    case RotationGradient::kRenderedSamples:
      return "rendered";
    case RotationGradient::kContactLever:
      return "lever";
    case RotationGradient::kWarpedBaseRender:
      return "warp";
  }
  return "?";
}

RotationGradient ParseRotationGradient(const std::string& text) {
  for (const RotationGradient r :
       {RotationGradient::kRenderedSamples, RotationGradient::kContactLever,
        RotationGradient::kWarpedBaseRender}) {
    if (text == ToString(r)) return r;
  }
  throw std::invalid_argument("rotation gradient must be rendered, lever or warp, got '" + text +
                              "'");
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

ContactLinearization AssembleLeverLinearization(const ContactWindow& w,
                                                std::span<const DepthSample> samples,
                                                const glm::dvec3& r_W, double stiffness_n_per_m,
                                                LinearizationFaults& faults) noexcept {
  ContactLinearization out;
  if (!StartLinearization(w, samples, 5, stiffness_n_per_m, out)) return out;
  const Differences d{w, samples, faults};
  out.gradient.d_translation_W = d.Translation(GradientSteps::For(w).h_x);
  // The tool point p moves by Δx + Δθ × r: δ changes by ∂δ/∂x·(Δθ × r) = (r × ∂δ/∂x)·Δθ.
  out.gradient.d_rotation_W = glm::cross(r_W, out.gradient.d_translation_W);
  return out;
}

}  // namespace ht
