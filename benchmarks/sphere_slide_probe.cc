// Scratch probe (not committed): smooth sphere sliding on a rippled plate.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <glm/gtc/quaternion.hpp>
#include "haptic_core/model_build/haptic_model_build.h"
#include "haptic_core/remote_step.h"

using namespace ht;

TriangleMesh UvSphere(double r, int n_lat, int n_lon) {
  TriangleMesh m;
  m.vertices.emplace_back(0, 0, r);
  for (int i = 1; i < n_lat; ++i) {
    const double th = std::numbers::pi * i / n_lat;
    for (int j = 0; j < n_lon; ++j) {
      const double ph = 2 * std::numbers::pi * j / n_lon;
      m.vertices.emplace_back(r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph), r * std::cos(th));
    }
  }
  m.vertices.emplace_back(0, 0, -r);
  const int south = static_cast<int>(m.vertices.size()) - 1;
  const auto ring = [&](int i, int j) { return 1 + (i - 1) * n_lon + (j % n_lon); };
  for (int j = 0; j < n_lon; ++j) m.triangles.emplace_back(0, ring(1, j), ring(1, j + 1));
  for (int i = 1; i < n_lat - 1; ++i)
    for (int j = 0; j < n_lon; ++j) {
      m.triangles.emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      m.triangles.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
    }
  for (int j = 0; j < n_lon; ++j) m.triangles.emplace_back(south, ring(n_lat - 1, j + 1), ring(n_lat - 1, j));
  return m;
}

const double A = 0.2e-3, L = 10e-3;
double H(double x) { return A * std::sin(2 * std::numbers::pi * x / L); }
double dH(double x) { return A * 2 * std::numbers::pi / L * std::cos(2 * std::numbers::pi * x / L); }

// Closed slab: top z = H(x) over [-hx,hx]x[-hy,hy], bottom z = -t.
TriangleMesh RippledPlate(double hx, double hy, double t, int nx, int ny) {
  TriangleMesh m;
  auto id = [&](int i, int j, int top) { return top * (nx + 1) * (ny + 1) + j * (nx + 1) + i; };
  for (int top = 0; top < 2; ++top)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        const double x = -hx + 2 * hx * i / nx, y = -hy + 2 * hy * j / ny;
        m.vertices.emplace_back(x, y, top ? H(x) : -t);
      }
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      // top: ccw from +z
      m.triangles.emplace_back(id(i, j, 1), id(i + 1, j, 1), id(i + 1, j + 1, 1));
      m.triangles.emplace_back(id(i, j, 1), id(i + 1, j + 1, 1), id(i, j + 1, 1));
      m.triangles.emplace_back(id(i, j, 0), id(i + 1, j + 1, 0), id(i + 1, j, 0));
      m.triangles.emplace_back(id(i, j, 0), id(i, j + 1, 0), id(i + 1, j + 1, 0));
    }
  // sides
  for (int i = 0; i < nx; ++i) {
    // y = -hy (outward -y)
    m.triangles.emplace_back(id(i, 0, 0), id(i + 1, 0, 0), id(i + 1, 0, 1));
    m.triangles.emplace_back(id(i, 0, 0), id(i + 1, 0, 1), id(i, 0, 1));
    m.triangles.emplace_back(id(i, ny, 0), id(i + 1, ny, 1), id(i + 1, ny, 0));
    m.triangles.emplace_back(id(i, ny, 0), id(i, ny, 1), id(i + 1, ny, 1));
  }
  for (int j = 0; j < ny; ++j) {
    m.triangles.emplace_back(id(0, j, 0), id(0, j + 1, 1), id(0, j + 1, 0));
    m.triangles.emplace_back(id(0, j, 0), id(0, j, 1), id(0, j + 1, 1));
    m.triangles.emplace_back(id(nx, j, 0), id(nx, j + 1, 0), id(nx, j + 1, 1));
    m.triangles.emplace_back(id(nx, j, 0), id(nx, j + 1, 1), id(nx, j, 1));
  }
  return m;
}

int main(int argc, char** argv) {
  const double R = 5e-3, pen = argc > 1 ? atof(argv[1]) : 0.3e-3;
  HapticModelCache cache(HapticModelCache::DefaultDir());
  HapticModelBuildParams ps;
  ps.coarse_triangles = 300;
  ps.texture.texture_size = 512;
  HapticModelBuild sphere = BuildHapticModelCached("sphere", UvSphere(R, 90, 180), ps, cache);
  HapticModelBuildParams pp;
  pp.coarse_triangles = argc > 2 ? atoi(argv[2]) : 24;
  pp.texture.texture_size = 1024;
  HapticModelBuild plate = BuildHapticModelCached("plate", RippledPlate(0.03, 0.015, 0.005, 240, 120), pp, cache);
  std::fprintf(stderr, "sphere: %lld coarse, reach %.3g, bake rms %.3g; plate %lld coarse, reach %.3g bake rms %.3g\n",
               (long long)sphere.report.coarse_triangles, sphere.report.outward_reach_m, sphere.report.bake.rms_bake_error_m,
               (long long)plate.report.coarse_triangles, plate.report.outward_reach_m, plate.report.bake.rms_bake_error_m);
  HapticScene scene;
  scene.name = "sphere_on_ripples";
  auto tool = std::make_shared<HapticModel>(*sphere.model);
  std::fprintf(stderr, "sphere com offset %.3g m\n", glm::length(tool->center_of_mass_O));
  const glm::dvec3 com = tool->center_of_mass_O;
  ShiftModelFrame(*tool, com);
  scene.tool = tool;
  TouchableObject t;
  t.model = plate.model;
  t.stiffness_n_per_m = 1000;
  scene.touchables.push_back(t);
  PipelineOptions opt;
  opt.region_normals = argc > 3 && atoi(argv[3]) != 0;
  HapticTexturePipeline pipe(scene, opt);
  std::printf("x_mm,contacts,delta_mm,cf_delta_mm,dir_err_deg,fx,fz,nx,nz,F_over_k_mm\n");
  int spikes = 0, ticks = 0, multi = 0;
  const int s0 = argc > 4 ? atoi(argv[4]) : 0, s1 = argc > 5 ? atoi(argv[5]) : 400;
  for (int s = s0; s <= s1; ++s) {
    const double x = -0.01 + 0.02 * s / 400.0;
    // Centre height: keep penetration `pen` below the local envelope roughly: z = R - pen (mean surface 0)
    RigidTransform X;
    X.translation = {x, 0.0003, R - pen};
    StepTimings tm;
    ContactModel m = pipe.Step(X, s, tm);
    // closed form: nearest point on curve to centre (in xz plane)
    const glm::dvec3 cc = X.translation - com;
    double best = 1e9, bx = 0;
    for (int k = -20000; k <= 20000; ++k) {
      const double px = cc.x + R * k / 20000.0;
      const double d = std::hypot(px - cc.x, H(px) - cc.z);
      if (d < best) { best = d; bx = px; }
    }
    const double cf_delta = R - best;
    glm::dvec3 nrm = glm::normalize(glm::dvec3(-dH(bx), 0, 1));
    const glm::dvec3 F = m.F_T_W_at_q0.force;
    double dir = glm::length(F) > 0 ? std::acos(std::clamp(glm::dot(F, nrm) / glm::length(F), -1.0, 1.0)) * 180 / std::numbers::pi : 180;
    double dmax = 0;
    glm::dvec3 n0(0);
    for (int c = 0; c < m.num_contacts; ++c) if (m.contacts[c].depth_m > dmax) { dmax = m.contacts[c].depth_m; n0 = m.contacts[c].normal_W; }
    ++ticks;
    if (m.num_contacts > 1) ++multi;
    if (dir > 3 || std::abs(dmax - cf_delta) > 20e-6) ++spikes;
    std::printf("%.3f,%d,%.4f,%.4f,%.2f,%.4f,%.4f,%.3f,%.3f,%.4f\n", x * 1e3, m.num_contacts, dmax * 1e3, cf_delta * 1e3, dir, F.x, F.z, n0.x, n0.z, glm::length(F) / t.stiffness_n_per_m * 1e3);
  }
  std::fprintf(stderr, "grazing dropped %lld, ", (long long)pipe.step_faults().grazing_dropped);
  std::fprintf(stderr, "ticks %d, multi-contact %d, off (>3 deg or >20um) %d\n", ticks, multi, spikes);
}
