#include "haptic_core/ray_cast_surface.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/penetration_depth.h"  // kPatchFacingThreshold

namespace ht {

struct RayCastSurface::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  // Unit face normals in F (zero for degenerate triangles), read by the intersection filter.
  std::vector<glm::vec3> face_normals_F;
  std::size_t triangles = 0;

  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
  void Check(const char* what) const {
    const RTCError err = rtcGetDeviceError(device);
    if (err != RTC_ERROR_NONE) {
      throw std::runtime_error(std::string("RayCastSurface: Embree error ") +
                               std::to_string(static_cast<int>(err)) + " after " + what);
    }
  }
};

namespace {

// The intersect context extended with the query's mode (Embree 3 passes the context to the
// filter, so a query may widen what the filter accepts).
struct ModeContext {
  RTCIntersectContext context;
  bool accept_every_hit = false;
};

// Embree intersection filter: a hit counts only where its triangle faces the ray, with the
// method's facing threshold (penetration_depth.h). Rejected hits let traversal go on to the next.
void FacingFilter(const RTCFilterFunctionNArguments* args) {
  if (reinterpret_cast<const ModeContext*>(args->context)->accept_every_hit) return;
  const auto* normals = static_cast<const glm::vec3*>(args->geometryUserPtr);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] != -1) continue;
    const unsigned prim = RTCHitN_primID(args->hit, args->N, i);
    const glm::vec3& n = normals[prim];
    const float d = n.x * RTCRayN_dir_x(args->ray, args->N, i) +
                    n.y * RTCRayN_dir_y(args->ray, args->N, i) +
                    n.z * RTCRayN_dir_z(args->ray, args->N, i);
    if (!(d < -static_cast<float>(kPatchFacingThreshold))) args->valid[i] = 0;
  }
}

}  // namespace

RayCastSurface::RayCastSurface(const TriangleMesh& mesh, const glm::dvec3& origin)
    : impl_(std::make_unique<Impl>()) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    throw std::invalid_argument("RayCastSurface: empty mesh");
  }
  if (!std::isfinite(origin.x) || !std::isfinite(origin.y) || !std::isfinite(origin.z)) {
    throw std::invalid_argument("RayCastSurface: non-finite origin");
  }
  const int nv = static_cast<int>(mesh.vertices.size());
  for (const glm::dvec3& p : mesh.vertices) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      throw std::invalid_argument("RayCastSurface: non-finite vertex");
    }
  }
  impl_->triangles = mesh.triangles.size();
  impl_->face_normals_F.resize(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const glm::ivec3 t = mesh.triangles[f];
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || t[c] >= nv) {
        throw std::invalid_argument("RayCastSurface: triangle " + std::to_string(f) +
                                    " has vertex index " + std::to_string(t[c]) + " out of [0, " +
                                    std::to_string(nv) + ")");
      }
    }
    const glm::dvec3 n = glm::cross(mesh.vertices[t[1]] - mesh.vertices[t[0]],
                                    mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    const double len = glm::length(n);
    impl_->face_normals_F[f] = len > 0.0 ? glm::vec3(n / len) : glm::vec3(0.0f);
  }
  impl_->device = rtcNewDevice(nullptr);
  if (impl_->device == nullptr) throw std::runtime_error("RayCastSurface: rtcNewDevice failed");
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.vertices.size()));
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                            RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                            mesh.triangles.size()));
  if (vb == nullptr || ib == nullptr) {
    rtcReleaseGeometry(geom);
    impl_->Check("rtcSetNewGeometryBuffer");
    throw std::runtime_error("RayCastSurface: Embree buffer allocation failed");
  }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const glm::dvec3 p = mesh.vertices[i] - origin;
    vb[3 * i] = static_cast<float>(p.x);
    vb[3 * i + 1] = static_cast<float>(p.y);
    vb[3 * i + 2] = static_cast<float>(p.z);
  }
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int c = 0; c < 3; ++c) ib[3 * f + c] = static_cast<unsigned>(mesh.triangles[f][c]);
  }
  rtcSetGeometryUserData(geom, impl_->face_normals_F.data());
  rtcSetGeometryIntersectFilterFunction(geom, &FacingFilter);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(impl_->scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(impl_->scene);
  impl_->Check("rtcCommitScene");
}

RayCastSurface::~RayCastSurface() = default;

std::size_t RayCastSurface::triangle_count() const noexcept { return impl_->triangles; }

namespace {

RTCRayHit MakeRay(const glm::dvec3& org, const glm::dvec3& dir, double tfar) noexcept {
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(org.x);
  rh.ray.org_y = static_cast<float>(org.y);
  rh.ray.org_z = static_cast<float>(org.z);
  rh.ray.tnear = 0.0f;
  rh.ray.dir_x = static_cast<float>(dir.x);
  rh.ray.dir_y = static_cast<float>(dir.y);
  rh.ray.dir_z = static_cast<float>(dir.z);
  rh.ray.time = 0.0f;
  rh.ray.tfar = static_cast<float>(tfar);
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

}  // namespace

double RayCastSurface::FirstHit(const glm::dvec3& org, const glm::dvec3& dir,
                                double tfar) const noexcept {
  ModeContext mode;
  rtcInitIntersectContext(&mode.context);
  mode.accept_every_hit = true;
  RTCRayHit rh = MakeRay(org, dir, tfar);
  rtcIntersect1(impl_->scene, &mode.context, &rh);
  return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1.0 : static_cast<double>(rh.ray.tfar);
}

double RayCastSurface::FirstFacingHit(const glm::dvec3& org, const glm::dvec3& dir,
                                      double tfar) const noexcept {
  ModeContext mode;
  rtcInitIntersectContext(&mode.context);
  RTCRayHit rh = MakeRay(org, dir, tfar);
  rtcIntersect1(impl_->scene, &mode.context, &rh);
  return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1.0 : static_cast<double>(rh.ray.tfar);
}

bool RayCastSurface::IsInside(const glm::dvec3& p, const glm::dvec3& dir) const noexcept {
  ModeContext mode;
  rtcInitIntersectContext(&mode.context);
  mode.accept_every_hit = true;
  RTCRayHit rh = MakeRay(p, dir, std::numeric_limits<float>::infinity());
  rtcIntersect1(impl_->scene, &mode.context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  const glm::vec3& n = impl_->face_normals_F[rh.hit.primID];
  return n.x * dir.x + n.y * dir.y + n.z * dir.z > 0.0;
}

}  // namespace ht
