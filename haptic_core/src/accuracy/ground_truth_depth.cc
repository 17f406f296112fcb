#include "haptic_core/accuracy/ground_truth_depth.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace ht {

// ------------------------------------------------------------------------------------------------
// RayCastSurface

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

RayCastSurface::RayCastSurface(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>()) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    throw std::invalid_argument("RayCastSurface: empty mesh");
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
    vb[3 * i] = static_cast<float>(mesh.vertices[i].x);
    vb[3 * i + 1] = static_cast<float>(mesh.vertices[i].y);
    vb[3 * i + 2] = static_cast<float>(mesh.vertices[i].z);
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

// ------------------------------------------------------------------------------------------------
// GroundTruthDepthSolver

void GroundTruthOptions::Validate() const {
  if (initial_samples < 2 || initial_samples > 8192) {
    throw std::invalid_argument("ground truth: initial_samples must be in [2, 8192], got " +
                                std::to_string(initial_samples));
  }
  if (max_samples < initial_samples || max_samples > 8192) {
    throw std::invalid_argument(
        "ground truth: max_samples must be in [initial_samples, 8192], got " +
        std::to_string(max_samples));
  }
  if (!(tolerance_m > 0.0) || !(refine_step_m > 0.0) || refine_seeds < 0) {
    throw std::invalid_argument(
        "ground truth: tolerance and refine step must be positive, refine_seeds >= 0");
  }
}

GroundTruthDepthSolver::GroundTruthDepthSolver(const RayCastSurface& tool_F,
                                               const RayCastSurface& environment_F,
                                               const GroundTruthOptions& options)
    : tool_(tool_F), environment_(environment_F), options_(options) {
  options_.Validate();
}

void GroundTruthDepthSolver::SetPoses(const RigidTransform& X_WFt, const RigidTransform& X_WFe,
                                      const ContactWindow& w) noexcept {
  const RigidTransform X_FtW = X_WFt.Inverse();
  const RigidTransform X_FeW = X_WFe.Inverse();
  c_t_ = X_FtW * w.center_W;
  u_t_ = X_FtW.rotation * w.axis_u_W;
  v_t_ = X_FtW.rotation * w.axis_v_W;
  n_t_ = X_FtW.rotation * w.normal_W;
  c_e_ = X_FeW * w.center_W;
  u_e_ = X_FeW.rotation * w.axis_u_W;
  v_e_ = X_FeW.rotation * w.axis_v_W;
  n_e_ = X_FeW.rotation * w.normal_W;
  range_m_ = w.depth_range_m();
}

bool GroundTruthDepthSolver::ProbeEnvironment(double s, double t, double& b) noexcept {
  // From +R along −n: the first surface facing the ray faces +n, and it is the highest one.
  ++rays_;
  const glm::dvec3 org = c_e_ + s * u_e_ + t * v_e_ + range_m_ * n_e_;
  const double hit = environment_.FirstFacingHit(org, -n_e_, 2.0 * range_m_);
  if (hit < 0.0) return false;
  b = range_m_ - hit;
  return true;
}

bool GroundTruthDepthSolver::ProbeTool(double s, double t, double& a) noexcept {
  // From −R along +n: the first surface facing the ray faces −n, and it is the lowest one.
  ++rays_;
  const glm::dvec3 org = c_t_ + s * u_t_ + t * v_t_ - range_m_ * n_t_;
  const double hit = tool_.FirstFacingHit(org, n_t_, 2.0 * range_m_);
  if (hit < 0.0) return false;
  a = hit - range_m_;
  return true;
}

GroundTruthDepthSolver::Sample GroundTruthDepthSolver::Probe(double s, double t) noexcept {
  Sample out;
  out.hit_b = ProbeEnvironment(s, t, out.b);
  if (out.hit_b) out.hit_a = ProbeTool(s, t, out.a);
  return out;
}

GroundTruthDepth GroundTruthDepthSolver::DepthAt(const RigidTransform& X_WFt,
                                                 const RigidTransform& X_WFe,
                                                 const ContactWindow& w, int m) {
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  m = std::clamp(m, 2, 8192);
  const long long rays_before = rays_;
  SetPoses(X_WFt, X_WFe, w);
  const double half = 0.5 * w.extent_m;
  const double cell = w.extent_m / m;
  const auto coord = [&](int i) { return ((i + 0.5) / m - 0.5) * w.extent_m; };

  // The environment's heights on this grid, reused while neither the window nor its pose changes.
  const EnvKey key{m, c_e_, u_e_, v_e_, w.extent_m};
  if (!(key == env_key_) || env_b_.size() != static_cast<std::size_t>(m) * m) {
    env_b_.assign(static_cast<std::size_t>(m) * m, 0.0);
    env_hit_.assign(static_cast<std::size_t>(m) * m, 0);
    for (int j = 0; j < m; ++j) {
      for (int i = 0; i < m; ++i) {
        double b = 0.0;
        env_hit_[j * m + i] = ProbeEnvironment(coord(i), coord(j), b) ? 1 : 0;
        env_b_[j * m + i] = b;
      }
    }
    env_key_ = key;
  }

  // Grid pass: δ per cell, and the best cells as seeds for the refinement.
  struct Seed {
    double d;
    double s, t;
  };
  std::vector<Seed> seeds;
  const int k = options_.refine_seeds;
  seeds.reserve(static_cast<std::size_t>(k) + 1);
  GroundTruthDepth out;
  out.depth_m = kNone;
  out.samples_per_side = m;
  for (int j = 0; j < m; ++j) {
    for (int i = 0; i < m; ++i) {
      if (!env_hit_[j * m + i]) continue;
      double a = 0.0;
      if (!ProbeTool(coord(i), coord(j), a)) continue;
      const double d = env_b_[j * m + i] - a;
      if (d > out.depth_m) {
        out.depth_m = d;
        out.at_uv_m = {coord(i), coord(j)};
      }
      if (k > 0 && (static_cast<int>(seeds.size()) < k || d > seeds.back().d)) {
        Seed sd{d, coord(i), coord(j)};
        auto it = std::upper_bound(seeds.begin(), seeds.end(), sd,
                                   [](const Seed& x, const Seed& y) { return x.d > y.d; });
        seeds.insert(it, sd);
        if (static_cast<int>(seeds.size()) > k) seeds.pop_back();
      }
    }
  }

  // Local refinement: compass search from each seed, halving the step down to refine_step_m.
  const auto eval = [&](double s, double t) {
    if (std::abs(s) > half || std::abs(t) > half) return kNone;
    const Sample p = Probe(s, t);
    return p.hit_a && p.hit_b ? p.b - p.a : kNone;
  };
  for (const Seed& seed : seeds) {
    double s = seed.s, t = seed.t, best = seed.d, h = 0.5 * cell;
    for (int iter = 0; iter < 400 && h >= options_.refine_step_m; ++iter) {
      static constexpr std::array<std::array<int, 2>, 8> kDirs{
          {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {1, 1}, {1, -1}, {-1, 1}, {-1, -1}}};
      bool moved = false;
      for (const auto& d : kDirs) {
        const double ns = s + d[0] * h, nt = t + d[1] * h;
        const double v = eval(ns, nt);
        if (v > best) {
          best = v;
          s = ns;
          t = nt;
          moved = true;
        }
      }
      if (!moved) h *= 0.5;
    }
    if (best > out.depth_m) {
      out.depth_m = best;
      out.at_uv_m = {s, t};
    }
  }
  out.rays = rays_ - rays_before;
  return out;
}

GroundTruthDepth GroundTruthDepthSolver::ConvergedDepth(const RigidTransform& X_WFt,
                                                        const RigidTransform& X_WFe,
                                                        const ContactWindow& w) {
  int m = options_.initial_samples;
  GroundTruthDepth prev = DepthAt(X_WFt, X_WFe, w, m);
  long long rays = prev.rays;
  while (true) {
    const int next = std::min(2 * m, options_.max_samples);
    if (next == m) {  // no finer grid allowed: not converged (unless nothing overlaps)
      prev.converged = std::isinf(prev.depth_m) && prev.depth_m < 0.0;
      prev.rays = rays;
      return prev;
    }
    m = next;
    GroundTruthDepth cur = DepthAt(X_WFt, X_WFe, w, m);
    rays += cur.rays;
    const bool both_empty = std::isinf(cur.depth_m) && std::isinf(prev.depth_m);
    cur.change_m = both_empty ? 0.0 : std::abs(cur.depth_m - prev.depth_m);
    if (std::isnan(cur.change_m)) cur.change_m = std::numeric_limits<double>::infinity();
    if (both_empty || cur.change_m < options_.tolerance_m) {
      cur.converged = true;
      cur.rays = rays;
      return cur;
    }
    prev = cur;
  }
}

GroundTruthContact GroundTruthDepthSolver::Linearize(const RigidTransform& X_WT,
                                                     const RigidTransform& X_TFt,
                                                     const RigidTransform& X_WFe,
                                                     const ContactWindow& window,
                                                     double stiffness_n_per_m, int step_resolution,
                                                     double tilt_step_rad) {
  ContactWindow w = window;
  // The seed's grid fixes the step table for every method compared, unless the caller sets it.
  w.resolution = step_resolution > 0 ? step_resolution : 50;
  const GradientSteps table = GradientSteps::For(w);
  const double h_tilt = tilt_step_rad > 0.0 ? tilt_step_rad : table.h_theta;
  // The tilts (samples 5-8) at h_tilt, the yaw (9, 10) at the table's h_θ.
  std::array<RigidTransform, kGradientSamples> poses =
      GradientSamplePoses(X_WT, w, {table.h_x, h_tilt});
  const std::array<RigidTransform, kGradientSamples> table_poses = GradientSamplePoses(X_WT, w);
  poses[9] = table_poses[9];
  poses[10] = table_poses[10];
  GroundTruthContact out;
  out.base = ConvergedDepth(poses[0] * X_TFt, X_WFe, w);
  long long rays = out.base.rays;
  std::array<DepthSample, kGradientSamples> samples;
  samples[0] = {out.base.depth_m, std::isfinite(out.base.depth_m) ? 0 : -1};
  for (int i = 1; i < kGradientSamples; ++i) {
    const GroundTruthDepth d = DepthAt(poses[i] * X_TFt, X_WFe, w, out.base.samples_per_side);
    rays += d.rays;
    samples[i] = {d.depth_m, std::isfinite(d.depth_m) ? 0 : -1};
  }
  LinearizationFaults faults;
  out.linearization = AssembleLinearization(w, samples, table.h_x, h_tilt, table.h_theta,
                                            stiffness_n_per_m, faults);
  out.linearization.point_W =
      w.center_W + out.base.at_uv_m.x * w.axis_u_W + out.base.at_uv_m.y * w.axis_v_W;
  out.F_T_W =
      PenaltyWrench(out.linearization.depth_m, out.linearization.gradient, stiffness_n_per_m);
  out.rays = rays;
  return out;
}

}  // namespace ht
