#include "haptic_core/accuracy/fcl_mesh.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace ht {

std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> MakeFclMesh(const TriangleMesh& mesh,
                                                         const char* what) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    throw std::invalid_argument(std::string(what) + " mesh is empty");
  }
  const int nv = static_cast<int>(mesh.vertices.size());
  std::vector<fcl::Vector3d> v;
  v.reserve(mesh.vertices.size());
  for (const glm::dvec3& p : mesh.vertices) v.emplace_back(p.x, p.y, p.z);
  std::vector<fcl::Triangle> t;
  t.reserve(mesh.triangles.size());
  for (const glm::ivec3& f : mesh.triangles) {
    if (f.x < 0 || f.y < 0 || f.z < 0 || f.x >= nv || f.y >= nv || f.z >= nv) {
      throw std::invalid_argument(std::string(what) + " mesh has a vertex index out of range");
    }
    t.emplace_back(f.x, f.y, f.z);
  }
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  bvh->beginModel(static_cast<int>(t.size()), nv);
  bvh->addSubModel(v, t);
  bvh->endModel();
  return bvh;
}

fcl::Transform3d ToFcl(const RigidTransform& X) {
  fcl::Transform3d T = fcl::Transform3d::Identity();
  T.linear() =
      fcl::Quaterniond(X.rotation.w, X.rotation.x, X.rotation.y, X.rotation.z).toRotationMatrix();
  T.translation() = fcl::Vector3d(X.translation.x, X.translation.y, X.translation.z);
  return T;
}

}  // namespace ht
