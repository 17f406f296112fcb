// The ground truth of the speed-vs-error study (haptic_core/accuracy): analytic cases where the
// directional penetration depth is known in closed form, the method's facing and box rules, the
// CPU method against the ground truth on models whose coarse mesh is exact (two routes to one
// number), and the FCL full-resolution baseline's sign and intersection test.

#include "haptic_core/accuracy/ground_truth_depth.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <limits>

#include "accuracy_test_meshes.h"
#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/contact_linearization.h"
#include "haptic_core/demo/procedural_models.h"

namespace ht {
namespace {

using test::At;
using test::Box;

// The coarse mesh of a model as a triangle mesh (exact for untextured boxes).
TriangleMesh CoarseMesh(const HapticModel& m) { return {m.vertices_O, m.triangles}; }

const ContactWindow kWindow = ContactWindow::Make({0, 0, 0}, {0, 0, 1}, 0.02, 50);

TEST(RayCastSurface, RefusesBadMeshes) {
  EXPECT_THROW(RayCastSurface(TriangleMesh{}), std::invalid_argument);
  TriangleMesh bad = Box({0, 0, 0}, {1, 1, 1});
  bad.triangles[3].y = 99;
  EXPECT_THROW(RayCastSurface{bad}, std::invalid_argument);
}

TEST(RayCastSurface, AcceptsOnlySurfacesFacingTheRay) {
  const RayCastSurface box(Box({-1, -1, -1}, {1, 1, 1}));
  // From outside, the near face faces the ray.
  EXPECT_NEAR(box.FirstFacingHit({0, 0, 5}, {0, 0, -1}, 10.0), 4.0, 1e-6);
  // From inside, the first face (the far one, facing away) is skipped: nothing else faces it.
  EXPECT_LT(box.FirstFacingHit({0, 0, 0}, {0, 0, -1}, 10.0), 0.0);
}

// Coplanar resting contact (DESIGN.md §8: many equal maxima): a flat tool face 0.3 mm into a
// flat object face; δ is the overlap everywhere the two are.
TEST(GroundTruthDepth, ParallelFacesGiveTheirOverlapExactly) {
  const RayCastSurface object(Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.0}));
  const RayCastSurface tool(Box({-0.015, -0.015, 0.0}, {0.015, 0.015, 0.01}));
  GroundTruthDepthSolver solver(tool, object);
  const GroundTruthDepth d = solver.ConvergedDepth(At({0, 0, -0.3e-3}), At({0, 0, 0}), kWindow);
  EXPECT_NEAR(d.depth_m, 0.3e-3, 2e-8);
  EXPECT_TRUE(d.converged);
  EXPECT_LT(d.change_m, 1e-7);
  // Separated by 1 mm: δ is −1 mm (signed), still finite: both faces are in the window's box.
  const GroundTruthDepth gap = solver.ConvergedDepth(At({0, 0, 1e-3}), At({0, 0, 0}), kWindow);
  EXPECT_NEAR(gap.depth_m, -1e-3, 2e-8);
}

// The deepest point on the window's border (DESIGN.md §8): a tilted flat tool face; the grid's
// cells stop half a cell short of the border, the refinement reaches it.
TEST(GroundTruthDepth, TiltedFacePeaksOnTheWindowBorder) {
  const double theta = 0.05;  // rad about y: the face is lowest at x = −W/2
  const RayCastSurface object(Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.0}));
  const RayCastSurface tool(Box({-0.03, -0.03, 0.0}, {0.03, 0.03, 0.01}));
  GroundTruthDepthSolver solver(tool, object);
  const double z0 = 0.2e-3;  // the tool face's height at x = 0
  const auto X_WFt = At({0, 0, z0}, glm::angleAxis(theta, glm::dvec3(0, 1, 0)));
  const GroundTruthDepth d = solver.ConvergedDepth(X_WFt, At({0, 0, 0}), kWindow);
  // The face in W: z = z0 − x·tanθ, lowest on the border x = +W/2 (world x, not the face's own).
  EXPECT_NEAR(d.depth_m, 0.01 * std::tan(theta) - z0, 5e-8);
  EXPECT_NEAR(std::abs(d.at_uv_m.x), 0.01, 1e-6);  // on the border
  EXPECT_TRUE(d.converged);
}

TEST(GroundTruthDepth, GradientOfATiltedFaceIsItsSlope) {
  const double theta = 0.05;
  const RayCastSurface object(Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.0}));
  const RayCastSurface tool(Box({-0.03, -0.03, 0.0}, {0.03, 0.03, 0.01}));
  GroundTruthDepthSolver solver(tool, object);
  const auto X_WT = At({0, 0, 0.2e-3}, glm::angleAxis(theta, glm::dvec3(0, 1, 0)));
  const GroundTruthContact c =
      solver.Linearize(X_WT, RigidTransform::Identity(), At({0, 0, 0}), kWindow, 8000.0);
  // Moving the tool along x moves its lowest border point's height by ∓tanθ; along y nothing;
  // along n by −1 exactly.
  const glm::dvec3 g = c.linearization.gradient.d_translation_W;
  EXPECT_NEAR(std::abs(g.x), std::tan(theta), 1e-4);
  EXPECT_NEAR(g.y, 0.0, 1e-6);
  EXPECT_DOUBLE_EQ(g.z, -1.0);
  // Φ = −k δ ∇δ: pushes up, and sideways against the slope.
  EXPECT_GT(c.F_T_W.force.z, 0.0);
  EXPECT_NEAR(c.F_T_W.force.z, 8000.0 * c.linearization.depth_m, 1e-9);
}

// The box rule: an object surface facing +n above +R is outside the window's box; from inside
// the object a ray meets only a face that looks away. Nothing covered: −∞.
TEST(GroundTruthDepth, SurfacesOutsideTheBoxOrFacingAwayDoNotCount) {
  const RayCastSurface object(Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.03}));  // top at 3 cm
  const RayCastSurface tool(Box({-0.01, -0.01, 0.0}, {0.01, 0.01, 0.01}));
  GroundTruthDepthSolver solver(tool, object);
  const GroundTruthDepth d = solver.DepthAt(At({0, 0, 0}), At({0, 0, 0}), kWindow, 32);
  EXPECT_TRUE(std::isinf(d.depth_m) && d.depth_m < 0.0);
}

TEST(GroundTruthDepth, NoOverlapOnTheWindowGivesMinusInfinity) {
  const RayCastSurface object(Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.0}));
  const RayCastSurface tool(Box({-0.005, -0.005, 0.0}, {0.005, 0.005, 0.01}));
  GroundTruthDepthSolver solver(tool, object);
  const GroundTruthDepth d = solver.ConvergedDepth(At({0.1, 0, 0}), At({0, 0, 0}), kWindow);
  EXPECT_TRUE(std::isinf(d.depth_m) && d.depth_m < 0.0);
  EXPECT_TRUE(d.converged);
}

TEST(GroundTruthOptions, RefusesValuesOutOfRange) {
  GroundTruthOptions o;
  o.initial_samples = 1;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.max_samples = o.initial_samples - 1;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.tolerance_m = 0.0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
}

// Two routes to one number: the method's CPU reference on untextured boxes (coarse = exact) and
// the ground truth on the same boxes. Parallel faces: equal. Tilted: the method's deepest cell
// centre stands half a cell in from the border, so it reads (W/N/2)·tanθ less.
TEST(GroundTruthDepth, AgreesWithTheMethodWhereTheCoarseMeshIsExact) {
  const auto flat = [](double, double) { return 0.0; };
  const HapticModel tool_model = MakeTexturedBox({0.03, 0.03, 0.005}, flat, 16, 0.1, "tool");
  const HapticModel object_model = MakeTexturedBox({0.05, 0.05, 0.01}, flat, 16, 1.0, "object");
  const RayCastSurface tool(CoarseMesh(tool_model));
  const RayCastSurface object(CoarseMesh(object_model));
  GroundTruthDepthSolver truth(tool, object);
  TexturePenetrationSolver method;
  const RigidTransform X_WO = At({0, 0, -0.01});  // object top at z = 0
  for (const double theta : {0.0, 0.03, 0.08}) {
    SCOPED_TRACE(theta);
    const auto X_WT = At({0, 0, 0.005 - 0.25e-3}, glm::angleAxis(theta, glm::dvec3(0, 1, 0)));
    const GroundTruthDepth gt = truth.ConvergedDepth(X_WT, X_WO, kWindow);
    const DepthSample m = method.Depth(tool_model, X_WT, object_model, X_WO, kWindow);
    const double half_cell_drop = 0.5 * kWindow.cell_size_m() * std::tan(theta);
    EXPECT_NEAR(gt.depth_m - m.depth_m, half_cell_drop, 2e-7);
  }
}

TEST(MeshContactBaseline, PushesTheToolOutOfTheObject) {
  const TriangleMesh object = Box({-0.05, -0.05, -0.01}, {0.05, 0.05, 0.0});
  const TriangleMesh tool = Box({-0.01, -0.01, 0.0}, {0.01, 0.01, 0.01});
  const MeshContactBaseline fcl(tool, object);
  const MeshContactResult r = fcl.Query(At({0, 0, -0.2e-3}), At({0, 0, 0}), 8000.0, {0, 0, 0.005});
  EXPECT_TRUE(r.in_contact);
  EXPECT_GT(r.contacts, 0);
  EXPECT_GT(r.F_T_W.force.z, 0.0);
  EXPECT_TRUE(fcl.Intersects(At({0, 0, -0.2e-3}), At({0, 0, 0})));
  EXPECT_FALSE(fcl.Intersects(At({0, 0, 0.2e-3}), At({0, 0, 0})));
  const MeshContactResult apart = fcl.Query(At({0, 0, 1e-3}), At({0, 0, 0}), 8000.0, {});
  EXPECT_FALSE(apart.in_contact);
  EXPECT_EQ(apart.contacts, 0);
  EXPECT_EQ(apart.F_T_W.force, glm::dvec3(0.0));
}

}  // namespace
}  // namespace ht
