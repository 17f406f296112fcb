#pragma once
// FCL's view of a full-resolution mesh, shared by the accuracy tools (internal to
// haptic_accuracy): the BVH over a TriangleMesh and a pose in FCL's transform.

#include <fcl/fcl.h>

#include <memory>

#include "haptic_core/haptic_model.h"
#include "haptic_core/spatial.h"

namespace ht::accuracy_detail {

/// FCL's OBBRSS hierarchy over `mesh` (frame F, metres). Throws std::invalid_argument naming
/// `what` for an empty mesh or a vertex index out of range.
std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> MakeFclMesh(const TriangleMesh& mesh,
                                                         const char* what);

/// X as FCL's isometry.
fcl::Transform3d ToFcl(const RigidTransform& X);

}  // namespace ht::accuracy_detail
