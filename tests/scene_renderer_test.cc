// The operator's scene renderer on a real headless EGL context (Mesa llvmpipe on machines without
// a GPU; skipped where no context can be made at all): pixels of a known scene checked against
// projections computed by hand for an axis-aligned camera and with ProjectToPixel for others,
// ghosts, force arrows, poses and mesh replacement, textures (a checker quad, sRGB decoding, the
// Duck), PNG files, images decoded from memory (PNG, JPEG, garbage), and bad arguments.
#include "master_station/scene_renderer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <glm/ext/matrix_transform.hpp>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <utility>

// clang-format off
#include <cstdio>  // jpeglib.h needs FILE and size_t first
#include <jpeglib.h>
// clang-format on

#include "codecs/gltf_scene.h"
#include "gltf_test_data.h"
#include "master_station/png_image.h"
#include "render_test_meshes.h"

namespace ht {
namespace {

constexpr int kWidth = 160;
constexpr int kHeight = 120;
constexpr double kHalf = 0.01;  // the cube's half edge (m): a 0.02 m cube
// A background of exact 8-bit values, so that "equals the background" can be checked exactly.
constexpr glm::vec4 kBackground{26.f / 255.f, 26.f / 255.f, 31.f / 255.f, 1.f};
constexpr std::array<std::uint8_t, 4> kBackgroundBytes{26, 26, 31, 255};

using Rgba = std::array<std::uint8_t, 4>;

using testing_support::Cube;

RenderMesh Sphere(double radius, int rings, int segments) {
  RenderMesh m;
  for (int r = 0; r <= rings; ++r) {
    const double theta = std::numbers::pi * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2.0 * std::numbers::pi * s / segments;
      m.positions_N.push_back(glm::vec3(radius * std::sin(theta) * std::cos(phi),
                                        radius * std::cos(theta),
                                        radius * std::sin(theta) * std::sin(phi)));
    }
  }
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const unsigned a = r * segments + s, b = r * segments + (s + 1) % segments;
      const unsigned c = a + segments, d = b + segments;
      m.triangles.push_back({a, c, b});
      m.triangles.push_back({b, c, d});
    }
  }
  return m;
}

// Looking down −z from (0, 0, distance) at the origin, y up: the camera of the hand computations.
RenderCamera AxisCamera(double distance = 0.1) {
  RenderCamera c;
  c.eye_W = {0, 0, distance};
  c.target_W = {0, 0, 0};
  c.up_W = {0, 1, 0};
  c.yfov_rad = 0.8;
  c.near_m = 0.001;
  c.far_m = 10.0;
  return c;
}

// The pinhole projection written out for AxisCamera: focal length f = (h/2)/tan(yfov/2) pixels,
// x = w/2 + f·X/(d − Z), y = h/2 − f·Y/(d − Z) (image y down).
glm::dvec2 HandProjection(const RenderCamera& c, int w, int h, const glm::dvec3& p) {
  const double f = 0.5 * h / std::tan(0.5 * c.yfov_rad);
  const double depth = c.eye_W.z - p.z;
  return {0.5 * w + f * p.x / depth, 0.5 * h - f * p.y / depth};
}

std::vector<glm::dvec3> Corners(const glm::dmat4& X_WN, double half) {
  std::vector<glm::dvec3> corners;
  for (int i = 0; i < 8; ++i) {
    const glm::dvec4 p_N((i & 1) ? half : -half, (i & 2) ? half : -half, (i & 4) ? half : -half,
                         1.0);
    corners.push_back(glm::dvec3(X_WN * p_N));
  }
  return corners;
}

// Continuous bounding box (pixels) of projected points: {x_min, y_min, x_max, y_max}.
std::array<double, 4> ProjectedBox(const RenderCamera& c, const std::vector<glm::dvec3>& points) {
  std::array<double, 4> box{1e9, 1e9, -1e9, -1e9};
  for (const glm::dvec3& p : points) {
    glm::dvec2 px;
    EXPECT_TRUE(ProjectToPixel(c, kWidth, kHeight, p, &px));
    box = {std::min(box[0], px.x), std::min(box[1], px.y), std::max(box[2], px.x),
           std::max(box[3], px.y)};
  }
  return box;
}

Rgba At(const std::vector<std::uint8_t>& img, int width, int i, int j) {
  const std::size_t k = 4 * (static_cast<std::size_t>(j) * width + i);
  return {img[k], img[k + 1], img[k + 2], img[k + 3]};
}

// Pixel indices {i_min, j_min, i_max, j_max} of everything that is not the background; i_min >
// i_max when there is none.
std::array<int, 4> NonBackgroundBox(const std::vector<std::uint8_t>& img) {
  std::array<int, 4> box{kWidth, kHeight, -1, -1};
  for (int j = 0; j < kHeight; ++j) {
    for (int i = 0; i < kWidth; ++i) {
      if (At(img, kWidth, i, j) != kBackgroundBytes) {
        box = {std::min(box[0], i), std::min(box[1], j), std::max(box[2], i), std::max(box[3], j)};
      }
    }
  }
  return box;
}

// Whether an 8-bit pixel is kForceArrowColour times one shade in [0.7, 1] (arrows are lit
// lightly), within rounding.
bool IsArrowColour(const Rgba& p) {
  const double r = p[0], g = p[1], b = p[2];
  if (r < 0.7 * 255 * kForceArrowColour.r - 2) return false;
  const double s = r / (255.0 * kForceArrowColour.r);
  return std::abs(g - s * 255 * kForceArrowColour.g) <= 2.5 &&
         std::abs(b - s * 255 * kForceArrowColour.b) <= 2.5 && p[3] == 255;
}

std::string Show(const Rgba& p) {
  return "(" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ", " + std::to_string(p[2]) +
         ", " + std::to_string(p[3]) + ")";
}

class SceneRendererTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { setenv("MESA_SHADER_CACHE_DISABLE", "true", 0); }

  void SetUp() override {
    try {
      renderer_ = SceneRenderer::Create(kWidth, kHeight);
    } catch (const GpuError& e) {
      GTEST_SKIP() << "no EGL context: " << e.what();
    }
    cube_ = renderer_->AddMesh(Cube(kHalf));
  }

  RenderFrame CubeFrame(const glm::dmat4& X_WN, const glm::vec4& colour) const {
    RenderFrame f;
    f.camera = AxisCamera();
    f.background_rgba = kBackground;
    f.items.push_back({.mesh = cube_, .X_WN = X_WN, .colour_rgba = colour});
    return f;
  }

  std::vector<std::uint8_t> Draw(const RenderFrame& frame) {
    std::vector<std::uint8_t> img;
    renderer_->Render(frame, &img);
    EXPECT_EQ(img.size(), static_cast<std::size_t>(kWidth) * kHeight * 4);
    return img;
  }

  std::unique_ptr<SceneRenderer> renderer_;
  int cube_ = -1;
};

TEST_F(SceneRendererTest, ReportsWhatItRunsOn) {
  EXPECT_EQ(renderer_->width(), kWidth);
  EXPECT_EQ(renderer_->height(), kHeight);
  EXPECT_FALSE(renderer_->gpu().renderer.empty());
  std::cout << "renderer: " << renderer_->gpu().renderer << ", " << renderer_->gpu().version << " ("
            << renderer_->gpu().platform << ")\n";
}

TEST_F(SceneRendererTest, ProjectToPixelAgreesWithTheHandProjection) {
  const RenderCamera c = AxisCamera();
  for (const glm::dvec3& p : {glm::dvec3(0, 0, 0), glm::dvec3(0.01, 0.01, 0.01),
                              glm::dvec3(-0.03, 0.02, -0.05), glm::dvec3(0.2, -0.1, -1.0)}) {
    glm::dvec2 px;
    ASSERT_TRUE(ProjectToPixel(c, kWidth, kHeight, p, &px));
    const glm::dvec2 hand = HandProjection(c, kWidth, kHeight, p);
    EXPECT_NEAR(px.x, hand.x, 1e-9) << p.x << " " << p.y << " " << p.z;
    EXPECT_NEAR(px.y, hand.y, 1e-9) << p.x << " " << p.y << " " << p.z;
  }
  // The image centre is the target; behind the eye there is no pixel.
  glm::dvec2 px(-1.0);
  ASSERT_TRUE(ProjectToPixel(c, kWidth, kHeight, c.target_W, &px));
  EXPECT_DOUBLE_EQ(px.x, kWidth / 2.0);
  EXPECT_DOUBLE_EQ(px.y, kHeight / 2.0);
  EXPECT_FALSE(ProjectToPixel(c, kWidth, kHeight, {0, 0, 0.2}, &px));
  EXPECT_FALSE(ProjectToPixel(c, kWidth, kHeight, c.eye_W, &px));
}

TEST_F(SceneRendererTest, CubeCentreHasTheCubesColourAndTheFrontFaceIsLitFully) {
  const glm::vec4 green{0.2f, 0.7f, 0.3f, 1.f};
  const auto img = Draw(CubeFrame(glm::dmat4(1.0), green));
  // The cube centre projects onto the image centre (80, 60): the four pixels around it lie on the
  // front face, which faces the headlight: shade 0.3 + 0.7·cos(angle < 0.1°) = colour.
  for (int j : {59, 60}) {
    for (int i : {79, 80}) {
      const Rgba p = At(img, kWidth, i, j);
      EXPECT_NEAR(p[0], 0.2 * 255, 1.5) << Show(p);
      EXPECT_NEAR(p[1], 0.7 * 255, 1.5) << Show(p);
      EXPECT_NEAR(p[2], 0.3 * 255, 1.5) << Show(p);
      EXPECT_EQ(p[3], 255);
    }
  }
  // Oblique: the cube turned and moved, seen from above and behind; the centre's pixel is
  // dominated by the cube's hue and is not the background.
  RenderFrame f = CubeFrame(glm::translate(glm::dmat4(1.0), glm::dvec3(0.01, -0.005, 0.0)) *
                                glm::rotate(glm::dmat4(1.0), 0.5, glm::dvec3(1, 1, 0)),
                            green);
  f.camera = FollowCamera({0.01, -0.005, 0.0}, {0, 1, 0}, 0.12);
  const auto oblique = Draw(f);
  glm::dvec2 centre;
  ASSERT_TRUE(ProjectToPixel(f.camera, kWidth, kHeight, {0.01, -0.005, 0.0}, &centre));
  const Rgba p = At(oblique, kWidth, static_cast<int>(centre.x), static_cast<int>(centre.y));
  EXPECT_NE(p, kBackgroundBytes);
  EXPECT_GT(p[1], p[0]) << Show(p);
  EXPECT_GT(p[1], p[2]) << Show(p);
  EXPECT_GE(p[1], 0.3 * 0.7 * 255) << Show(p);  // at least the ambient term
}

TEST_F(SceneRendererTest, EverythingOutsideTheProjectedSilhouetteIsExactlyTheBackground) {
  const auto img = Draw(CubeFrame(glm::dmat4(1.0), {0.8f, 0.8f, 0.2f, 1.f}));
  // By hand: the silhouette is the front face (z = +h, depth 0.09 m), a square of half-width
  // f·h/0.09 around the centre; f = 60/tan(0.4) ≈ 141.9 px, so about 15.8 px.
  const double f = 0.5 * kHeight / std::tan(0.4);
  const double half_px = f * kHalf / (0.1 - kHalf);
  const std::array<double, 4> hand{80 - half_px, 60 - half_px, 80 + half_px, 60 + half_px};
  const std::array<double, 4> box = ProjectedBox(AxisCamera(), Corners(glm::dmat4(1.0), kHalf));
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(box[k], hand[k], 1e-9) << k;
  int inside = 0;
  for (int j = 0; j < kHeight; ++j) {
    for (int i = 0; i < kWidth; ++i) {
      const double x = i + 0.5, y = j + 0.5;  // pixel centre
      const Rgba p = At(img, kWidth, i, j);
      if (x < hand[0] - 1 || x > hand[2] + 1 || y < hand[1] - 1 || y > hand[3] + 1) {
        ASSERT_EQ(p, kBackgroundBytes) << "pixel " << i << ", " << j << " outside the silhouette";
      } else if (x > hand[0] + 1 && x < hand[2] - 1 && y > hand[1] + 1 && y < hand[3] - 1) {
        ASSERT_NE(p, kBackgroundBytes) << "pixel " << i << ", " << j << " inside the silhouette";
        ++inside;
      }
    }
  }
  EXPECT_GT(inside, 25 * 25);
}

TEST_F(SceneRendererTest, NonBackgroundPixelsFillTheProjectedBoxAtAnyPose) {
  // Each pose: the box of non-background pixels equals the box of the projected corners (the
  // pixels whose centres it covers) within one pixel. Offsets up and left check the row order.
  const std::vector<glm::dmat4> poses = {
      glm::dmat4(1.0),
      glm::translate(glm::dmat4(1.0), glm::dvec3(0.02, 0.0, 0.0)),
      glm::translate(glm::dmat4(1.0), glm::dvec3(-0.015, 0.02, -0.01)),
      glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, -0.01, 0.02)) *
          glm::rotate(glm::dmat4(1.0), 0.7, glm::dvec3(0.3, 1.0, 0.2)),
      glm::scale(glm::dmat4(1.0), glm::dvec3(1.5, 0.5, 1.0)),
  };
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const auto img = Draw(CubeFrame(poses[k], {0.5f, 0.5f, 0.9f, 1.f}));
    const std::array<double, 4> box = ProjectedBox(AxisCamera(), Corners(poses[k], kHalf));
    const std::array<int, 4> seen = NonBackgroundBox(img);
    const std::array<double, 4> expected{std::ceil(box[0] - 0.5), std::ceil(box[1] - 0.5),
                                         std::floor(box[2] - 0.5), std::floor(box[3] - 0.5)};
    for (int e = 0; e < 4; ++e) {
      EXPECT_NEAR(seen[e], expected[e], 1.0) << "pose " << k << ", box edge " << e;
    }
  }
}

TEST_F(SceneRendererTest, MovingThePoseMovesTheSilhouette) {
  const glm::vec4 colour{0.9f, 0.6f, 0.2f, 1.f};
  const auto a = Draw(CubeFrame(glm::dmat4(1.0), colour));
  const auto b =
      Draw(CubeFrame(glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, 0.015, 0.0)), colour));
  const std::array<int, 4> box_a = NonBackgroundBox(a), box_b = NonBackgroundBox(b);
  // Up by 15 mm. By hand (f = 60/tan 0.4 px): the top edge stays the front face's top edge (depth
  // 90 mm) and moves up f·0.015/0.09 ≈ 23.6 px; the bottom edge was the front face's bottom edge
  // (y = −10 mm, depth 90 mm) and is now the back face's bottom edge (y = +5 mm, depth 110 mm:
  // the bottom face is above the eye and shows), f·(0.01/0.09 + 0.005/0.11) ≈ 22.2 px higher.
  const double f = 0.5 * kHeight / std::tan(0.4);
  EXPECT_NEAR(box_a[1] - box_b[1], f * 0.015 / 0.09, 1.0);
  EXPECT_NEAR(box_a[3] - box_b[3], f * (0.01 / 0.09 + 0.005 / 0.11), 1.0);
  EXPECT_EQ(box_a[0], box_b[0]);
  EXPECT_EQ(box_a[2], box_b[2]);
  // The bottom row the cube covered before shows the background now.
  EXPECT_EQ(At(b, kWidth, 80, box_a[3]), kBackgroundBytes);
  EXPECT_NE(At(a, kWidth, 80, box_a[3]), kBackgroundBytes);
}

TEST_F(SceneRendererTest, ForceArrowAndContactMarkerShowInTheArrowColour) {
  // A contact on the cube's top face, pushing up with 2 N at 0.01 m/N: a 20 mm arrow along +y,
  // seen obliquely so that it is not along a pixel row or column.
  const glm::vec4 grey{0.6f, 0.6f, 0.6f, 1.f};
  RenderFrame f = CubeFrame(glm::dmat4(1.0), grey);
  f.camera = AxisCamera();
  f.camera.eye_W = {0.04, 0.03, 0.1};
  const glm::dvec3 contact_W(0.003, kHalf, 0.002);
  const glm::dvec3 force_W(0.0, 2.0, 0.0);
  f.arrow_m_per_n = 0.01;
  const auto without = Draw(f);
  f.arrows.push_back({contact_W, force_W});
  const auto with = Draw(f);
  const auto arrow_near = [&](const std::vector<std::uint8_t>& img, const glm::dvec3& p_W) {
    glm::dvec2 px;
    EXPECT_TRUE(ProjectToPixel(f.camera, kWidth, kHeight, p_W, &px));
    int found = 0;
    for (int dj = -1; dj <= 1; ++dj) {
      for (int di = -1; di <= 1; ++di) {
        found += IsArrowColour(
            At(img, kWidth, static_cast<int>(px.x) + di, static_cast<int>(px.y) + dj));
      }
    }
    return found;
  };
  const glm::dvec3 half_W = contact_W + 0.5 * f.arrow_m_per_n * force_W;
  EXPECT_GT(arrow_near(with, half_W), 0) << "no arrow pixel near the middle of the arrow";
  EXPECT_GT(arrow_near(with, contact_W), 0) << "no marker pixel at the contact point";
  EXPECT_GT(arrow_near(with, contact_W + 0.85 * f.arrow_m_per_n * force_W), 0) << "no head";
  EXPECT_EQ(arrow_near(without, half_W), 0);
  EXPECT_EQ(arrow_near(without, contact_W), 0);
  // Nothing of the arrow beyond its tip (3 mm further on) nor beside it (8 mm off its axis).
  EXPECT_EQ(arrow_near(with, contact_W + f.arrow_m_per_n * force_W + glm::dvec3(0, 0.003, 0)), 0);
  EXPECT_EQ(arrow_near(with, half_W + glm::dvec3(0.008, 0, 0)), 0);
  // A zero force still marks the contact point, with no arrow.
  f.arrows = {{contact_W, glm::dvec3(0.0)}};
  const auto zero = Draw(f);
  EXPECT_GT(arrow_near(zero, contact_W), 0);
  EXPECT_EQ(arrow_near(zero, half_W), 0);
}

TEST_F(SceneRendererTest, GhostBlendsBetweenBackgroundAndItsColour) {
  const glm::vec4 red{0.9f, 0.1f, 0.1f, 1.f};
  RenderFrame f = CubeFrame(glm::dmat4(1.0), red);
  f.items[0].ghost = true;
  const auto img = Draw(f);
  // Front face, shade 1: 0.3·colour + 0.7·background.
  const Rgba p = At(img, kWidth, 80, 60);
  for (int c = 0; c < 3; ++c) {
    const double expected = 255.0 * (0.3 * red[c] + 0.7 * kBackground[c]);
    EXPECT_NEAR(p[c], expected, 2.0) << "channel " << c << " " << Show(p);
  }
  EXPECT_GT(p[0], kBackgroundBytes[0]);
  EXPECT_LT(p[0], 0.9 * 255 - 10);
  EXPECT_EQ(p[3], 255);
  // Outside it, the background is untouched.
  EXPECT_EQ(At(img, kWidth, 5, 5), kBackgroundBytes);

  // A ghost in front of an opaque item shows the item through it; one behind it is hidden, and
  // draw order in the frame does not matter (opaque items go first).
  const glm::vec4 blue{0.1f, 0.2f, 0.9f, 1.f};
  RenderFrame both;
  both.camera = AxisCamera();
  both.background_rgba = kBackground;
  both.items.push_back({.mesh = cube_,
                        .X_WN = glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 0.03)),
                        .colour_rgba = red,
                        .ghost = true});
  both.items.push_back({.mesh = cube_, .X_WN = glm::dmat4(1.0), .colour_rgba = blue});
  const Rgba front = At(Draw(both), kWidth, 80, 60);
  for (int c = 0; c < 3; ++c) {
    const double expected = 255.0 * (0.3 * red[c] + 0.7 * blue[c]);
    EXPECT_NEAR(front[c], expected, 2.0) << "channel " << c << " " << Show(front);
  }
  both.items[0].X_WN = glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, -0.03));
  const Rgba behind = At(Draw(both), kWidth, 80, 60);
  EXPECT_NEAR(behind[0], 0.1 * 255, 1.5) << Show(behind);
  EXPECT_NEAR(behind[2], 0.9 * 255, 1.5) << Show(behind);
}

TEST_F(SceneRendererTest, ReplaceMeshChangesWhatItemsDraw) {
  const auto big = Draw(CubeFrame(glm::dmat4(1.0), {0.7f, 0.7f, 0.7f, 1.f}));
  renderer_->ReplaceMesh(cube_, Cube(kHalf / 2));
  const auto small = Draw(CubeFrame(glm::dmat4(1.0), {0.7f, 0.7f, 0.7f, 1.f}));
  const std::array<double, 4> box = ProjectedBox(AxisCamera(), Corners(glm::dmat4(1.0), kHalf / 2));
  const std::array<int, 4> seen = NonBackgroundBox(small);
  EXPECT_NEAR(seen[0], std::ceil(box[0] - 0.5), 1.0);
  EXPECT_NEAR(seen[2], std::floor(box[2] - 0.5), 1.0);
  EXPECT_LT(seen[2] - seen[0], NonBackgroundBox(big)[2] - NonBackgroundBox(big)[0] - 10);
  // A second mesh gets the next index and draws independently.
  EXPECT_EQ(renderer_->AddMesh(Cube(kHalf)), cube_ + 1);
}

TEST_F(SceneRendererTest, BadArgumentsThrow) {
  EXPECT_THROW(SceneRenderer::Create(0, 10), std::invalid_argument);
  EXPECT_THROW(SceneRenderer::Create(10, 0), std::invalid_argument);
  EXPECT_THROW(SceneRenderer::Create(4097, 10), std::invalid_argument);
  EXPECT_THROW(SceneRenderer::Create(-1, -1), std::invalid_argument);

  RenderMesh out_of_range = Cube(kHalf);
  out_of_range.triangles.push_back({0, 1, 8});
  EXPECT_THROW(renderer_->AddMesh(out_of_range), std::invalid_argument);
  RenderMesh nan_vertex = Cube(kHalf);
  nan_vertex.positions_N[3].y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(renderer_->AddMesh(nan_vertex), std::invalid_argument);
  RenderMesh inf_vertex = Cube(kHalf);
  inf_vertex.positions_N[0].x = std::numeric_limits<float>::infinity();
  EXPECT_THROW(renderer_->ReplaceMesh(cube_, inf_vertex), std::invalid_argument);
  EXPECT_THROW(renderer_->ReplaceMesh(cube_ + 1, Cube(kHalf)), std::invalid_argument);
  EXPECT_THROW(renderer_->ReplaceMesh(-1, Cube(kHalf)), std::invalid_argument);

  std::vector<std::uint8_t> img;
  const RenderFrame good = CubeFrame(glm::dmat4(1.0), {0.5f, 0.5f, 0.5f, 1.f});
  EXPECT_THROW(renderer_->Render(good, nullptr), std::invalid_argument);
  RenderFrame f = good;
  f.items[0].mesh = cube_ + 1;
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.items[0].mesh = -1;  // the RenderItem default
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.items[0].X_WN[3][1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.arrows.push_back({{0, 0, 0}, {0, std::numeric_limits<double>::infinity(), 0}});
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.arrow_m_per_n = -0.01;
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.camera.target_W = f.camera.eye_W;
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.camera.up_W = {0, 0, 1};  // along the view direction
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  f = good;
  f.camera.near_m = 0.0;
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
  EXPECT_TRUE(img.empty()) << "a refused frame draws nothing";
  // The mesh the failed replacement named is intact.
  renderer_->Render(good, &img);
  EXPECT_NE(At(img, kWidth, 80, 60), kBackgroundBytes);

  EXPECT_THROW(FollowCamera({0, 0, 0}, {0, 0, 0}, 1.0), std::invalid_argument);
  EXPECT_THROW(FollowCamera({0, 0, 0}, {0, 1, 0}, 0.0), std::invalid_argument);
  EXPECT_THROW(FollowCamera({0, 0, 0}, {0, 1, 0}, std::nan("")), std::invalid_argument);
  glm::dvec2 px;
  EXPECT_THROW(ProjectToPixel(good.camera, 0, 10, {0, 0, 0}, &px), std::invalid_argument);
}

TEST_F(SceneRendererTest, FollowCameraLooksAtItsTargetFromAboveAndBehind) {
  for (const glm::dvec3& up : {glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1), glm::dvec3(1, 1, 0)}) {
    const glm::dvec3 target(0.1, -0.2, 0.3);
    const RenderCamera c = FollowCamera(target, up, 0.25);
    EXPECT_NEAR(glm::length(c.eye_W - target), 0.25, 1e-12);
    // Above: the eye is higher than the target along up, by sin(35°)·distance.
    EXPECT_NEAR(glm::dot(c.eye_W - target, glm::normalize(up)),
                0.25 * std::sin(35 * std::numbers::pi / 180), 1e-12);
    glm::dvec2 px;
    ASSERT_TRUE(ProjectToPixel(c, kWidth, kHeight, target, &px));
    EXPECT_NEAR(px.x, kWidth / 2.0, 1e-9);
    EXPECT_NEAR(px.y, kHeight / 2.0, 1e-9);
    // A point above the target along up appears higher in the image (smaller y).
    glm::dvec2 above;
    ASSERT_TRUE(ProjectToPixel(c, kWidth, kHeight, target + 0.02 * glm::normalize(up), &above));
    EXPECT_LT(above.y, px.y - 5);
  }
}

// ---- Textures.

// sRGB decoding (IEC 61966-2-1) of an 8-bit value, and encoding of a linear value to 8 bits.
double SrgbToLinear(std::uint8_t byte) {
  const double c = byte / 255.0;
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}
double LinearToSrgbByte(double linear) {
  const double c = linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;
  return 255.0 * c;
}

// A 2 x 2 checker of four distinct colours, row 0 the top: texel (column, row).
constexpr std::array<Rgba, 4> kChecker = {
    Rgba{200, 40, 40, 255}, Rgba{40, 180, 60, 255},    // top-left, top-right
    Rgba{50, 70, 220, 255}, Rgba{230, 210, 90, 255}};  // bottom-left, bottom-right

std::vector<std::uint8_t> CheckerBytes() {
  std::vector<std::uint8_t> bytes;
  for (const Rgba& t : kChecker) bytes.insert(bytes.end(), t.begin(), t.end());
  return bytes;
}

// A camera 1 m in front of the z = 0 plane looking down −z with a narrow field of view (0.05 rad:
// the view direction of every pixel is within 1.3° of the normal, shade > 0.9998), and the quad
// of that plane that exactly fills a width x height image, with glTF texture coordinates: its
// top-left corner (as seen) at (0, 0), bottom-right at (1, 1).
RenderCamera QuadCamera() {
  RenderCamera c = AxisCamera(1.0);
  c.yfov_rad = 0.05;
  return c;
}
RenderMesh ScreenQuad(int width, int height) {
  const double half_h = std::tan(0.5 * QuadCamera().yfov_rad);  // at distance 1
  const auto y = static_cast<float>(half_h);
  const auto x = static_cast<float>(half_h * width / height);
  RenderMesh m;
  m.positions_N = {{-x, y, 0}, {x, y, 0}, {-x, -y, 0}, {x, -y, 0}};
  m.uv = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
  m.triangles = {{0, 2, 1}, {1, 2, 3}};
  return m;
}

// The checker quad seen face-on, in both encodings: each quadrant's centre pixel is its texel.
// The image is 162 x 122 so that those pixels' centres fall on texel centres (uv 0.25 or 0.75:
// (40 + 0.5) / 162 = 0.25): bilinear filtering then takes the texel alone.
// kSrgb: the texel's own bytes (decoded to linear, times white and shade 1, encoded again);
// kLinear: 255 × the texel's linear value, from the sRGB formula written out here. A
// colour_rgba other than white scales the linear value.
TEST(SceneRendererTextureTest, CheckerQuadShowsEachTexelInItsQuadrant) {
  setenv("MESA_SHADER_CACHE_DISABLE", "true", 0);
  for (const ColourEncoding encoding : {ColourEncoding::kSrgb, ColourEncoding::kLinear}) {
    constexpr int kW = 162, kH = 122;
    std::unique_ptr<SceneRenderer> r;
    try {
      r = SceneRenderer::Create(kW, kH, encoding);
    } catch (const GpuError& e) {
      GTEST_SKIP() << "no EGL context: " << e.what();
    }
    const int quad = r->AddMesh(ScreenQuad(kW, kH));
    const std::vector<std::uint8_t> checker = CheckerBytes();
    const int texture = r->AddTexture(checker, 2, 2);
    EXPECT_EQ(texture, 0);
    for (const glm::vec4 colour : {glm::vec4(1.f), glm::vec4(0.5f, 1.f, 0.25f, 1.f)}) {
      RenderFrame f;
      f.camera = QuadCamera();
      f.background_rgba = kBackground;
      f.items.push_back({.mesh = quad, .colour_rgba = colour, .texture = texture});
      std::vector<std::uint8_t> img;
      r->Render(f, &img);
      const std::string what = std::string(encoding == ColourEncoding::kSrgb ? "sRGB" : "linear") +
                               " output, colour (" + std::to_string(colour.r) + ", " +
                               std::to_string(colour.g) + ", " + std::to_string(colour.b) + ")";
      for (int row = 0; row < 2; ++row) {
        for (int column = 0; column < 2; ++column) {
          const Rgba& texel = kChecker[static_cast<std::size_t>(2 * row + column)];
          const Rgba got = At(img, kW, kW / 4 + column * kW / 2, kH / 4 + row * kH / 2);
          for (int c = 0; c < 3; ++c) {
            const double linear = colour[c] * SrgbToLinear(texel[static_cast<std::size_t>(c)]);
            const double expected =
                encoding == ColourEncoding::kSrgb ? LinearToSrgbByte(linear) : 255.0 * linear;
            EXPECT_NEAR(got[static_cast<std::size_t>(c)], expected, 1.5)
                << what << ", texel (" << column << ", " << row << ") channel " << c << ": got "
                << Show(got);
          }
          EXPECT_EQ(got[3], 255);
        }
      }
    }
  }
}

// The same quad without a texture, or with one but no uv, is its flat colour; with uv it is
// not; a texture given to an item whose mesh has no uv changes nothing.
TEST_F(SceneRendererTest, TextureNeedsUvAndUvWithoutTextureIsFlat) {
  RenderMesh with_uv = ScreenQuad(kWidth, kHeight);
  RenderMesh without_uv = with_uv;
  without_uv.uv.clear();
  const int a = renderer_->AddMesh(with_uv);
  const int b = renderer_->AddMesh(without_uv);
  const int texture = renderer_->AddTexture(CheckerBytes(), 2, 2);
  const glm::vec4 grey{0.6f, 0.6f, 0.6f, 1.f};
  auto draw = [&](int mesh, int tex) {
    RenderFrame f;
    f.camera = QuadCamera();
    f.background_rgba = kBackground;
    f.items.push_back({.mesh = mesh, .colour_rgba = grey, .texture = tex});
    return Draw(f);
  };
  const auto flat = draw(a, -1);
  EXPECT_EQ(draw(b, texture), flat);
  EXPECT_EQ(draw(b, -1), flat);
  EXPECT_NE(draw(a, texture), flat);
  EXPECT_NEAR(At(flat, kWidth, 10, 10)[0], 0.6 * 255, 1.0);
}

// A translucent (ghost) item is textured too: its pixel is between the background and the
// opaque textured pixel.
TEST_F(SceneRendererTest, GhostItemsAreTexturedToo) {
  const int quad = renderer_->AddMesh(ScreenQuad(kWidth, kHeight));
  const int texture = renderer_->AddTexture(CheckerBytes(), 2, 2);
  RenderFrame f;
  f.camera = QuadCamera();
  f.background_rgba = kBackground;
  f.items.push_back({.mesh = quad, .colour_rgba = glm::vec4(1.f), .texture = texture});
  const Rgba opaque = At(Draw(f), kWidth, kWidth / 4, kHeight / 4);
  f.items[0].ghost = true;
  const Rgba ghost = At(Draw(f), kWidth, kWidth / 4, kHeight / 4);
  for (int c = 0; c < 3; ++c) {
    const double expected = 0.3 * opaque[c] + 0.7 * kBackgroundBytes[c];
    EXPECT_NEAR(ghost[c], expected, 2.0) << c;
  }
}

TEST_F(SceneRendererTest, BadTexturesAndTextureIndicesAreRefused) {
  const std::vector<std::uint8_t> checker = CheckerBytes();
  EXPECT_THROW(renderer_->AddTexture(checker, 2, 3), std::invalid_argument);
  EXPECT_THROW(renderer_->AddTexture(checker, 0, 2), std::invalid_argument);
  EXPECT_THROW(renderer_->AddTexture({}, 0, 0), std::invalid_argument);
  EXPECT_THROW(renderer_->AddTexture(std::vector<std::uint8_t>(8193 * 4), 8193, 1),
               std::invalid_argument);
  RenderMesh quad = ScreenQuad(kWidth, kHeight);
  quad.uv.pop_back();
  EXPECT_THROW(renderer_->AddMesh(quad), std::invalid_argument);
  quad = ScreenQuad(kWidth, kHeight);
  quad.uv[2].y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(renderer_->AddMesh(quad), std::invalid_argument);
  EXPECT_THROW(renderer_->ReplaceMesh(cube_, quad), std::invalid_argument);

  std::vector<std::uint8_t> img;
  RenderFrame f = CubeFrame(glm::dmat4(1.0), {0.5f, 0.5f, 0.5f, 1.f});
  for (const int bad : {0, 1, -2}) {  // no texture added yet
    f.items[0].texture = bad;
    EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument) << bad;
  }
  EXPECT_TRUE(img.empty());
  EXPECT_EQ(renderer_->AddTexture(checker, 2, 2), 0);
  EXPECT_EQ(renderer_->AddTexture(checker, 1, 4), 1);  // 1 x 4: any shape
  f.items[0].texture = 1;
  EXPECT_NO_THROW(renderer_->Render(f, &img));
  f.items[0].texture = 2;
  EXPECT_THROW(renderer_->Render(f, &img), std::invalid_argument);
}

// sRGB output encodes flat colours too: linear 0.5 → 188, and the background likewise.
TEST(SceneRendererTextureTest, SrgbOutputEncodesFlatColoursAndTheBackground) {
  setenv("MESA_SHADER_CACHE_DISABLE", "true", 0);
  std::unique_ptr<SceneRenderer> r;
  try {
    r = SceneRenderer::Create(kWidth, kHeight, ColourEncoding::kSrgb);
  } catch (const GpuError& e) {
    GTEST_SKIP() << "no EGL context: " << e.what();
  }
  const int quad = r->AddMesh(ScreenQuad(kWidth, kHeight));
  RenderFrame f;
  f.camera = QuadCamera();
  f.background_rgba = {0.2f, 0.2f, 0.2f, 1.f};
  f.items.push_back({.mesh = quad,
                     .X_WN = glm::scale(glm::dmat4(1.0), glm::dvec3(0.5)),
                     .colour_rgba = {0.5f, 0.25f, 0.f, 1.f}});
  std::vector<std::uint8_t> img;
  r->Render(f, &img);
  const Rgba centre = At(img, kWidth, kWidth / 2, kHeight / 2);
  EXPECT_NEAR(centre[0], LinearToSrgbByte(0.5), 1.5);   // 188
  EXPECT_NEAR(centre[1], LinearToSrgbByte(0.25), 1.5);  // 137
  EXPECT_EQ(centre[2], 0);
  const Rgba corner = At(img, kWidth, 2, 2);           // outside the half-size quad
  EXPECT_NEAR(corner[0], LinearToSrgbByte(0.2), 1.5);  // 124
}

// ---- Images decoded from memory.

std::vector<std::uint8_t> FileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Encodes an RGB image (`components` 3) or a grey one (1) as a baseline JPEG with libjpeg.
std::vector<std::uint8_t> EncodeJpeg(const std::vector<std::uint8_t>& pixels, int width, int height,
                                     int components, int quality) {
  jpeg_compress_struct cinfo;
  jpeg_error_mgr err;
  cinfo.err = jpeg_std_error(&err);  // the default handler exits: only for known-good input
  jpeg_create_compress(&cinfo);
  unsigned char* out = nullptr;
  unsigned long size = 0;
  jpeg_mem_dest(&cinfo, &out, &size);
  cinfo.image_width = static_cast<JDIMENSION>(width);
  cinfo.image_height = static_cast<JDIMENSION>(height);
  cinfo.input_components = components;
  cinfo.in_color_space = components == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_quality(&cinfo, quality, TRUE);
  jpeg_start_compress(&cinfo, TRUE);
  const std::size_t row = static_cast<std::size_t>(width) * components;
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW r = const_cast<std::uint8_t*>(pixels.data()) + row * cinfo.next_scanline;
    jpeg_write_scanlines(&cinfo, &r, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  std::vector<std::uint8_t> bytes(out, out + size);
  std::free(out);
  return bytes;
}

// A smooth colour image (JPEG's easy case), `components` 3 (RGB) or 1 (grey).
std::vector<std::uint8_t> Gradient(int width, int height, int components) {
  std::vector<std::uint8_t> p;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const int r = 255 * x / (width - 1), g = 255 * y / (height - 1), b = (r + g) / 3 + 40;
      if (components == 1) {
        p.push_back(static_cast<std::uint8_t>((r + g) / 2));
      } else {
        p.insert(p.end(), {static_cast<std::uint8_t>(r), static_cast<std::uint8_t>(g),
                           static_cast<std::uint8_t>(b)});
      }
    }
  }
  return p;
}

TEST(DecodeImageTest, DuckTexturePngHasTheSizeInItsHeaderAndReadPngsPixels) {
  REQUIRE_GLTF_DATA(dir);
  const std::filesystem::path png =
      *dir / "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/DuckCM.png";
  const std::vector<std::uint8_t> bytes = FileBytes(png);
  ASSERT_GT(bytes.size(), 24u);
  // IHDR is the first chunk: width and height big-endian at bytes 16 and 20.
  auto be32 = [&](std::size_t at) {
    return (bytes[at] << 24) | (bytes[at + 1] << 16) | (bytes[at + 2] << 8) | bytes[at + 3];
  };
  int w = 0, h = 0;
  const std::vector<std::uint8_t> rgba = DecodeImage(bytes, &w, &h);
  EXPECT_EQ(w, be32(16));
  EXPECT_EQ(h, be32(20));
  EXPECT_EQ(rgba.size(), static_cast<std::size_t>(w) * h * 4);
  int rw = 0, rh = 0;
  EXPECT_EQ(rgba, ReadPng(png.string(), &rw, &rh)) << "from memory = from the file";
}

TEST(DecodeImageTest, JpegRoundTripIsWithinJpegTolerance) {
  for (const int components : {3, 1}) {
    const int w = 48, h = 32;
    const std::vector<std::uint8_t> pixels = Gradient(w, h, components);
    const std::vector<std::uint8_t> jpeg = EncodeJpeg(pixels, w, h, components, 95);
    int dw = 0, dh = 0;
    const std::vector<std::uint8_t> rgba = DecodeImage(jpeg, &dw, &dh);
    ASSERT_EQ(dw, w);
    ASSERT_EQ(dh, h);
    ASSERT_EQ(rgba.size(), static_cast<std::size_t>(w) * h * 4);
    double sum = 0.0, worst = 0.0;
    for (std::size_t i = 0; i < static_cast<std::size_t>(w) * h; ++i) {
      for (int c = 0; c < 3; ++c) {
        const int given = pixels[i * components + (components == 1 ? 0 : c)];
        const double d = std::abs(rgba[4 * i + c] - given);
        sum += d;
        worst = std::max(worst, d);
      }
      ASSERT_EQ(rgba[4 * i + 3], 255);
    }
    const double mean = sum / (3.0 * w * h);
    std::cout << components << "-component JPEG (quality 95): mean |error| " << mean << ", max "
              << worst << "\n";
    EXPECT_LT(mean, 2.0) << components;
    EXPECT_LT(worst, 12.0) << components;
  }
}

TEST(DecodeImageTest, GarbageTruncatedAndOversizedImagesThrowSayingWhy) {
  const auto expect_error = [](const std::vector<std::uint8_t>& bytes, const std::string& word,
                               const std::string& what) {
    int w = -1, h = -1;
    try {
      DecodeImage(bytes, &w, &h);
      ADD_FAILURE() << what << ": decoded";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << what << ": " << e.what();
    } catch (...) {
      ADD_FAILURE() << what << ": threw something other than std::runtime_error";
    }
    EXPECT_EQ(w, -1) << what << ": width set on failure";
  };
  expect_error({}, "neither PNG nor JPEG", "no bytes");
  const std::string text = "GIF89a, or any other format";
  expect_error({text.begin(), text.end()}, "neither PNG nor JPEG", "GIF");
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<std::uint8_t> bytes(1 + rng() % 2000);
    for (std::uint8_t& b : bytes) b = static_cast<std::uint8_t>(rng());
    expect_error(bytes, "DecodeImage", "random bytes");
    // The same after a valid signature, so that the decoders themselves see garbage.
    std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
    png.insert(png.end(), bytes.begin(), bytes.end());
    expect_error(png, "PNG", "PNG signature + random bytes");
    std::vector<std::uint8_t> jpeg = {0xFF, 0xD8, 0xFF};
    jpeg.insert(jpeg.end(), bytes.begin(), bytes.end());
    expect_error(jpeg, "JPEG", "JPEG signature + random bytes");
  }

  // Truncations of a valid PNG and a valid JPEG at many lengths.
  const std::vector<std::uint8_t> rgb = Gradient(40, 30, 3);
  std::vector<std::uint8_t> rgba;
  for (std::size_t i = 0; i < rgb.size(); i += 3)
    rgba.insert(rgba.end(), {rgb[i], rgb[i + 1], rgb[i + 2], 255});
  const std::string png_path = ::testing::TempDir() + "scene_renderer_test_decode.png";
  WritePng(png_path, 40, 30, rgba);
  const std::vector<std::uint8_t> png = FileBytes(png_path);
  std::filesystem::remove(png_path);
  const std::vector<std::uint8_t> jpeg = EncodeJpeg(rgb, 40, 30, 3, 90);
  int w = 0, h = 0;
  EXPECT_EQ(DecodeImage(png, &w, &h), rgba);  // the whole files decode
  EXPECT_EQ(DecodeImage(jpeg, &w, &h).size(), rgba.size());
  for (const auto& [bytes, format] : {std::pair{png, std::string("PNG")}, {jpeg, "JPEG"}}) {
    for (std::size_t length = 1; length < bytes.size(); length += 1 + length / 8) {
      expect_error({bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(length)}, "",
                   format + " truncated to " + std::to_string(length) + " of " +
                       std::to_string(bytes.size()) + " bytes");
    }
  }

  // Larger than 8192 a side: refused from the header.
  const std::string wide_path = ::testing::TempDir() + "scene_renderer_test_wide.png";
  WritePng(wide_path, 8193, 1, std::vector<std::uint8_t>(8193 * 4, 9));
  expect_error(FileBytes(wide_path), "at most 8192", "8193 x 1 PNG");
  std::filesystem::remove(wide_path);
  expect_error(EncodeJpeg(std::vector<std::uint8_t>(8193, 9), 1, 8193, 1, 90), "at most 8192",
               "1 x 8193 JPEG");
  EXPECT_THROW(DecodeImage(png, nullptr, &h), std::invalid_argument);
}

// ---- The Duck, textured.

// The Duck (mesh 0 with its uv, its material's PNG decoded and added as a texture), drawn by a
// camera looking at its bounding box: the textured frame covers exactly the untextured frame's
// pixels, shows many more colours, and is yellow (the texture's main colour: red and green well
// above blue). Written to the test temp dir as duck_textured.png (sRGB output, as a viewer
// expects) and duck_textured_linear.png for a person to look at.
TEST(SceneRendererDuckTest, DuckIsDrawnWithItsBaseColourTexture) {
  setenv("MESA_SHADER_CACHE_DISABLE", "true", 0);
  REQUIRE_GLTF_DATA(dir);
  const GltfScene scene = LoadGltfScene(
      (*dir / "draco_testdata_gltf/KhronosSampleModels/Duck/glTF/Duck.gltf").string());
  ASSERT_FALSE(scene.meshes.empty());
  ASSERT_FALSE(scene.instances.empty());
  const GltfMesh& duck = scene.meshes[0];
  ASSERT_EQ(duck.uv_N.size(), duck.mesh_N.vertices.size());
  ASSERT_GE(duck.material, 0);
  const GltfMaterial& material = scene.materials[static_cast<std::size_t>(duck.material)];
  ASSERT_GE(material.base_colour_image, 0);
  int tw = 0, th = 0;
  const std::vector<std::uint8_t> texels = DecodeImage(
      scene.images[static_cast<std::size_t>(material.base_colour_image)].bytes, &tw, &th);

  RenderMesh mesh;
  for (const glm::dvec3& p : duck.mesh_N.vertices) mesh.positions_N.emplace_back(p);
  for (const glm::dvec2& uv : duck.uv_N) mesh.uv.emplace_back(uv);
  for (const glm::ivec3& t : duck.mesh_N.triangles) mesh.triangles.emplace_back(t);
  const glm::dmat4& X_WN = scene.instances[0].X_WN;
  glm::dvec3 lo(1e300), hi(-1e300);
  for (const glm::dvec3& p_N : duck.mesh_N.vertices) {
    const glm::dvec3 p_W(X_WN * glm::dvec4(p_N, 1.0));
    lo = glm::min(lo, p_W);
    hi = glm::max(hi, p_W);
  }
  const int w = 480, h = 360;
  RenderFrame f;
  f.camera = FollowCamera(0.5 * (lo + hi), {0, 1, 0}, 1.6 * glm::length(hi - lo));
  f.background_rgba = kBackground;
  f.items.push_back({.mesh = 0,
                     .X_WN = X_WN,
                     .colour_rgba = glm::vec4(glm::dvec4(material.base_colour_rgba)),
                     .texture = 0});
  for (const ColourEncoding encoding : {ColourEncoding::kSrgb, ColourEncoding::kLinear}) {
    std::unique_ptr<SceneRenderer> r;
    try {
      r = SceneRenderer::Create(w, h, encoding);
    } catch (const GpuError& e) {
      GTEST_SKIP() << "no EGL context: " << e.what();
    }
    ASSERT_EQ(r->AddMesh(mesh), 0);
    ASSERT_EQ(r->AddTexture(texels, tw, th), 0);
    std::vector<std::uint8_t> textured, flat;
    r->Render(f, &textured);
    RenderFrame untextured = f;
    untextured.items[0].texture = -1;
    r->Render(untextured, &flat);
    const Rgba bg = At(flat, w, 0, 0);
    std::set<std::array<std::uint8_t, 4>> colours_textured, colours_flat;
    std::size_t covered = 0, differ = 0;
    double r_sum = 0, g_sum = 0, b_sum = 0;
    for (int j = 0; j < h; ++j) {
      for (int i = 0; i < w; ++i) {
        const Rgba t = At(textured, w, i, j), u = At(flat, w, i, j);
        differ += (t == bg) != (u == bg);
        if (u == bg) continue;
        ++covered;
        colours_textured.insert(t);
        colours_flat.insert(u);
        r_sum += t[0];
        g_sum += t[1];
        b_sum += t[2];
      }
    }
    const std::string name =
        encoding == ColourEncoding::kSrgb ? "duck_textured.png" : "duck_textured_linear.png";
    const std::string path = ::testing::TempDir() + name;
    WritePng(path, w, h, textured);
    const auto n = static_cast<double>(covered);
    std::cout << path << ": " << covered << " duck pixels, " << colours_textured.size()
              << " colours textured vs " << colours_flat.size() << " flat; mean RGB (" << r_sum / n
              << ", " << g_sum / n << ", " << b_sum / n << ")\n";
    EXPECT_GT(covered, static_cast<std::size_t>(w * h / 10));
    EXPECT_LE(differ, covered / 1000) << "the texture changes no coverage";
    EXPECT_GT(colours_textured.size(), 4 * colours_flat.size());
    EXPECT_GT(r_sum, 1.5 * b_sum);
    EXPECT_GT(g_sum, 1.2 * b_sum);
  }
}

TEST(PngImageTest, WriteThenReadIsExact) {
  const int w = 37, h = 23;  // odd sizes: no row padding hides a stride bug
  std::mt19937 rng(7);
  std::vector<std::uint8_t> rgba(static_cast<std::size_t>(w) * h * 4);
  for (std::uint8_t& b : rgba) b = static_cast<std::uint8_t>(rng() & 0xff);
  const std::string path = ::testing::TempDir() + "scene_renderer_test_roundtrip.png";
  WritePng(path, w, h, rgba);
  int rw = 0, rh = 0;
  const std::vector<std::uint8_t> back = ReadPng(path, &rw, &rh);
  EXPECT_EQ(rw, w);
  EXPECT_EQ(rh, h);
  EXPECT_EQ(back, rgba);
  std::filesystem::remove(path);
}

TEST(PngImageTest, BadFilesThrowNamingThePath) {
  const std::string dir = ::testing::TempDir();
  const auto expect_throw_naming = [](const std::string& path, auto&& call) {
    try {
      call();
      ADD_FAILURE() << "no exception for " << path;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  };
  // Truncated: a valid file cut in half.
  std::vector<std::uint8_t> rgba(64 * 64 * 4);
  std::mt19937 rng(3);
  for (std::uint8_t& b : rgba) b = static_cast<std::uint8_t>(rng() & 0xff);
  const std::string truncated = dir + "scene_renderer_test_truncated.png";
  WritePng(truncated, 64, 64, rgba);
  const auto size = std::filesystem::file_size(truncated);
  std::filesystem::resize_file(truncated, size / 2);
  int w = 0, h = 0;
  expect_throw_naming(truncated, [&] { ReadPng(truncated, &w, &h); });
  // Garbage.
  const std::string garbage = dir + "scene_renderer_test_garbage.png";
  std::ofstream(garbage) << "this is not a PNG file at all, just text";
  expect_throw_naming(garbage, [&] { ReadPng(garbage, &w, &h); });
  // Missing, and a directory that does not exist for writing.
  const std::string missing = dir + "scene_renderer_test_missing/none.png";
  expect_throw_naming(missing, [&] { ReadPng(missing, &w, &h); });
  expect_throw_naming(missing, [&] { WritePng(missing, 64, 64, rgba); });
  // A buffer of the wrong size, or no size, is a caller's error.
  EXPECT_THROW(WritePng(garbage, 63, 64, rgba), std::invalid_argument);
  EXPECT_THROW(WritePng(garbage, 0, 0, {}), std::invalid_argument);
  EXPECT_THROW(ReadPng(garbage, nullptr, &h), std::invalid_argument);
  std::filesystem::remove(truncated);
  std::filesystem::remove(garbage);
}

// A scene like the operator's: a ground slab, a few objects, a ghost tool, arrows; written as a
// PNG (kept in the test temp directory, path printed, for a person to look at) and read back;
// then the time of one 640 x 480 frame including readback (median of 20).
TEST(SceneRendererFrameTest, WritesAViewableFrameAndTimesIt) {
  setenv("MESA_SHADER_CACHE_DISABLE", "true", 0);
  std::unique_ptr<SceneRenderer> r;
  try {
    r = SceneRenderer::Create(640, 480);
  } catch (const GpuError& e) {
    GTEST_SKIP() << "no EGL context: " << e.what();
  }
  const int cube = r->AddMesh(Cube(0.5));
  const int sphere = r->AddMesh(Sphere(0.02, 48, 96));  // 9216 triangles
  RenderFrame f;
  // Scene in glTF convention (+Y up).
  f.items.push_back({.mesh = cube,
                     .X_WN = glm::scale(glm::translate(glm::dmat4(1.0), glm::dvec3(0, -0.005, 0)),
                                        glm::dvec3(0.2, 0.01, 0.2)),
                     .colour_rgba = {0.55f, 0.55f, 0.5f, 1.f}});
  f.items.push_back({.mesh = sphere,
                     .X_WN = glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, 0.02, 0.0)),
                     .colour_rgba = {0.2f, 0.5f, 0.85f, 1.f}});
  f.items.push_back(
      {.mesh = cube,
       .X_WN = glm::scale(glm::translate(glm::dmat4(1.0), glm::dvec3(0.05, 0.015, -0.03)) *
                              glm::rotate(glm::dmat4(1.0), 0.6, glm::dvec3(0, 1, 0)),
                          glm::dvec3(0.03)),
       .colour_rgba = {0.3f, 0.75f, 0.3f, 1.f}});
  // The tool where the remote side holds it, and its ghost where the operator's hand is.
  const glm::dmat4 tool = glm::translate(glm::dmat4(1.0), glm::dvec3(-0.004, 0.046, 0.004)) *
                          glm::rotate(glm::dmat4(1.0), 0.3, glm::dvec3(0, 0, 1)) *
                          glm::scale(glm::dmat4(1.0), glm::dvec3(0.008, 0.012, 0.008));
  f.items.push_back({.mesh = cube, .X_WN = tool, .colour_rgba = {0.85f, 0.8f, 0.3f, 1.f}});
  f.items.push_back({.mesh = cube,
                     .X_WN = glm::translate(glm::dmat4(1.0), glm::dvec3(0, -0.008, 0)) * tool,
                     .colour_rgba = {0.85f, 0.8f, 0.3f, 1.f},
                     .ghost = true});
  f.arrows.push_back({{0.0, 0.04, 0.0}, {0.0, 1.5, 0.0}});
  f.arrows.push_back({{0.0141, 0.0341, 0.0}, {0.8, 0.8, 0.0}});
  f.arrows.push_back({{0.05, 0.03, -0.03}, {0.0, 0.0, 0.0}});  // touching, no force
  f.camera = FollowCamera({0.0, 0.02, 0.0}, {0, 1, 0}, 0.2);
  f.arrow_m_per_n = 0.015;
  std::vector<std::uint8_t> img;
  r->Render(f, &img);
  const std::string path = ::testing::TempDir() + "scene_renderer_test_frame.png";
  WritePng(path, 640, 480, img);
  int w = 0, h = 0;
  EXPECT_EQ(ReadPng(path, &w, &h), img);
  std::cout << "frame written to " << path << "\n";

  std::vector<double> ms;
  for (int i = 0; i < 20; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    r->Render(f, &img);
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  const double median = 0.5 * (ms[9] + ms[10]);
  std::cout << "640x480 frame (~9.3k triangles, 3 arrows) incl. readback on " << r->gpu().renderer
            << ": median " << median << " ms, min " << ms.front() << " ms, max " << ms.back()
            << " ms\n";
  RecordProperty("frame_640x480_median_ms", std::to_string(median));
  EXPECT_LT(median, 1000.0);
}

}  // namespace
}  // namespace ht
