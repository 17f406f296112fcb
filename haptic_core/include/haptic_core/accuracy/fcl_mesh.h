#pragma once
// FCL's view of a mesh and a pose (haptic_accuracy): the BVH over a TriangleMesh and a pose in
// FCL's transform, for the accuracy tools' full-resolution baselines and the tests and benchmarks
// that compare the coarse query with FCL. Not installed (FCL is a build dependency of the study,
// not of the haptic core).

#include <fcl/fcl.h>

#include <memory>

#include "haptic_core/mesh.h"
#include "haptic_core/spatial.h"

namespace ht {

/// FCL's OBBRSS hierarchy over `mesh` (frame F, metres). Throws std::invalid_argument naming
/// `what` for an empty mesh or a vertex index out of range.
std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> MakeFclMesh(const TriangleMesh& mesh,
                                                         const char* what);

/// A pose X_AB (m, unit quaternion) as FCL's isometry between the same frames.
fcl::Transform3d ToFcl(const RigidTransform& X);

}  // namespace ht
