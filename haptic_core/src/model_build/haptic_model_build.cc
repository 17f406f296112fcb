// The model build (haptic_model_build.h, DESIGN.md §2): the texture size chosen by the surface
// error, the build itself (decimation, bake, hulls, mass properties). Its cache file:
// haptic_model_cache.cc.
#include "haptic_core/model_build/haptic_model_build.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/glm.hpp>
#include <limits>
#include <stdexcept>

#include "model_build_helpers.h"

namespace ht {
namespace {

using model_build::BoundsOf;
using model_build::IsSizingSize;
using model_build::MeasuredSurface;
using model_build::Seconds;

// Mass properties of a closed triangle mesh by signed tetrahedra from the origin (Mirtich 1996 in
// its simplest, exact-for-polyhedra form: second moments of each tetrahedron).
void SetMassProperties(const TriangleMesh& coarse, bool closed, double density,
                       HapticModel& model) {
  double volume = 0.0;
  glm::dvec3 first{0.0};
  glm::dmat3 second{0.0};  // ∫ x_i x_j dV
  for (const glm::ivec3& t : coarse.triangles) {
    const glm::dvec3 a = coarse.vertices[t.x], b = coarse.vertices[t.y], c = coarse.vertices[t.z];
    const double v6 = glm::dot(a, glm::cross(b, c));  // 6 × signed volume
    volume += v6 / 6.0;
    first += v6 / 24.0 * (a + b + c);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        second[i][j] +=
            v6 / 120.0 *
            (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + (a[i] + b[i] + c[i]) * (a[j] + b[j] + c[j]));
      }
    }
  }
  const auto [lo, hi] = BoundsOf(coarse.vertices);
  const glm::dvec3 size = hi - lo;
  const double box_volume = size.x * size.y * size.z;
  if (closed && volume > 1e-6 * box_volume && volume > 0.0) {
    model.mass_kg = density * volume;
    model.center_of_mass_O = first / volume;
    const glm::dvec3 c = model.center_of_mass_O;
    // Inertia about the centre of mass: I = ρ(tr(S)·1 − S) with S the second moment about c.
    glm::dmat3 s_c{0.0};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) s_c[i][j] = second[i][j] - volume * c[i] * c[j];
    }
    const double trace = s_c[0][0] + s_c[1][1] + s_c[2][2];
    model.inertia_diagonal_O =
        density * glm::dvec3(trace - s_c[0][0], trace - s_c[1][1], trace - s_c[2][2]);
  } else {
    // Open surface or no enclosed volume: the solid bounding box stands in.
    const double v = std::max(box_volume, 1e-12);
    model.mass_kg = density * v;
    model.center_of_mass_O = 0.5 * (lo + hi);
    const double m = model.mass_kg;
    model.inertia_diagonal_O =
        m / 12.0 *
        glm::dvec3(size.y * size.y + size.z * size.z, size.x * size.x + size.z * size.z,
                   size.x * size.x + size.y * size.y);
  }
}

}  // namespace

void TextureSizingParams::Validate() const {
  if (!IsSizingSize(min_size) || !IsSizingSize(max_size) || min_size > max_size) {
    throw std::invalid_argument(
        "texture sizing: min_size and max_size must be powers of two with 16 <= min_size <= "
        "max_size <= 8192, got " +
        std::to_string(min_size) + " and " + std::to_string(max_size));
  }
  if (!(surface_budget_m > 0.0) || !std::isfinite(surface_budget_m)) {
    throw std::invalid_argument("texture sizing: surface_budget_m must be finite and > 0");
  }
  if (!(min_improvement >= 0.0 && min_improvement < 1.0)) {
    throw std::invalid_argument("texture sizing: min_improvement must be in [0, 1)");
  }
}

TextureSizeChoice ChooseTextureSize(const TextureSizingParams& params,
                                    const std::function<SurfaceErrorReport(int size)>& measure) {
  params.Validate();
  TextureSizeChoice c;
  char why[320];
  const double budget_um = params.surface_budget_m * 1e6;
  for (int size = params.min_size;; size *= 2) {
    const auto start = std::chrono::steady_clock::now();
    const SurfaceErrorReport e = measure(size);
    c.trials.push_back({size, e.p99_m, e.outside_p99_m, Seconds(start)});
    const double p99_um = e.p99_m * 1e6;
    if (e.samples == 0) {
      c.size = size;
      std::snprintf(why, sizeof why,
                    "%d: the surface error could not be measured (a full-resolution mesh "
                    "without area), so this size is kept",
                    size);
      break;
    }
    if (e.p99_m <= params.surface_budget_m) {
      c.size = size;
      std::snprintf(why, sizeof why,
                    "%d: the full-resolution surface lies within %.3g um of the model (p99), "
                    "within the budget of %.3g um",
                    size, p99_um, budget_um);
      break;
    }
    if (c.trials.size() >= 2) {
      const TextureSizeTrial& before = c.trials[c.trials.size() - 2];
      if (e.p99_m > (1.0 - params.min_improvement) * before.surface_p99_m) {
        c.size = before.size;
        std::snprintf(why, sizeof why,
                      "%d: doubling it to %d moves the surface error p99 only from %.3g to "
                      "%.3g um (less than %.0f %% lower; budget %.3g um): the error left is the "
                      "coarse mesh's, not the texture's",
                      before.size, size, before.surface_p99_m * 1e6, p99_um,
                      100.0 * params.min_improvement, budget_um);
        break;
      }
    }
    if (size >= params.max_size) {
      c.size = size;
      std::snprintf(why, sizeof why,
                    "%d, the largest size allowed: the surface error p99 is still %.3g um, above "
                    "the budget of %.3g um (more coarse triangles may lower it)",
                    size, p99_um, budget_um);
      break;
    }
  }
  c.reason = why;
  return c;
}

HapticModelBuild BuildHapticModel(const std::string& name, const TriangleMesh& full_O,
                                  const HapticModelBuildParams& params) {
  const auto start = std::chrono::steady_clock::now();
  if (params.coarse_triangles < 4) {
    throw std::invalid_argument(name + ": coarse_triangles must be at least 4, got " +
                                std::to_string(params.coarse_triangles));
  }
  if (!(params.density_kg_per_m3 > 0.0) || !std::isfinite(params.density_kg_per_m3)) {
    throw std::invalid_argument(name + ": density must be positive and finite");
  }
  HapticModelBuild build;
  HapticModelBuildReport& rep = build.report;
  rep.name = name;
  rep.full_triangles = static_cast<std::int64_t>(full_O.triangles.size());
  auto model = std::make_shared<HapticModel>();
  model->name = name;
  model->full_resolution_triangles = rep.full_triangles;

  DecimationResult coarse;
  try {
    coarse = DecimateQuadric(full_O, params.coarse_triangles);
  } catch (const std::exception& e) {
    throw std::invalid_argument(name + ": " + e.what());
  }
  rep.decimate_s = coarse.seconds;
  rep.welded_vertices = coarse.welded_vertices;
  rep.dropped_non_manifold_triangles = coarse.dropped_non_manifold_triangles;
  rep.input_boundary_edges = coarse.input_boundary_edges;
  rep.coarse_boundary_edges = coarse.output_boundary_edges;
  rep.coarse_triangles = static_cast<std::int64_t>(coarse.mesh.triangles.size());
  model->vertices_O = coarse.mesh.vertices;
  model->triangles = coarse.mesh.triangles;

  auto stage = std::chrono::steady_clock::now();
  const auto bake = [&](int size) {
    TextureBakeParams texture = params.texture;
    texture.texture_size = size;
    try {
      return BakeHapticTexture(coarse.mesh, full_O, texture);
    } catch (const std::exception& e) {
      throw std::invalid_argument(name + ": texture bake at " + std::to_string(size) +
                                  "²: " + e.what());
    }
  };
  if (params.texture_sizing.from_detail) {
    TextureSizingParams sizing = params.texture_sizing;
    try {
      sizing.Validate();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(name + ": " + e.what());
    }
    // Sizes whose charts would not fit the coarse triangles are not tried.
    const int fits = SmallestAtlasSize(static_cast<int>(coarse.mesh.triangles.size()),
                                       params.texture.gutter_texels);
    if (fits == 0 || fits > sizing.max_size) {
      throw std::invalid_argument(name + ": " + std::to_string(coarse.mesh.triangles.size()) +
                                  " coarse triangles do not fit an atlas of the largest size "
                                  "allowed (" +
                                  std::to_string(sizing.max_size) +
                                  "²): raise max_size or lower coarse_triangles");
    }
    sizing.min_size = std::max(sizing.min_size, fits);
    // Each size baked into a model of its own (the coarse mesh without hulls suffices for the
    // surface error); the chosen one's texture moves into `model`.
    std::vector<std::pair<int, HapticModel>> tried;
    std::vector<TextureBakeReport> reports;
    const TextureSizeChoice choice = ChooseTextureSize(sizing, [&](int size) {
      HapticModel m;
      m.name = name;
      m.vertices_O = coarse.mesh.vertices;
      m.triangles = coarse.mesh.triangles;
      BakedTexture baked = bake(size);
      reports.push_back(baked.report);
      ApplyBakedTexture(std::move(baked), m);
      SurfaceErrorReport surface = MeasuredSurface(m, full_O);
      // Only the last two sizes can be chosen (the rule keeps the latest or the one before).
      if (tried.size() == 2) tried.erase(tried.begin());
      tried.emplace_back(size, std::move(m));
      return surface;
    });
    for (auto& [size, m] : tried) {
      if (size != choice.size) continue;
      model->corner_normals_O = std::move(m.corner_normals_O);
      model->corner_uvs = std::move(m.corner_uvs);
      model->textured = std::move(m.textured);
      model->texel_size_m = std::move(m.texel_size_m);
      model->texture = std::move(m.texture);
    }
    for (std::size_t i = 0; i < choice.trials.size(); ++i) {
      if (choice.trials[i].size == choice.size) rep.bake = reports[i];
    }
    rep.texture_trials = choice.trials;
    rep.texture_size_reason = choice.reason;
  } else {
    BakedTexture baked = bake(params.texture.texture_size);
    rep.bake = baked.report;
    ApplyBakedTexture(std::move(baked), *model);
  }
  rep.bake_s = Seconds(stage);
  rep.texture_size = model->texture.empty() ? 0 : model->texture.level(0).width;
  if (!model->texture.empty()) {
    // 99.9th percentile of the positive heights (see HapticModel::outward_reach_m).
    std::vector<float> positive;
    for (const float h : model->texture.level(0).texels) {
      if (h > 0.0f) positive.push_back(h);
    }
    double reach = 0.0;
    if (!positive.empty()) {
      const auto k = static_cast<std::size_t>(0.999 * static_cast<double>(positive.size() - 1));
      std::nth_element(positive.begin(), positive.begin() + static_cast<std::ptrdiff_t>(k),
                       positive.end());
      reach = positive[k];
    }
    model->outward_reach_m = reach;
  }
  rep.outward_reach_m = model->OutwardReach();

  stage = std::chrono::steady_clock::now();
  try {
    model->hull_hierarchy =
        BuildConvexHullHierarchy(coarse.mesh.vertices, coarse.mesh.triangles, params.hulls);
  } catch (const std::exception& e) {
    throw std::invalid_argument(name + ": convex-hull hierarchy: " + e.what());
  }
  rep.hulls_s = Seconds(stage);
  model->hull_vertices_O = model->hull_hierarchy.nodes.front().hull.vertices_O;
  rep.hull_nodes = static_cast<int>(model->hull_hierarchy.nodes.size());
  rep.hull_leaves = model->hull_hierarchy.LeafCount();
  rep.hull_depth = model->hull_hierarchy.Depth();

  SetMassProperties(coarse.mesh, coarse.output_boundary_edges == 0, params.density_kg_per_m3,
                    *model);
  model->Validate();
  rep.surface = MeasuredSurface(*model, full_O);
  rep.total_s = Seconds(start);
  build.model = std::move(model);
  return build;
}

}  // namespace ht
