#pragma once
// A baseline a user might pick instead of haptic textures: contact between the
// FULL-RESOLUTION triangle meshes through FCL (BVH of OBBRSS, all contacts with penetration depth
// and normal), rendered as a penalty force Σ k·d·n over the contacts. Used by the speed-vs-error
// frontier; also the full-resolution proximity check that counts contacts a method misses.

#include <memory>

#include "haptic_core/haptic_model.h"
#include "haptic_core/spatial.h"

namespace ht {

/// What one FCL query on the full-resolution meshes gave.
struct MeshContactResult {
  /// Σ over FCL contacts of the penalty k·d pushing the tool out along each contact normal, on
  /// the tool at its centre of mass, in W (N, N·m).
  Wrench F_T_W;
  /// FCL contacts (intersecting triangle pairs), and the largest penetration depth among them (m).
  int contacts = 0;
  double max_depth_m = 0.0;
  /// True when the two surfaces intersect anywhere.
  bool in_contact = false;
  /// Wall time of the FCL query (µs).
  double query_us = 0.0;
};

/// FCL contact between two full-resolution meshes. Not thread-safe (FCL's objects are mutated by
/// queries): one per thread.
class MeshContactBaseline {
 public:
  /// Builds FCL's BVH over both meshes, each in its own file frame F (#V vertices, #F triangles,
  /// metres). Throws std::invalid_argument for an empty mesh or an index out of range.
  MeshContactBaseline(const TriangleMesh& tool_Ft, const TriangleMesh& environment_Fe);
  ~MeshContactBaseline();
  MeshContactBaseline(const MeshContactBaseline&) = delete;
  MeshContactBaseline& operator=(const MeshContactBaseline&) = delete;

  /// Contacts with the tool mesh at X_WFt and the environment mesh at X_WFe (poses in W of the
  /// meshes' frames), penalty stiffness k (N/m), torque about the tool's centre of mass p_WTcm
  /// (m, in W). At most `max_contacts` FCL contacts are gathered.
  MeshContactResult Query(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                          double stiffness_n_per_m, const glm::dvec3& p_WTcm,
                          int max_contacts = 100000) const;

  /// True when the two meshes intersect at these poses (FCL's first-contact test, no contact
  /// data): the full-resolution proximity check.
  bool Intersects(const RigidTransform& X_WFt, const RigidTransform& X_WFe) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ht
