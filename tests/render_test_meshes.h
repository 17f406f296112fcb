#pragma once
// Meshes the display tests draw: scene_renderer_test and display_window_test.

#include "master_station/scene_renderer.h"

namespace ht::testing_support {

/// A cube of half side `half` (m) centred on the origin of its mesh frame N, axis-aligned, its
/// triangles counter-clockwise seen from outside.
inline RenderMesh Cube(double half) {
  const float h = static_cast<float>(half);
  RenderMesh m;
  for (int i = 0; i < 8; ++i) {
    m.positions_N.push_back({(i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h});
  }
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

}  // namespace ht::testing_support
