#pragma once
// Coarse meshes for the haptic model (DESIGN.md §2): quadric edge-collapse decimation of a
// full-resolution triangle mesh through OpenMesh (Garland & Heckbert 1997, "Surface
// simplification using quadric error metrics").

#include <cstdint>

#include "haptic_core/haptic_model.h"

namespace ht {

/// What DecimateQuadric() returns: the coarse mesh and what happened on the way.
struct DecimationResult {
  /// The coarse mesh, same frame and units as the input; #V vertices (only those that triangles
  /// use) and #F triangles with the input's winding.
  TriangleMesh mesh;
  /// Triangles and vertices of the input.
  std::int64_t input_triangles = 0;
  std::int64_t input_vertices = 0;
  /// Vertices left after welding the input's vertices that share a position exactly (glTF files
  /// split vertices along normal and UV seams; welding makes the surface one connected piece).
  std::int64_t welded_vertices = 0;
  /// Input triangles that could not join the welded surface because they would make it
  /// non-manifold (an edge with three faces, a flipped neighbour); they are left out of the
  /// decimation and counted here.
  std::int64_t dropped_non_manifold_triangles = 0;
  /// Boundary (one-sided) edges of the welded input and of the output. 0 means closed; quadric
  /// collapses never open a closed surface (OpenMesh refuses collapses that change topology).
  std::int64_t input_boundary_edges = 0;
  std::int64_t output_boundary_edges = 0;
  /// Vertices still of valence above 64 at the end (fan centres), which were kept out of the
  /// collapses: OpenMesh re-scores every edge around such a vertex after each neighbouring
  /// collapse, at a cost of the square of the valence. Fans are thinned in a first pass to 4× the
  /// target, after which most centres have a low valence and are collapsed like any vertex.
  std::int64_t locked_high_valence_vertices = 0;
  /// Wall time (s).
  double seconds = 0.0;
};

/// Decimates `full` (#V vertices, #F triangles, counter-clockwise seen from outside) to at most
/// `target_triangles` triangles by quadric edge collapses, with OpenMesh's normal-flip guard
/// (no collapse turns a face normal by more than 90°). Vertices at the same position are welded
/// first. When the input already has no more than `target_triangles` triangles, the welded input
/// is returned. The count reached can stay above the target when no further collapse is legal
/// (e.g. a closed surface cannot go below 4 triangles).
///
/// Throws std::invalid_argument when `target_triangles` < 4, a vertex is not finite, or a
/// triangle indexes a vertex out of range; std::runtime_error when no triangle of the input
/// forms a manifold surface.
///
/// Calls on different meshes may run on several threads at once (OpenMesh's error stream, which
/// is silenced while faces are added, is shared and counted).
DecimationResult DecimateQuadric(const TriangleMesh& full, int target_triangles);

}  // namespace ht
