#include "haptic_core/accuracy/mesh_contact_baseline.h"

#include <fcl/fcl.h>

#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/accuracy/fcl_mesh.h"

namespace ht {

struct MeshContactBaseline::Impl {
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> tool, environment;
};

MeshContactBaseline::MeshContactBaseline(const TriangleMesh& tool_Ft,
                                         const TriangleMesh& environment_Fe)
    : impl_(std::make_unique<Impl>()) {
  impl_->tool = MakeFclMesh(tool_Ft, "full-resolution tool");
  impl_->environment = MakeFclMesh(environment_Fe, "full-resolution environment");
}

MeshContactBaseline::~MeshContactBaseline() = default;

MeshContactResult MeshContactBaseline::Query(const RigidTransform& X_WFt,
                                             const RigidTransform& X_WFe, double k,
                                             const glm::dvec3& p_WTcm, int max_contacts) const {
  MeshContactResult out;
  fcl::CollisionObjectd tool(impl_->tool, ToFcl(X_WFt));
  fcl::CollisionObjectd env(impl_->environment, ToFcl(X_WFe));
  fcl::CollisionRequestd request(static_cast<std::size_t>(std::max(max_contacts, 1)), true);
  fcl::CollisionResultd result;
  const auto t0 = std::chrono::steady_clock::now();
  fcl::collide(&tool, &env, request, result);
  const auto t1 = std::chrono::steady_clock::now();
  out.query_us = std::chrono::duration<double, std::micro>(t1 - t0).count();
  out.in_contact = result.isCollision();
  out.contacts = static_cast<int>(result.numContacts());
  for (std::size_t i = 0; i < result.numContacts(); ++i) {
    const fcl::Contactd& c = result.getContact(i);
    // FCL's normal points from o1 (the tool) to o2 (the environment): the penalty pushes the
    // tool the other way.
    const glm::dvec3 n(c.normal.x(), c.normal.y(), c.normal.z());
    const glm::dvec3 p(c.pos.x(), c.pos.y(), c.pos.z());
    const double d = c.penetration_depth;
    if (!std::isfinite(d) || !std::isfinite(n.x + n.y + n.z + p.x + p.y + p.z)) continue;
    const glm::dvec3 f = -k * d * n;
    out.F_T_W.force += f;
    out.F_T_W.torque += glm::cross(p - p_WTcm, f);
    out.max_depth_m = std::max(out.max_depth_m, d);
  }
  return out;
}

bool MeshContactBaseline::Intersects(const RigidTransform& X_WFt,
                                     const RigidTransform& X_WFe) const {
  fcl::CollisionObjectd tool(impl_->tool, ToFcl(X_WFt));
  fcl::CollisionObjectd env(impl_->environment, ToFcl(X_WFe));
  fcl::CollisionRequestd request(1, false);
  fcl::CollisionResultd result;
  fcl::collide(&tool, &env, request, result);
  return result.isCollision();
}

}  // namespace ht
