// The operator's scene renderer on a real headless EGL context (Mesa llvmpipe on machines without
// a GPU; skipped where no context can be made at all): pixels of a known scene checked against
// projections computed by hand for an axis-aligned camera and with ProjectToPixel for others,
// ghosts, force arrows, poses and mesh replacement, PNG files, and bad arguments.
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

#include "master_station/png_image.h"

namespace ht {
namespace {

constexpr int kWidth = 160;
constexpr int kHeight = 120;
constexpr double kHalf = 0.01;  // the cube's half edge (m): a 0.02 m cube
// A background of exact 8-bit values, so that "equals the background" can be checked exactly.
constexpr glm::vec4 kBackground{26.f / 255.f, 26.f / 255.f, 31.f / 255.f, 1.f};
constexpr std::array<std::uint8_t, 4> kBackgroundBytes{26, 26, 31, 255};

using Rgba = std::array<std::uint8_t, 4>;

RenderMesh Cube(double half) {
  const float h = static_cast<float>(half);
  RenderMesh m;
  for (int i = 0; i < 8; ++i) {
    m.positions_N.push_back({(i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h});
  }
  // Counter-clockwise from outside.
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

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
