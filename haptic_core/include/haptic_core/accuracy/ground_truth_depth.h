#pragma once
// Ground truth for the speed-vs-error study: the directional penetration depth of one
// contact window computed on the FULL-RESOLUTION meshes of both objects by dense ray casting
// (Embree 3), with the same facing and box rules as the method (penetration_depth.h), its
// gradient by central differences at the method's sample poses (GradientSamplePoses, step table
// of the seed's 50×50 grid), and the penalty wrench Φ_gt = −k δ_gt ∇δ_gt.
//
// The method (DESIGN.md §4, [L]): δ = max over window samples covered by both patches of (b − a),
// b the highest surface of the environment facing +n, a the lowest surface of the tool facing −n,
// both within ±R of the window plane along n. Here b and a are found exactly per sample by a ray
// along ∓n that accepts only surfaces facing it (unit face normal · ray direction <
// −kPatchFacingThreshold), so the only approximation left is where the samples are: an M×M grid
// of cell centres, refined locally around its best cells (a pattern search that halves its step
// down to 10 nm), with M doubled until δ changes by less than a tolerance.

#include <memory>
#include <vector>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/haptic_model.h"
#include "haptic_core/penetration_depth.h"
#include "haptic_core/ray_cast_surface.h"
#include "haptic_core/spatial.h"

namespace ht {

/// How hard the ground truth works for one window.
struct GroundTruthOptions {
  /// M of the first pass (samples per side of the window).
  int initial_samples = 64;
  /// Largest M tried; a window that has not converged by then is reported as such (measured:
  /// windows whose n is nearly parallel to the surfaces, where the overlap is a band thinner
  /// than a cell, go on changing; 512 costs 4× the rays of 256 there).
  int max_samples = 256;
  /// Converged when δ at M and at M/2 (each with local refinement) differ by less than this (m).
  double tolerance_m = 1e-7;
  /// Best cells of the grid from which the local refinement starts.
  int refine_seeds = 6;
  /// The refinement stops when its step falls below this (m).
  double refine_step_m = 1e-8;

  /// Throws std::invalid_argument naming a value out of range.
  void Validate() const;
};

/// δ_gt of one window at one pose.
struct GroundTruthDepth {
  /// δ_gt (m), signed like DepthSample::depth_m; −∞ when no sample is covered by both surfaces.
  double depth_m = 0.0;
  /// Where the maximum is, on the window plane: metres along u and v from the window centre.
  glm::dvec2 at_uv_m{0.0};
  /// M of the grid that gave it.
  int samples_per_side = 0;
  /// |δ(M) − δ(M/2)| (m) of the last doubling (0 when only one M was evaluated).
  double change_m = 0.0;
  /// True when change_m < tolerance (or both passes found no overlap).
  bool converged = false;
  /// Rays cast for it.
  long long rays = 0;
};

/// The ground truth of one contact: δ_gt and ∇δ_gt at the method's sample poses, and Φ_gt.
struct GroundTruthContact {
  /// depth_m = δ_gt at the base pose, gradient = ∇δ_gt (central differences with the step table
  /// of a 50×50 grid on this window, one-sided where a perturbed pose has no overlap), stiffness k,
  /// point_W where the maximum is, normal_W = n.
  ContactLinearization linearization;
  /// Φ_gt on the tool at its centre of mass, in W (N, N·m); zero when δ_gt ≤ 0.
  Wrench F_T_W;
  /// The base pose's convergence record (M, last change, converged).
  GroundTruthDepth base;
  /// Rays cast for all kGradientSamples poses.
  long long rays = 0;
};

/// The pressure law's truth on one window (depth_field.h, ForceLaw::kPressure, on the
/// full-resolution meshes): the overlap d = b − a along the window's normal n at the centres of
/// an M×M grid of cells of area A (b the environment's highest surface facing +n, a the tool's
/// lowest facing −n, as the depth's samples), and over the cells where d > 0 the sums the law
/// integrates: V = Σ A d and −∇U/k_p = −Σ A d ∇d, ∇d = (g, r × g) with g = b_u u + b_v v − n (the
/// environment's slope from its heights half a cell either side) and r the tool's surface point
/// less its centre of mass.
struct GroundTruthPressure {
  double volume_m3 = 0.0;
  /// −∇U / k_p on the tool at its centre of mass, in W (m³ and m⁴): the law's wrench per unit k_p.
  Wrench per_kp;
  /// M of the grid that gave it, the last doubling's relative change of the wrench (force against
  /// |F|, torque against |τ| + |F|·W/2), and whether that is within the tolerance.
  int samples_per_side = 0;
  double change = 0.0;
  bool converged = false;
  long long rays = 0;
};

/// Computes ground-truth penetration depths between one tool mesh and one environment mesh.
/// Holds no per-call state beyond scratch buffers: one solver per thread.
class GroundTruthDepthSolver {
 public:
  /// Keeps references to both surfaces, which must outlive the solver. Throws
  /// std::invalid_argument for bad options.
  GroundTruthDepthSolver(const RayCastSurface& tool_F, const RayCastSurface& environment_F,
                         const GroundTruthOptions& options = {});

  /// δ_gt on an M×M grid (M = `samples_per_side`, ≥ 2) with local refinement, the tool mesh posed
  /// at X_WFt and the environment mesh at X_WFe (poses in W of the meshes' own frames), over the
  /// window's W×W square (its resolution is ignored; its box is ±R = ±W along n).
  GroundTruthDepth DepthAt(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                           const ContactWindow& window, int samples_per_side);

  /// δ_gt with M doubled from options.initial_samples until it changes by less than
  /// options.tolerance_m (or M reaches options.max_samples).
  GroundTruthDepth ConvergedDepth(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                                  const ContactWindow& window);

  /// The ground truth of one contact of the method: the tool's frame T (its centre of mass) at
  /// X_WT, the tool mesh's frame at X_TFt in T, the environment mesh at X_WFe; `window` as the
  /// method built it (its resolution is replaced by the seed's 50 for the step table, so every
  /// method is compared with one truth); penalty stiffness k (N/m). M is chosen at the base pose
  /// (ConvergedDepth) and used for the 10 perturbed poses.
  /// `step_resolution` N' sets the step table instead (h_x = W/N', h_θ = h_x/(W/2); 0 = the seed's
  /// 50): the pipeline truth (contact_patch_truth.h) takes its steps at texel scale.
  /// `tilt_step_rad` > 0 sets the step of the tilts about u and v instead (the yaw about n keeps
  /// the table's h_θ): a tilt lifts points along n, by h·r at a lever r, so the table's h_θ
  /// (which lifts the window's edge by a whole h_x) rounds a resting face's V over ±h_θ
  /// (ContactPatchTruthOptions::tilt_lift_m).
  GroundTruthContact Linearize(const RigidTransform& X_WT, const RigidTransform& X_TFt,
                               const RigidTransform& X_WFe, const ContactWindow& window,
                               double stiffness_n_per_m, int step_resolution = 0,
                               double tilt_step_rad = 0.0);

  /// The pressure law's sums on `window` (GroundTruthPressure) on an M×M grid (M =
  /// `samples_per_side`, ≥ 2), the tool's centre of mass frame T at X_WT, its mesh at X_TFt in T,
  /// the environment's mesh at X_WFe.
  GroundTruthPressure PressureAt(const RigidTransform& X_WT, const RigidTransform& X_TFt,
                                 const RigidTransform& X_WFe, const ContactWindow& window,
                                 int samples_per_side);
  /// The same with M doubled from options.initial_samples until the wrench changes by less than
  /// `tolerance` (relative, GroundTruthPressure::change) or M reaches `max_samples`.
  GroundTruthPressure ConvergedPressure(const RigidTransform& X_WT, const RigidTransform& X_TFt,
                                        const RigidTransform& X_WFe, const ContactWindow& window,
                                        double tolerance, int max_samples);

 private:
  struct Sample {
    double b = 0.0, a = 0.0;
    bool hit_b = false, hit_a = false;
  };
  // Heights along n of both surfaces at window coordinates (s, t) (m from the centre along u, v).
  Sample Probe(double s, double t) noexcept;
  // b alone (the environment's height), for the grid cache.
  bool ProbeEnvironment(double s, double t, double& b) noexcept;
  bool ProbeTool(double s, double t, double& a) noexcept;
  void SetPoses(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                const ContactWindow& window) noexcept;

  const RayCastSurface& tool_;
  const RayCastSurface& environment_;
  GroundTruthOptions options_;
  // Set by SetPoses: the window's centre and axes in each mesh's frame.
  glm::dvec3 c_t_{0.0}, u_t_{0.0}, v_t_{0.0}, n_t_{0.0};
  glm::dvec3 c_e_{0.0}, u_e_{0.0}, v_e_{0.0}, n_e_{0.0};
  double range_m_ = 0.0;
  long long rays_ = 0;
  // The environment's heights on the last grid (the environment does not move between the
  // gradient's sample poses): valid for env_key_.
  struct EnvKey {
    int m = 0;
    glm::dvec3 c{0.0}, u{0.0}, v{0.0};
    double extent = 0.0;
    bool operator==(const EnvKey&) const = default;
  } env_key_;
  std::vector<double> env_b_;
  std::vector<unsigned char> env_hit_;
};

}  // namespace ht
