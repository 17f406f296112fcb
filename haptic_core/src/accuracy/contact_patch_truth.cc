#include "haptic_core/accuracy/contact_patch_truth.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "contact_patch_geometry.h"
#include "haptic_core/accuracy/fcl_mesh.h"
#include "haptic_core/connected_contacts.h"

namespace ht {

void ContactPatchTruthOptions::Validate() const {
  const auto fail = [](const std::string& what, double v) {
    throw std::invalid_argument("pipeline truth: " + what + ", got " + std::to_string(v));
  };
  if (!(merge_distance_m > 0.0) || !std::isfinite(merge_distance_m))
    fail("merge_distance_m must be > 0", merge_distance_m);
  if (!(max_normal_angle_deg >= 0.0 && max_normal_angle_deg < 180.0))
    fail("max_normal_angle_deg must be in [0, 180)", max_normal_angle_deg);
  if (!(window_margin_m >= 0.0) || !std::isfinite(window_margin_m))
    fail("window_margin_m must be >= 0", window_margin_m);
  if (!(min_extent_m > 0.0) || !(max_extent_m >= min_extent_m) || !std::isfinite(max_extent_m))
    fail("extents must satisfy 0 < min_extent_m <= max_extent_m", min_extent_m);
  if (!(gradient_step_m > 0.0) || !std::isfinite(gradient_step_m))
    fail("gradient_step_m must be > 0", gradient_step_m);
  if (!(tilt_lift_m >= 0.0) || !std::isfinite(tilt_lift_m))
    fail("tilt_lift_m must be >= 0", tilt_lift_m);
  if (!(inside_cell_m > 0.0) || !std::isfinite(inside_cell_m))
    fail("inside_cell_m must be > 0", inside_cell_m);
  if (!(boundary_cell_m > 0.0) || !(boundary_cell_m <= inside_cell_m))
    fail("boundary_cell_m must be in (0, inside_cell_m]", boundary_cell_m);
  if (max_pairs < 1) fail("max_pairs must be >= 1", max_pairs);
  if (!(pressure_tolerance >= 0.0 && pressure_tolerance < 1.0))
    fail("pressure_tolerance must be in [0, 1)", pressure_tolerance);
  if (pressure_max_samples < 2) fail("pressure_max_samples must be >= 2", pressure_max_samples);
  if (!(share_fade_m >= 0.0) || !std::isfinite(share_fade_m))
    fail("share_fade_m must be >= 0", share_fade_m);
  if (!(share_temperature_m > 0.0) || !std::isfinite(share_temperature_m))
    fail("share_temperature_m must be > 0", share_temperature_m);
  if (!(overlap_merge_angle_deg >= 0.0 && overlap_merge_angle_deg <= 180.0))
    fail("overlap_merge_angle_deg must be in [0, 180]", overlap_merge_angle_deg);
  if (!(macro_normal_radius_m >= 0.0) || !std::isfinite(macro_normal_radius_m))
    fail("macro_normal_radius_m must be >= 0", macro_normal_radius_m);
  if (!(minor_patch_fraction >= 0.0 && minor_patch_fraction < 1.0))
    fail("minor_patch_fraction must be in [0, 1)", minor_patch_fraction);
  depth.Validate();
}

namespace {

using patch_truth::CellGrid;
using patch_truth::EdgePiercings;
using patch_truth::Find;
using patch_truth::MeshTopology;
using patch_truth::SurfaceNormalGrid;

}  // namespace

namespace {

// An intersecting triangle pair of the full-resolution meshes at one pose.
struct Pair {
  int tool_tri, env_tri;
  glm::dvec3 p_W, n_W;  // midpoint of the centroids; environment normal
};

// A patch's geometry before its depth: the patch, ∇V, the macroscopic normal and the window side.
struct PatchGeometry {
  TruthPatch patch;
  glm::dvec3 dV_dx{0.0}, dV_dtheta{0.0};
  glm::dvec3 macro_normal{0.0};  // zero where undefined
  double extent = 0.0;
};

// One pose's state through ContactPatchTruth::At's steps.
struct PoseState {
  RigidTransform X_WT, X_TFt, X_WFe, X_WFt;
  double k = 0.0;
  PoseTruth out;
  std::vector<Pair> pairs;
  // Each pair's patch, the patches' count, and the pairs near each other whose fine normals
  // disagree (candidates for step 3a).
  std::vector<int> patch_of;
  int num_patches = 0;
  std::vector<std::pair<int, int>> split_neighbours;
  std::vector<PatchGeometry> geometries;
  long long geometry_rays = 0;
};

}  // namespace

struct ContactPatchTruth::Impl {
  TriangleMesh tool, environment;
  MeshTopology tool_topology, environment_topology;
  const RayCastSurface& tool_rays;
  const RayCastSurface& environment_rays;
  ContactPatchTruthOptions options;
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> tool_fcl, environment_fcl;
  GroundTruthDepthSolver solver;
  SurfaceNormalGrid tool_normals, environment_normals;
  // Per-triangle state of the current pose: 0 unseen, 1 crossing, 2 inside, 3 outside.
  std::vector<std::uint8_t> tool_state, environment_state;

  Impl(const TriangleMesh& t, const TriangleMesh& e, const RayCastSurface& tr,
       const RayCastSurface& er, const ContactPatchTruthOptions& o)
      : tool(t),
        environment(e),
        tool_topology(t),
        environment_topology(e),
        tool_rays(tr),
        environment_rays(er),
        options(o),
        tool_fcl(MakeFclMesh(t, "full-resolution tool")),
        environment_fcl(MakeFclMesh(e, "full-resolution environment")),
        solver(tr, er, o.depth),
        tool_normals(tool, tool_topology, o.macro_normal_radius_m),
        environment_normals(environment, environment_topology, o.macro_normal_radius_m) {}

  // What one side's inside surface adds to a patch.
  struct SideSums {
    double area = 0.0;
    glm::dvec3 sum_an_W{0.0}, sum_a_r_x_n_W{0.0}, sum_ap_W{0.0};
  };

  // The inside surface of one side of a patch: `mesh` posed at X_WF, its triangles `crossing`
  // (marked 1 in `state`), tested against the other solid `other` posed at X_WG along ray
  // direction `dir_W`. Appends inside points (W) to `points`.
  SideSums InsideSurface(const TriangleMesh& mesh, const MeshTopology& topo,
                         std::vector<std::uint8_t>& state, const std::vector<int>& crossing,
                         const RigidTransform& X_WF, const RayCastSurface& other,
                         const RigidTransform& X_WG, const glm::dvec3& dir_W,
                         const glm::dvec3& p_WTcm, std::vector<glm::dvec3>& points,
                         long long& rays) const {
    SideSums s;
    const RigidTransform X_GW = X_WG.Inverse();
    const glm::dvec3 dir_G = X_GW.rotation * dir_W;
    const auto inside = [&](const glm::dvec3& p_W) {
      ++rays;
      return other.IsInside(X_GW * p_W, dir_G);
    };
    const auto add = [&](const glm::dvec3& p_W, const glm::dvec3& n_W, double a) {
      s.area += a;
      s.sum_an_W += a * n_W;
      s.sum_a_r_x_n_W += a * glm::cross(p_W - p_WTcm, n_W);
      s.sum_ap_W += a * p_W;
    };
    std::vector<int> queue;
    const double forced2 = options.inside_cell_m * options.inside_cell_m;
    const double boundary2 = options.boundary_cell_m * options.boundary_cell_m;
    // A crossing triangle's inside part: sub-triangles are split in four until their longest edge
    // is at most inside_cell_m, then further only where their corners and centroid disagree,
    // down to boundary_cell_m, where the inside share of those four tests is taken.
    const auto refine = [&](auto&& self, const glm::dvec3& p0, const glm::dvec3& p1,
                            const glm::dvec3& p2, const glm::dvec3& n_W, double area) -> void {
      const double e2 = std::max(
          {glm::dot(p1 - p0, p1 - p0), glm::dot(p2 - p1, p2 - p1), glm::dot(p0 - p2, p0 - p2)});
      const auto split = [&] {
        const glm::dvec3 a = 0.5 * (p0 + p1), b = 0.5 * (p1 + p2), c = 0.5 * (p2 + p0);
        self(self, p0, a, c, n_W, 0.25 * area);
        self(self, a, p1, b, n_W, 0.25 * area);
        self(self, c, b, p2, n_W, 0.25 * area);
        self(self, a, b, c, n_W, 0.25 * area);
      };
      if (e2 > forced2) return split();
      const glm::dvec3 c = (p0 + p1 + p2) / 3.0;
      const int in = inside(p0) + inside(p1) + inside(p2) + inside(c);
      if (in == 0) return;
      if (in < 4 && e2 > boundary2) return split();
      add(c, n_W, area * in / 4.0);
      points.push_back(c);
    };
    for (const int f : crossing) {
      const glm::ivec3 t = mesh.triangles[f];
      refine(refine, X_WF * mesh.vertices[t[0]], X_WF * mesh.vertices[t[1]],
             X_WF * mesh.vertices[t[2]], X_WF.rotation * topo.normal_F[f], topo.area_m2[f]);
      queue.push_back(f);
    }
    // Flood fill: a triangle next to a crossing or inside one, crossing nothing, is wholly inside
    // or wholly outside; its centroid decides.
    while (!queue.empty()) {
      const int f = queue.back();
      queue.pop_back();
      for (const int g : topo.neighbours[f]) {
        if (g < 0 || state[g] != 0) continue;
        const glm::ivec3 t = mesh.triangles[g];
        const glm::dvec3 p0 = X_WF * mesh.vertices[t[0]], p1 = X_WF * mesh.vertices[t[1]],
                         p2 = X_WF * mesh.vertices[t[2]];
        const glm::dvec3 c = (p0 + p1 + p2) / 3.0;
        if (!inside(c)) {
          state[g] = 3;
          continue;
        }
        state[g] = 2;
        add(c, X_WF.rotation * topo.normal_F[g], topo.area_m2[g]);
        points.push_back(p0);
        points.push_back(p1);
        points.push_back(p2);
        queue.push_back(g);
      }
    }
    return s;
  }
  // ContactPatchTruth::At's steps on one pose's state, in order.
  // 1. Every intersecting triangle pair (false: none).
  bool FindIntersectingPairs(PoseState& s);
  // 2. Patches: single linkage of the pairs.
  void LinkPairsIntoPatches(PoseState& s);
  // 3. Each patch's geometry: inside surfaces, ∇V, direction, centre and window (no δ yet).
  std::vector<PatchGeometry> Geometries(PoseState& s, const std::vector<int>& patch_index,
                                        int count);
  // After merges: `root[q]` is the patch q joins; the patches renumbered, their geometry anew.
  void Regroup(PoseState& s, const std::vector<int>& root);
  // 3a. Neighbouring patches on one surface merged.
  void MergeNeighboursOnOneSurface(PoseState& s);
  // 3b. Patches that measure one interpenetration twice merged.
  void MergeDoubleCounted(PoseState& s);
  // 4. T1 on each patch's window.
  void LinearizePatches(PoseState& s);
  // 4a. Shares between neighbouring patches, then the pose's wrench.
  void SharePenalties(PoseState& s);
};

ContactPatchTruth::ContactPatchTruth(const TriangleMesh& tool_Ft,
                                     const TriangleMesh& environment_Fe,
                                     const RayCastSurface& tool_rays,
                                     const RayCastSurface& environment_rays,
                                     const ContactPatchTruthOptions& options) {
  options.Validate();
  impl_ = std::make_unique<Impl>(tool_Ft, environment_Fe, tool_rays, environment_rays, options);
}

ContactPatchTruth::~ContactPatchTruth() = default;

bool ContactPatchTruth::Impl::FindIntersectingPairs(PoseState& s) {
  Impl& m = *this;
  const ContactPatchTruthOptions& o = options;
  const RigidTransform& X_WFt = s.X_WFt;
  const RigidTransform& X_WFe = s.X_WFe;
  PoseTruth& out = s.out;
  std::vector<Pair>& pairs = s.pairs;
  fcl::CollisionObjectd tool_object(m.tool_fcl, ToFcl(X_WFt));
  fcl::CollisionObjectd env_object(m.environment_fcl, ToFcl(X_WFe));
  fcl::CollisionRequestd request(static_cast<std::size_t>(o.max_pairs), false);
  fcl::CollisionResultd result;
  fcl::collide(&tool_object, &env_object, request, result);
  const int np = static_cast<int>(result.numContacts());
  out.pairs = np;
  out.pairs_truncated = np >= o.max_pairs;
  if (np == 0) return false;

  pairs.assign(static_cast<std::size_t>(np), Pair{});
  const auto centroid = [](const TriangleMesh& mesh, int f, const RigidTransform& X) {
    const glm::ivec3 t = mesh.triangles[f];
    return X * ((mesh.vertices[t[0]] + mesh.vertices[t[1]] + mesh.vertices[t[2]]) / 3.0);
  };
  for (int i = 0; i < np; ++i) {
    const fcl::Contactd& c = result.getContact(static_cast<std::size_t>(i));
    const bool swapped = c.o1 != m.tool_fcl.get();
    Pair& p = pairs[i];
    p.tool_tri = static_cast<int>(swapped ? c.b2 : c.b1);
    p.env_tri = static_cast<int>(swapped ? c.b1 : c.b2);
    // The pair's point: the middle of its intersection segment (where each triangle's edges
    // pierce the other); the centroids' midpoint when rounding found no piercing.
    const auto corner = [](const TriangleMesh& mesh, int f, int corner_index,
                           const RigidTransform& X) {
      return X * mesh.vertices[mesh.triangles[f][corner_index]];
    };
    const glm::dvec3 a0 = corner(m.tool, p.tool_tri, 0, X_WFt),
                     a1 = corner(m.tool, p.tool_tri, 1, X_WFt),
                     a2 = corner(m.tool, p.tool_tri, 2, X_WFt);
    const glm::dvec3 b0 = corner(m.environment, p.env_tri, 0, X_WFe),
                     b1 = corner(m.environment, p.env_tri, 1, X_WFe),
                     b2 = corner(m.environment, p.env_tri, 2, X_WFe);
    glm::dvec3 sum(0.0);
    int count = 0;
    EdgePiercings(a0, a1, a2, b0, b1, b2, sum, count);
    EdgePiercings(b0, b1, b2, a0, a1, a2, sum, count);
    p.p_W = count > 0 ? sum / static_cast<double>(count)
                      : 0.5 * (centroid(m.tool, p.tool_tri, X_WFt) +
                               centroid(m.environment, p.env_tri, X_WFe));
    p.n_W = X_WFe.rotation * m.environment_topology.normal_F[p.env_tri];
  }
  return true;
}

void ContactPatchTruth::Impl::LinkPairsIntoPatches(PoseState& s) {
  const ContactPatchTruthOptions& o = options;
  const std::vector<Pair>& pairs = s.pairs;
  const int np = static_cast<int>(pairs.size());
  std::vector<std::pair<int, int>>& split_neighbours = s.split_neighbours;
  std::vector<int>& patch_of = s.patch_of;
  int& num_patches = s.num_patches;
  const double d = o.merge_distance_m, d2 = d * d;
  const double cos_max = std::cos(o.max_normal_angle_deg * std::numbers::pi / 180.0);
  CellGrid grid(d);
  for (int i = 0; i < np; ++i) grid.Add(pairs[i].p_W, i);
  std::vector<int> parent(static_cast<std::size_t>(np));
  for (int i = 0; i < np; ++i) parent[i] = i;
  for (int i = 0; i < np; ++i) {
    grid.ForEachNear(pairs[i].p_W, [&](int j) {
      if (j <= i) return;
      const glm::dvec3 dp = pairs[j].p_W - pairs[i].p_W;
      if (glm::dot(dp, dp) >= d2) return;
      if (glm::dot(pairs[i].n_W, pairs[j].n_W) < cos_max) {
        split_neighbours.emplace_back(i, j);  // near, but the fine normals disagree
        return;
      }
      const int a = Find(parent, i), b = Find(parent, j);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    });
  }
  const auto link_shared = [&](auto triangle_of) {
    std::unordered_map<int, int> first;  // triangle → first pair holding it
    first.reserve(static_cast<std::size_t>(np));
    for (int i = 0; i < np; ++i) {
      const auto [it, fresh] = first.try_emplace(triangle_of(pairs[i]), i);
      if (fresh) continue;
      const int j = it->second;
      if (glm::dot(pairs[i].n_W, pairs[j].n_W) < cos_max) continue;
      const int a = Find(parent, i), b = Find(parent, j);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  };
  link_shared([](const Pair& p) { return p.tool_tri; });
  link_shared([](const Pair& p) { return p.env_tri; });
  patch_of.assign(static_cast<std::size_t>(np), -1);
  std::vector<int> root_patch(static_cast<std::size_t>(np), -1);
  num_patches = 0;
  for (int i = 0; i < np; ++i) {
    const int r = Find(parent, i);
    if (root_patch[r] < 0) root_patch[r] = num_patches++;
    patch_of[i] = root_patch[r];
  }
}

std::vector<PatchGeometry> ContactPatchTruth::Impl::Geometries(PoseState& s,
                                                               const std::vector<int>& patch_index,
                                                               int count) {
  Impl& m = *this;
  const ContactPatchTruthOptions& o = options;
  const std::vector<Pair>& pairs = s.pairs;
  const int np = static_cast<int>(pairs.size());
  const RigidTransform& X_WFt = s.X_WFt;
  const RigidTransform& X_WFe = s.X_WFe;
  const glm::dvec3 p_WTcm = s.X_WT.translation;
  long long& geometry_rays = s.geometry_rays;
  // Crossing triangles are marked for all patches first, so that no flood fill walks into
  // another patch's crossing triangles.
  m.tool_state.assign(m.tool.triangles.size(), 0);
  m.environment_state.assign(m.environment.triangles.size(), 0);
  std::vector<std::vector<int>> tool_crossing(count), env_crossing(count);
  std::vector<glm::dvec3> provisional_n(count, glm::dvec3(0.0));
  std::vector<std::vector<glm::dvec3>> pair_points(count);
  std::vector<int> patch_pairs(count, 0);
  for (int i = 0; i < np; ++i) {
    const int q = patch_index[i];
    ++patch_pairs[q];
    provisional_n[q] += pairs[i].n_W;
    pair_points[q].push_back(pairs[i].p_W);
    if (m.tool_state[pairs[i].tool_tri] == 0) {
      m.tool_state[pairs[i].tool_tri] = 1;
      tool_crossing[q].push_back(pairs[i].tool_tri);
    }
    if (m.environment_state[pairs[i].env_tri] == 0) {
      m.environment_state[pairs[i].env_tri] = 1;
      env_crossing[q].push_back(pairs[i].env_tri);
    }
  }
  std::vector<PatchGeometry> result(static_cast<std::size_t>(count));
  for (int q = 0; q < count; ++q) {
    const double len = glm::length(provisional_n[q]);
    const glm::dvec3 n0 = len > 1e-12 ? provisional_n[q] / len : glm::dvec3(0, 0, 1);
    std::vector<glm::dvec3> points = pair_points[q];
    // Tool points inside the environment: a ray along +n leaves it through its surface.
    const Impl::SideSums a =
        m.InsideSurface(m.tool, m.tool_topology, m.tool_state, tool_crossing[q], X_WFt,
                        m.environment_rays, X_WFe, n0, p_WTcm, points, geometry_rays);
    // Environment points inside the tool: a ray along −n leaves the tool.
    const Impl::SideSums b =
        m.InsideSurface(m.environment, m.environment_topology, m.environment_state, env_crossing[q],
                        X_WFe, m.tool_rays, X_WFt, -n0, p_WTcm, points, geometry_rays);
    PatchGeometry& g = result[static_cast<std::size_t>(q)];
    TruthPatch& patch = g.patch;
    patch.pairs = patch_pairs[q];
    patch.tool_inside_area_m2 = a.area;
    patch.environment_inside_area_m2 = b.area;
    patch.dV_dx_tool_W = a.sum_an_W;
    patch.dV_dtheta_tool_W = a.sum_a_r_x_n_W;
    patch.dV_dx_environment_W = -b.sum_an_W;
    patch.dV_dtheta_environment_W = -b.sum_a_r_x_n_W;
    g.dV_dx = 0.5 * (patch.dV_dx_tool_W + patch.dV_dx_environment_W);
    g.dV_dtheta = 0.5 * (patch.dV_dtheta_tool_W + patch.dV_dtheta_environment_W);
    const double gl = glm::length(g.dV_dx);
    glm::dvec3 n = gl > 1e-18 ? -g.dV_dx / gl : n0;
    // The centre: the inside surfaces' area centroid (the pairs' points' mean without them).
    glm::dvec3 centre(0.0);
    if (a.area + b.area > 0.0) {
      centre = (a.sum_ap_W + b.sum_ap_W) / (a.area + b.area);
    } else {
      for (const glm::dvec3& p : pair_points[q]) centre += p;
      centre /= static_cast<double>(pair_points[q].size());
    }
    // The depth's direction: the macroscopic normal at the centre (texture finer than
    // macro_normal_radius_m does not tilt it), where it is defined and on n's side.
    // Both surfaces' mean normals over the ball; the flatter one (the longer mean) gives the
    // direction: at a block's edge pressed on a face, the face's. The tool's is turned to point
    // from the environment to the tool.
    const glm::dvec3 env_mean =
        X_WFe.rotation * m.environment_normals.MeanNormal(X_WFe.Inverse() * centre);
    const glm::dvec3 tool_mean =
        -(X_WFt.rotation * m.tool_normals.MeanNormal(X_WFt.Inverse() * centre));
    const glm::dvec3 flatter =
        glm::length(env_mean) >= glm::length(tool_mean) ? env_mean : tool_mean;
    const double flat = glm::length(flatter);
    g.macro_normal = flat > 1e-9 ? flatter / flat : glm::dvec3(0.0);
    if (o.depth_along_macro_normal && glm::dot(g.macro_normal, n) > 0.0) n = g.macro_normal;
    // The window holding the inside surfaces' projection.
    const ContactWindow axes = ContactWindow::Make(centre, n, 1.0, 2);
    double half = 0.0;
    for (const glm::dvec3& p : points) {
      const glm::dvec3 dp = p - centre;
      half = std::max(
          {half, std::abs(glm::dot(dp, axes.axis_u_W)), std::abs(glm::dot(dp, axes.axis_v_W))});
    }
    g.extent = std::clamp(2.0 * (half + o.window_margin_m), o.min_extent_m, o.max_extent_m);
    patch.window = ContactWindow::Make(centre, n, g.extent, 50);
  }
  return result;
}

void ContactPatchTruth::Impl::Regroup(PoseState& s, const std::vector<int>& root) {
  const int np = static_cast<int>(s.pairs.size());
  std::vector<int>& patch_of = s.patch_of;
  int& num_patches = s.num_patches;
  PoseTruth& out = s.out;
  std::vector<PatchGeometry>& geometries = s.geometries;
  std::vector<int> renumber(static_cast<std::size_t>(num_patches), -1);
  int count = 0;
  for (int q = 0; q < num_patches; ++q) {
    if (root[q] == q) renumber[q] = count++;
  }
  for (int i = 0; i < np; ++i) patch_of[i] = renumber[root[patch_of[i]]];
  out.patches_merged += num_patches - count;
  num_patches = count;
  geometries = Geometries(s, patch_of, num_patches);
}

void ContactPatchTruth::Impl::MergeNeighboursOnOneSurface(PoseState& s) {
  const ContactPatchTruthOptions& o = options;
  const double cos_max = std::cos(o.max_normal_angle_deg * std::numbers::pi / 180.0);
  const int num_patches = s.num_patches;
  const std::vector<std::pair<int, int>>& split_neighbours = s.split_neighbours;
  const std::vector<int>& patch_of = s.patch_of;
  const std::vector<PatchGeometry>& geometries = s.geometries;
  if (o.macro_normal_radius_m > 0.0 && num_patches > 1 && !split_neighbours.empty()) {
    std::vector<int> patch_parent(static_cast<std::size_t>(num_patches));
    for (int q = 0; q < num_patches; ++q) patch_parent[q] = q;
    bool any = false;
    for (const auto& [i, j] : split_neighbours) {
      const int a = Find(patch_parent, patch_of[i]), b = Find(patch_parent, patch_of[j]);
      if (a == b || glm::dot(geometries[patch_of[i]].macro_normal,
                             geometries[patch_of[j]].macro_normal) < cos_max) {
        continue;
      }
      patch_parent[std::max(a, b)] = std::min(a, b);
      any = true;
    }
    if (any) {
      for (int q = 0; q < num_patches; ++q) patch_parent[q] = Find(patch_parent, q);
      Regroup(s, patch_parent);
    }
  }
}

void ContactPatchTruth::Impl::MergeDoubleCounted(PoseState& s) {
  const ContactPatchTruthOptions& o = options;
  const int& num_patches = s.num_patches;
  const std::vector<PatchGeometry>& geometries = s.geometries;
  const double cos_overlap = std::cos(o.overlap_merge_angle_deg * std::numbers::pi / 180.0);
  for (int round = 0; round < 8 && num_patches > 1; ++round) {
    std::vector<int> order(static_cast<std::size_t>(num_patches));
    for (int q = 0; q < num_patches; ++q) order[q] = q;
    const auto strength = [&](int q) { return glm::length(geometries[q].dV_dx); };
    std::sort(order.begin(), order.end(), [&](int a, int b) { return strength(a) > strength(b); });
    std::vector<int> merged_into(static_cast<std::size_t>(num_patches), -1);  // −1: kept
    bool any = false;
    for (std::size_t ia = 0; ia < order.size(); ++ia) {
      const int pa = order[ia];
      if (merged_into[pa] >= 0) continue;
      const ContactWindow& w = geometries[pa].patch.window;
      const double half = 0.5 * geometries[pa].extent;
      for (std::size_t ib = ia + 1; ib < order.size(); ++ib) {
        const int qb = order[ib];
        if (merged_into[qb] >= 0) continue;
        const ContactWindow& wq = geometries[qb].patch.window;
        const glm::dvec3 dc = wq.center_W - w.center_W;
        const double du = std::abs(glm::dot(dc, w.axis_u_W));
        const double dv = std::abs(glm::dot(dc, w.axis_v_W));
        const double dn = std::abs(glm::dot(dc, w.normal_W));
        const bool overlapping = o.overlap_merge_angle_deg > 0.0 && du <= half && dv <= half &&
                                 dn <= half && glm::dot(w.normal_W, wq.normal_W) >= cos_overlap;
        const double grown = half + o.merge_distance_m;
        const bool minor = strength(qb) <= o.minor_patch_fraction * strength(pa) && du <= grown &&
                           dv <= grown && dn <= grown;
        if (overlapping || minor) {
          merged_into[qb] = pa;
          any = true;
        }
      }
    }
    if (!any) break;
    for (int q = 0; q < num_patches; ++q) {
      if (merged_into[q] < 0) merged_into[q] = q;
    }
    Regroup(s, merged_into);
  }
}

void ContactPatchTruth::Impl::LinearizePatches(PoseState& s) {
  Impl& m = *this;
  const ContactPatchTruthOptions& o = options;
  const RigidTransform& X_WT = s.X_WT;
  const RigidTransform& X_TFt = s.X_TFt;
  const RigidTransform& X_WFe = s.X_WFe;
  const double k = s.k;
  PoseTruth& out = s.out;
  std::vector<PatchGeometry>& geometries = s.geometries;
  for (PatchGeometry& g : geometries) {
    TruthPatch& patch = g.patch;
    out.dV_dx_W += g.dV_dx;
    out.dV_dtheta_W += g.dV_dtheta;
    const int step_resolution =
        std::max(2, static_cast<int>(std::lround(g.extent / o.gradient_step_m)));
    patch.gradient_step_m = g.extent / step_resolution;
    patch.tilt_step_rad = o.tilt_lift_m > 0.0 ? o.tilt_lift_m / (0.5 * g.extent)
                                              : patch.gradient_step_m / (0.5 * g.extent);
    patch.contact = m.solver.Linearize(X_WT, X_TFt, X_WFe, patch.window, k, step_resolution,
                                       patch.tilt_step_rad);
    out.rays += patch.contact.rays;
    if (o.pressure_tolerance > 0.0) {  // 4b.
      patch.pressure = m.solver.ConvergedPressure(X_WT, X_TFt, X_WFe, patch.window,
                                                  o.pressure_tolerance, o.pressure_max_samples);
      out.rays += patch.pressure.rays;
      out.pressure_per_kp += patch.pressure.per_kp;
      out.pressure_volume_m3 += patch.pressure.volume_m3;
    }
    out.patches.push_back(std::move(patch));
  }
}

void ContactPatchTruth::Impl::SharePenalties(PoseState& s) {
  const ContactPatchTruthOptions& o = options;
  const double cos_max = std::cos(o.max_normal_angle_deg * std::numbers::pi / 180.0);
  PoseTruth& out = s.out;
  const std::vector<Pair>& pairs = s.pairs;
  const int np = static_cast<int>(pairs.size());
  const std::vector<int>& patch_of = s.patch_of;
  const int P = static_cast<int>(out.patches.size());
  if (P > 1 && o.share_fade_m > 0.0) {
    const double reach = o.merge_distance_m + o.share_fade_m;
    std::vector<double> gap(static_cast<std::size_t>(P) * P,
                            std::numeric_limits<double>::infinity());
    CellGrid near(reach);
    for (int i = 0; i < np; ++i) near.Add(pairs[i].p_W, i);
    for (int i = 0; i < np; ++i) {
      const int pi = patch_of[i];
      near.ForEachNear(pairs[i].p_W, [&](int j) {
        const int pj = patch_of[j];
        if (pj <= pi) return;
        double& g = gap[static_cast<std::size_t>(pi) * P + pj];
        g = std::min(g, glm::distance(pairs[i].p_W, pairs[j].p_W));
      });
    }
    std::vector<double> links(static_cast<std::size_t>(P) * P, 0.0);
    for (int a = 0; a < P; ++a) {
      for (int b = a + 1; b < P; ++b) {
        const double g = gap[static_cast<std::size_t>(a) * P + b];
        if (glm::dot(out.patches[a].window.normal_W, out.patches[b].window.normal_W) < cos_max) {
          continue;
        }
        out.patches[a].gap_to_neighbour_m = std::min(out.patches[a].gap_to_neighbour_m, g);
        out.patches[b].gap_to_neighbour_m = std::min(out.patches[b].gap_to_neighbour_m, g);
        const double l = OverlapLink(g, o.merge_distance_m, o.share_fade_m);
        links[static_cast<std::size_t>(a) * P + b] = links[static_cast<std::size_t>(b) * P + a] = l;
      }
    }
    StrongestPathLinks(links, P);
    std::vector<double> depths(static_cast<std::size_t>(P)), shares(static_cast<std::size_t>(P));
    for (int a = 0; a < P; ++a) {
      const double dm = out.patches[a].contact.linearization.depth_m;
      // Patches without force take no part (a zero-force patch must not take a share).
      depths[a] = glm::length(out.patches[a].contact.F_T_W.force) > 0.0 && std::isfinite(dm)
                      ? dm
                      : std::numeric_limits<double>::quiet_NaN();
    }
    LinkedPenaltyShares(depths, links, o.share_temperature_m, shares);
    for (int a = 0; a < P; ++a) {
      out.patches[a].share = std::isfinite(depths[a]) ? shares[a] : 1.0;
      out.patches_shared += out.patches[a].share < 1.0;
    }
  }
  for (const TruthPatch& patch : out.patches) {
    out.F_T_W.force += patch.share * patch.contact.F_T_W.force;
    out.F_T_W.torque += patch.share * patch.contact.F_T_W.torque;
  }
}

PoseTruth ContactPatchTruth::At(const RigidTransform& X_WT, const RigidTransform& X_TFt,
                                const RigidTransform& X_WFe, double k) {
  if (!IsFiniteRigidTransform(X_WT) || !IsFiniteRigidTransform(X_TFt) ||
      !IsFiniteRigidTransform(X_WFe)) {
    return PoseTruth{};
  }
  Impl& m = *impl_;
  PoseState s;
  s.X_WT = X_WT;
  s.X_TFt = X_TFt;
  s.X_WFe = X_WFe;
  s.X_WFt = X_WT * X_TFt;
  s.k = k;
  if (!m.FindIntersectingPairs(s)) return s.out;              // 1.
  m.LinkPairsIntoPatches(s);                                  // 2.
  s.geometries = m.Geometries(s, s.patch_of, s.num_patches);  // 3.
  m.MergeNeighboursOnOneSurface(s);                           // 3a.
  m.MergeDoubleCounted(s);                                    // 3b.
  s.out.rays += s.geometry_rays;
  m.LinearizePatches(s);  // 4.
  m.SharePenalties(s);    // 4a.
  return s.out;
}

}  // namespace ht
