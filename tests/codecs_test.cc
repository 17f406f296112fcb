// Tests of codecs/draco_mesh_codec: round trip of a procedural mesh against the quantization bound
// and the surface area, texture coordinates that stay attached to their vertices, rejection of bad
// input on both sides, and decoding of Draco's own test files (../shared/data/draco, located
// through HT_SHARED_DATA); and codecs/depth_map_codec and depth_field_codec: their bound, their
// holes, their refusals.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <glm/common.hpp>
#include <glm/ext/vector_int3_sized.hpp>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <iostream>
#include <iterator>
#include <limits>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "codecs/depth_field_codec.h"
#include "codecs/depth_map_codec.h"
#include "codecs/draco_mesh_codec.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/haptic_model.h"

namespace ht {
namespace {

double SurfaceArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (const glm::ivec3& t : mesh.triangles) {
    const glm::dvec3& a = mesh.vertices[t.x];
    const glm::dvec3& b = mesh.vertices[t.y];
    const glm::dvec3& c = mesh.vertices[t.z];
    area += 0.5 * glm::length(glm::cross(b - a, c - a));
  }
  return area;
}

// Uniform hash grid over a point set: answers "distance to the nearest point, if it is within
// `radius`" by scanning the 27 cells around the query (cell size = radius).
class PointGrid {
 public:
  PointGrid(const std::vector<glm::dvec3>& points, double radius) : points_(points), cell_(radius) {
    for (std::size_t i = 0; i < points_.size(); ++i) cells_[Key(Cell(points_[i]))].push_back(i);
  }

  // Distance from `q` to the nearest point, or nullopt when none lies within `radius`.
  std::optional<double> NearestWithinRadius(const glm::dvec3& q) const {
    const glm::i64vec3 c = Cell(q);
    double best = std::numeric_limits<double>::infinity();
    for (std::int64_t dx = -1; dx <= 1; ++dx) {
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(Key(c + glm::i64vec3(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (std::size_t i : it->second) best = std::min(best, glm::distance(q, points_[i]));
        }
      }
    }
    if (!(best <= cell_)) return std::nullopt;
    return best;
  }

 private:
  glm::i64vec3 Cell(const glm::dvec3& p) const {
    return glm::i64vec3(std::floor(p.x / cell_), std::floor(p.y / cell_), std::floor(p.z / cell_));
  }
  static std::uint64_t Key(const glm::i64vec3& c) {
    // 21 bits per axis is ample for a 6 cm object on a µm grid.
    const auto k = [](std::int64_t v) { return static_cast<std::uint64_t>(v) & 0x1fffffu; };
    return k(c.x) | (k(c.y) << 21) | (k(c.z) << 42);
  }

  const std::vector<glm::dvec3>& points_;
  double cell_;
  std::unordered_map<std::uint64_t, std::vector<std::size_t>> cells_;
};

// Largest distance from a point of `from` to its nearest point of `to`; +inf when some point of
// `from` has no point of `to` within `radius`.
double MaxNearestDistance(const std::vector<glm::dvec3>& from, const std::vector<glm::dvec3>& to,
                          double radius) {
  const PointGrid grid(to, radius);
  double worst = 0.0;
  for (const glm::dvec3& p : from) {
    const std::optional<double> d = grid.NearestWithinRadius(p);
    if (!d) return std::numeric_limits<double>::infinity();
    worst = std::max(worst, *d);
  }
  return worst;
}

void ExpectIndicesInRange(const TriangleMesh& mesh) {
  const auto n = static_cast<int>(mesh.vertices.size());
  for (const glm::ivec3& t : mesh.triangles) {
    for (int c = 0; c < 3; ++c) {
      ASSERT_GE(t[c], 0);
      ASSERT_LT(t[c], n);
    }
  }
}

// Decoding must either throw std::runtime_error or give a usable mesh; anything else (another
// exception, a crash) fails the test.
void ExpectRuntimeErrorOrValidMesh(const std::vector<std::uint8_t>& bytes) {
  try {
    const TriangleMesh mesh = DecodeMeshDraco(bytes);
    EXPECT_FALSE(mesh.triangles.empty());
    ExpectIndicesInRange(mesh);
  } catch (const std::runtime_error&) {
  }
}

TriangleMesh OneTriangle() {
  TriangleMesh mesh;
  mesh.vertices = {{0.0, 0.0, 0.0}, {0.02, 0.0, 0.0}, {0.0, 0.01, 0.005}};
  mesh.triangles = {{0, 1, 2}};
  return mesh;
}

class DracoGearTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    gear_ = new TriangleMesh(MakeRidgedGearFullResolution());
    encoded_ = new std::vector<std::uint8_t>(EncodeMeshDraco(*gear_));
  }
  static void TearDownTestSuite() {
    delete gear_;
    delete encoded_;
  }
  static const TriangleMesh* gear_;
  static const std::vector<std::uint8_t>* encoded_;
};
const TriangleMesh* DracoGearTest::gear_ = nullptr;
const std::vector<std::uint8_t>* DracoGearTest::encoded_ = nullptr;

TEST_F(DracoGearTest, RoundTripKeepsTrianglesVerticesWithinOneStepAndArea) {
  const TriangleMesh decoded = DecodeMeshDraco(*encoded_);
  ASSERT_EQ(decoded.triangles.size(), gear_->triangles.size());
  ExpectIndicesInRange(decoded);

  const double step =
      DracoQuantizationStep(*gear_, DracoEncodeOptions{}.position_quantization_bits);
  // Every decoded vertex is near an original one, and every original near a decoded one (no
  // vertex moved further than a step, none lost).
  EXPECT_LE(MaxNearestDistance(decoded.vertices, gear_->vertices, step), step);
  EXPECT_LE(MaxNearestDistance(gear_->vertices, decoded.vertices, step), step);

  const double area = SurfaceArea(*gear_);
  EXPECT_NEAR(SurfaceArea(decoded), area, 1e-3 * area);
}

TEST_F(DracoGearTest, QuantizationStepIsTheGearLengthOverTheGridSize) {
  // Independent route: the gear's largest extent is its length along x (it is 6 cm long and
  // about 5.1 cm across), and Draco divides the extent into 2^bits - 1 steps.
  const RidgedGearParams params;
  ASSERT_GT(params.length_m, 2.0 * (params.radius_m + params.amplitude_m));
  for (int bits : {1, 8, 14, 24}) {
    const double expected = params.length_m / (std::ldexp(1.0, bits) - 1.0);
    EXPECT_NEAR(DracoQuantizationStep(*gear_, bits), expected, 1e-6 * expected) << bits;
  }
}

TEST_F(DracoGearTest, MoreBitsGiveSmallerErrorAndLargerStream) {
  double previous_error = std::numeric_limits<double>::infinity();
  std::size_t previous_size = 0;
  for (int bits : {8, 12, 16, 20}) {
    const std::vector<std::uint8_t> bytes = EncodeMeshDraco(*gear_, {bits, 5});
    const TriangleMesh decoded = DecodeMeshDraco(bytes);
    const double step = DracoQuantizationStep(*gear_, bits);
    const double error = MaxNearestDistance(decoded.vertices, gear_->vertices, step);
    EXPECT_LE(error, step) << bits;
    EXPECT_LT(error, previous_error) << bits;
    EXPECT_GT(bytes.size(), previous_size) << bits;
    previous_error = error;
    previous_size = bytes.size();
  }
}

TEST_F(DracoGearTest, EverySpeedRoundTrips) {
  const double area = SurfaceArea(*gear_);
  for (int speed = 0; speed <= 10; ++speed) {
    const TriangleMesh decoded = DecodeMeshDraco(EncodeMeshDraco(*gear_, {14, speed}));
    EXPECT_EQ(decoded.triangles.size(), gear_->triangles.size()) << speed;
    EXPECT_NEAR(SurfaceArea(decoded), area, 1e-3 * area) << speed;
  }
}

TEST_F(DracoGearTest, TruncatedStreamThrowsRuntimeError) {
  const std::size_t n = encoded_->size();
  for (std::size_t length : {std::size_t{0}, std::size_t{1}, std::size_t{4}, std::size_t{5},
                             std::size_t{8}, std::size_t{11}, std::size_t{16}, std::size_t{64},
                             n / 4, n / 2, 3 * n / 4, n - 16, n - 1}) {
    const std::vector<std::uint8_t> truncated(encoded_->begin(),
                                              encoded_->begin() + static_cast<long>(length));
    EXPECT_THROW(DecodeMeshDraco(truncated), std::runtime_error) << length << " of " << n;
  }
}

TEST_F(DracoGearTest, CorruptedStreamThrowsRuntimeErrorOrDecodes) {
  std::mt19937 rng(12345);
  for (int trial = 0; trial < 60; ++trial) {
    std::vector<std::uint8_t> bytes = *encoded_;
    // Corrupt 1-3 bytes, half the time within the header and the first attribute data.
    const std::size_t span =
        trial % 2 == 0 ? std::min<std::size_t>(64, bytes.size()) : bytes.size();
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int k = 0; k < flips; ++k) bytes[rng() % span] = static_cast<std::uint8_t>(rng());
    ExpectRuntimeErrorOrValidMesh(bytes);
  }
}

TEST(DracoDecodeTest, RandomBytesThrowRuntimeError) {
  std::mt19937 rng(2024);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::uint8_t> bytes(rng() % 4096);
    for (std::uint8_t& b : bytes) b = static_cast<std::uint8_t>(rng());
    EXPECT_THROW(DecodeMeshDraco(bytes), std::runtime_error) << trial;
  }
}

TEST(DracoDecodeTest, ValidHeaderFollowedByRandomBytesNeverCrashes) {
  const std::vector<std::uint8_t> valid = EncodeMeshDraco(OneTriangle());
  std::mt19937 rng(77);
  for (int trial = 0; trial < 200; ++trial) {
    // Keep the 11-byte header (magic, version, mesh, method, flags) and a few more bytes.
    std::vector<std::uint8_t> bytes(valid.begin(), valid.begin() + 11 + trial % 8);
    const std::size_t extra = rng() % 256;
    for (std::size_t k = 0; k < extra; ++k) bytes.push_back(static_cast<std::uint8_t>(rng()));
    ExpectRuntimeErrorOrValidMesh(bytes);
  }
}

TEST(DracoEncodeTest, BadOptionsThrowInvalidArgument) {
  const TriangleMesh mesh = OneTriangle();
  for (int bits : {-1, 0, 25, 30, 64}) {
    EXPECT_THROW(EncodeMeshDraco(mesh, {bits, 5}), std::invalid_argument) << bits;
    EXPECT_THROW(DracoQuantizationStep(mesh, bits), std::invalid_argument) << bits;
  }
  for (int speed : {-1, 11, 100}) {
    EXPECT_THROW(EncodeMeshDraco(mesh, {14, speed}), std::invalid_argument) << speed;
  }
  EXPECT_NO_THROW(EncodeMeshDraco(mesh, {1, 0}));
  // 24 bits is the cap: Draco's encoder then needs ~67 MB whatever the mesh (see
  // DracoEncodeOptions): check the upper bound of bits through DracoQuantizationStep only.
  EXPECT_NO_THROW(EncodeMeshDraco(mesh, {20, 10}));
  EXPECT_NO_THROW(DracoQuantizationStep(mesh, 24));
}

TEST(DracoEncodeTest, BadMeshesThrowInvalidArgument) {
  EXPECT_THROW(EncodeMeshDraco(TriangleMesh{}), std::invalid_argument);
  EXPECT_THROW(DracoQuantizationStep(TriangleMesh{}, 14), std::invalid_argument);

  TriangleMesh no_triangles = OneTriangle();
  no_triangles.triangles.clear();
  EXPECT_THROW(EncodeMeshDraco(no_triangles), std::invalid_argument);

  for (const glm::ivec3& bad : {glm::ivec3(0, 1, 3), glm::ivec3(-1, 1, 2)}) {
    TriangleMesh mesh = OneTriangle();
    mesh.triangles.push_back(bad);
    EXPECT_THROW(EncodeMeshDraco(mesh), std::invalid_argument);
  }
  for (double bad : {std::numeric_limits<double>::quiet_NaN(),
                     std::numeric_limits<double>::infinity(), 1e39 /* overflows float */}) {
    TriangleMesh mesh = OneTriangle();
    mesh.vertices[1].y = bad;
    EXPECT_THROW(EncodeMeshDraco(mesh), std::invalid_argument) << bad;
    EXPECT_THROW(DracoQuantizationStep(mesh, 14), std::invalid_argument) << bad;
  }
}

TEST(DracoEncodeTest, SingleTriangleRoundTripsWithinHalfAStepPerAxis) {
  const TriangleMesh mesh = OneTriangle();
  const int bits = 10;
  const double step = DracoQuantizationStep(mesh, bits);
  EXPECT_NEAR(step, 0.02 / 1023.0, 1e-6 * step);  // x extent 2 cm is the largest
  const TriangleMesh decoded = DecodeMeshDraco(EncodeMeshDraco(mesh, {bits, 5}));
  ASSERT_EQ(decoded.triangles.size(), 1u);
  ASSERT_EQ(decoded.vertices.size(), 3u);
  for (const glm::dvec3& p : decoded.vertices) {
    double best = std::numeric_limits<double>::infinity();
    for (const glm::dvec3& q : mesh.vertices) {
      const glm::dvec3 d = glm::abs(p - q);
      best = std::min(best, std::max({d.x, d.y, d.z}));
    }
    EXPECT_LE(best, 0.5 * step + 1e-9);
  }
}

TEST(DracoEncodeTest, EdgebreakerDropsRepeatedIndexTrianglesAndUnusedVerticesSpeedTenKeepsThem) {
  TriangleMesh mesh;  // unit square as two triangles, plus an unused vertex and a needle
  mesh.vertices = {
      {0.0, 0.0, 0.0}, {1.0, 0.0, 0.0}, {1.0, 1.0, 0.0}, {0.0, 1.0, 0.0}, {0.5, 0.5, 1}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 0, 1}};
  const TriangleMesh edgebreaker = DecodeMeshDraco(EncodeMeshDraco(mesh, {14, 5}));
  EXPECT_EQ(edgebreaker.triangles.size(), 2u);
  EXPECT_EQ(edgebreaker.vertices.size(), 4u);
  const TriangleMesh sequential = DecodeMeshDraco(EncodeMeshDraco(mesh, {14, 10}));
  EXPECT_EQ(sequential.triangles.size(), 3u);
  EXPECT_EQ(sequential.vertices.size(), 5u);
  EXPECT_NEAR(SurfaceArea(edgebreaker), 1.0, 1e-3);
  EXPECT_NEAR(SurfaceArea(sequential), 1.0, 1e-3);
}

// ---- Texture coordinates (EncodeMeshDracoWithUv / DecodeMeshDracoWithUv).

// A smooth, non-linear map from position to (u, v) over the gear's bounding box, so that a
// coordinate that stayed attached to its vertex is f(its decoded position) and one that moved
// to another vertex is not. A change of dp moves u and v each by at most kUvLipschitz·max|dp_k|
// / (the smallest extent).
struct UvOfPosition {
  glm::dvec3 lo, extent;
  glm::dvec2 operator()(const glm::dvec3& p) const {
    const glm::dvec3 s = (p - lo) / extent;  // each in [0, 1]
    return {0.8 * s.x + 0.2 * s.y * s.y, 0.6 * s.z + 0.4 * s.x * s.y};
  }
};
// Sum over the axes of |d(u or v)/ds_k|, at most: u 0.8 + 0.4, v 0.6 + 0.4 + 0.4.
constexpr double kUvLipschitz = 1.4;

UvOfPosition UvMapOf(const TriangleMesh& mesh) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const glm::dvec3& p : mesh.vertices) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  return {lo, glm::max(hi - lo, glm::dvec3(1e-12))};
}

TEST_F(DracoGearTest, TextureCoordinatesStayAttachedToTheirVerticesAtEverySpeed) {
  const UvOfPosition f = UvMapOf(*gear_);
  std::vector<glm::dvec2> uv;
  for (const glm::dvec3& p : gear_->vertices) uv.push_back(f(p));
  const double min_extent = std::min({f.extent.x, f.extent.y, f.extent.z});
  for (const int speed : {0, 5, 10}) {
    DracoEncodeOptions options;
    options.speed = speed;
    const DracoMesh decoded = DecodeMeshDracoWithUv(EncodeMeshDracoWithUv(*gear_, uv, options));
    ASSERT_EQ(decoded.uv.size(), decoded.mesh.vertices.size()) << speed;
    EXPECT_EQ(decoded.mesh.triangles.size(), gear_->triangles.size()) << speed;
    ExpectIndicesInRange(decoded.mesh);
    // Bound: half a uv step (range <= 1 here, 12 bits) plus f's change over the position error
    // (half a position step per axis), plus float32 rounding.
    const double uv_step = 1.0 / ((1 << options.uv_quantization_bits) - 1);
    const double position_step = DracoQuantizationStep(*gear_, options.position_quantization_bits);
    const double bound = 0.5 * uv_step + kUvLipschitz * 0.5 * position_step / min_extent + 1e-6;
    double worst = 0.0;
    for (std::size_t i = 0; i < decoded.uv.size(); ++i) {
      const glm::dvec2 d = glm::abs(decoded.uv[i] - f(decoded.mesh.vertices[i]));
      worst = std::max({worst, d.x, d.y});
    }
    EXPECT_LE(worst, bound) << "speed " << speed;
    std::cout << "speed " << speed << ": worst |uv - f(p)| " << worst << " (bound " << bound
              << ")\n";
  }
}

TEST_F(DracoGearTest, WithoutCoordinatesTheStreamIsTheSameAndDecodesWithEmptyUv) {
  EXPECT_EQ(EncodeMeshDracoWithUv(*gear_, {}), *encoded_);
  const DracoMesh decoded = DecodeMeshDracoWithUv(*encoded_);
  EXPECT_TRUE(decoded.uv.empty());
  const TriangleMesh plain = DecodeMeshDraco(*encoded_);
  EXPECT_EQ(decoded.mesh.vertices, plain.vertices);
  EXPECT_EQ(decoded.mesh.triangles, plain.triangles);
}

TEST_F(DracoGearTest, TruncatedStreamWithCoordinatesThrowsRuntimeError) {
  const UvOfPosition f = UvMapOf(*gear_);
  std::vector<glm::dvec2> uv;
  for (const glm::dvec3& p : gear_->vertices) uv.push_back(f(p));
  const std::vector<std::uint8_t> bytes = EncodeMeshDracoWithUv(*gear_, uv);
  EXPECT_GT(bytes.size(), encoded_->size());  // the coordinates take room
  for (const std::size_t length :
       {std::size_t{0}, std::size_t{10}, bytes.size() / 3, bytes.size() / 2, bytes.size() - 1}) {
    const std::vector<std::uint8_t> truncated(bytes.begin(),
                                              bytes.begin() + static_cast<std::ptrdiff_t>(length));
    EXPECT_THROW(DecodeMeshDracoWithUv(truncated), std::runtime_error) << length;
  }
}

// A unit cube with a seam at every edge: 24 vertices, 4 per face, each face mapped onto the whole
// [0, 1]² (the same positions with different coordinates). Every decoded corner's (position, uv)
// pair must be one of the 24 given pairs: a coordinate is not a function of position here.
TEST(DracoUvTest, SeamVerticesKeepTheirOwnCoordinates) {
  TriangleMesh cube;
  std::vector<glm::dvec2> uv;
  for (int axis = 0; axis < 3; ++axis) {
    for (const double side : {0.0, 1.0}) {
      const auto base = static_cast<int>(cube.vertices.size());
      for (int k = 0; k < 4; ++k) {
        const double a = (k & 1) ? 1.0 : 0.0, b = (k & 2) ? 1.0 : 0.0;
        glm::dvec3 p;
        p[axis] = side;
        p[(axis + 1) % 3] = a;
        p[(axis + 2) % 3] = b;
        cube.vertices.push_back(p * 0.05);
        uv.emplace_back(0.1 + 0.8 * a, 0.9 - 0.8 * b);
      }
      if (side == 0.0) {
        cube.triangles.emplace_back(base, base + 2, base + 1);
        cube.triangles.emplace_back(base + 1, base + 2, base + 3);
      } else {
        cube.triangles.emplace_back(base, base + 1, base + 2);
        cube.triangles.emplace_back(base + 1, base + 3, base + 2);
      }
    }
  }
  for (const int speed : {0, 5, 10}) {
    DracoEncodeOptions options;
    options.speed = speed;
    const DracoMesh d = DecodeMeshDracoWithUv(EncodeMeshDracoWithUv(cube, uv, options));
    ASSERT_EQ(d.uv.size(), d.mesh.vertices.size());
    ASSERT_EQ(d.mesh.triangles.size(), 12u) << speed;
    for (const glm::ivec3& t : d.mesh.triangles) {
      // The triangle's three (position, uv) pairs are the corners of one given triangle.
      bool found = false;
      for (const glm::ivec3& g : cube.triangles) {
        int matched = 0;
        for (int c = 0; c < 3; ++c) {
          for (int e = 0; e < 3; ++e) {
            const auto i = static_cast<std::size_t>(t[c]), j = static_cast<std::size_t>(g[e]);
            if (glm::length(d.mesh.vertices[i] - cube.vertices[j]) < 1e-4 &&
                glm::length(d.uv[i] - uv[j]) < 1e-3) {
              ++matched;
              break;
            }
          }
        }
        found = found || matched == 3;
      }
      EXPECT_TRUE(found) << "speed " << speed << ": a decoded triangle matches no given one";
    }
  }
}

TEST(DracoUvTest, BadCoordinatesAndOptionsThrowInvalidArgument) {
  const TriangleMesh mesh = OneTriangle();
  const std::vector<glm::dvec2> uv = {{0, 0}, {1, 0}, {0, 1}};
  EXPECT_NO_THROW(EncodeMeshDracoWithUv(mesh, uv));
  EXPECT_THROW(EncodeMeshDracoWithUv(mesh, std::vector<glm::dvec2>(2)), std::invalid_argument);
  EXPECT_THROW(EncodeMeshDracoWithUv(mesh, std::vector<glm::dvec2>(4)), std::invalid_argument);
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), 1e39}) {
    std::vector<glm::dvec2> b = uv;
    b[1].y = bad;
    EXPECT_THROW(EncodeMeshDracoWithUv(mesh, b), std::invalid_argument) << bad;
  }
  for (const int bits : {0, 25}) {
    DracoEncodeOptions options;
    options.uv_quantization_bits = bits;
    EXPECT_THROW(EncodeMeshDracoWithUv(mesh, uv, options), std::invalid_argument) << bits;
    EXPECT_NO_THROW(EncodeMeshDraco(mesh, options)) << "unused without coordinates";
  }
}

// 12 bits give a step of 1/4095 on [0, 1]: a coordinate comes back within half of it; 20 bits
// much closer (two routes: the chosen bits show in the error).
TEST(DracoUvTest, CoordinatesComeBackWithinHalfAQuantizationStep) {
  const TriangleMesh mesh = OneTriangle();
  const std::vector<glm::dvec2> uv = {{0.0, 1.0}, {0.123456, 0.654321}, {1.0, 0.0}};
  for (const int bits : {8, 12, 20}) {
    DracoEncodeOptions options;
    options.uv_quantization_bits = bits;
    const DracoMesh d = DecodeMeshDracoWithUv(EncodeMeshDracoWithUv(mesh, uv, options));
    ASSERT_EQ(d.uv.size(), 3u);
    const double half_step = 0.5 / ((1 << bits) - 1);
    for (std::size_t i = 0; i < 3; ++i) {
      std::size_t j = 0;  // the given vertex nearest the decoded one
      for (std::size_t k = 1; k < 3; ++k) {
        if (glm::length(mesh.vertices[k] - d.mesh.vertices[i]) <
            glm::length(mesh.vertices[j] - d.mesh.vertices[i]))
          j = k;
      }
      EXPECT_LE(std::abs(d.uv[i].x - uv[j].x), half_step + 1e-7) << bits;
      EXPECT_LE(std::abs(d.uv[i].y - uv[j].y), half_step + 1e-7) << bits;
    }
  }
}

// Draco's test files (../shared/data/draco). HT_SHARED_DATA overrides the location; otherwise
// ../shared/data relative to the working directory, then /work/shared/data.
std::optional<std::filesystem::path> DracoDataDir() {
  std::vector<std::filesystem::path> candidates;
  if (const char* env = std::getenv("HT_SHARED_DATA"); env != nullptr && *env != '\0') {
    candidates.emplace_back(env);
  } else {
    candidates.emplace_back("../shared/data");
    candidates.emplace_back("/work/shared/data");
  }
  for (const std::filesystem::path& base : candidates) {
    std::error_code ec;
    if (std::filesystem::is_directory(base / "draco", ec)) return base / "draco";
  }
  return std::nullopt;
}

std::vector<std::uint8_t> ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open " + path.string());
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Triangle count and surface area of an OBJ made of triangles ("v x y z", "f a b c" with optional
// /vt/vn suffixes, 1-based indices): the independent route to the numbers in the .drc twins.
struct ObjFacts {
  std::size_t triangles = 0;
  double area = 0.0;
};
ObjFacts ReadTriangleObj(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path.string());
  std::vector<glm::dvec3> vertices;
  std::vector<glm::ivec3> faces;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      glm::dvec3 v;
      ls >> v.x >> v.y >> v.z;
      vertices.push_back(v);
    } else if (tag == "f") {
      std::vector<int> corners;
      std::string corner;
      while (ls >> corner) corners.push_back(std::stoi(corner.substr(0, corner.find('/'))) - 1);
      if (corners.size() != 3) throw std::runtime_error("non-triangle face in " + path.string());
      faces.emplace_back(corners[0], corners[1], corners[2]);
    }
  }
  TriangleMesh mesh{vertices, faces};
  return {faces.size(), SurfaceArea(mesh)};
}

class DracoFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::optional<std::filesystem::path> dir = DracoDataDir();
    if (!dir) {
      GTEST_SKIP() << "Draco test data not found: set HT_SHARED_DATA to the shared data directory "
                      "(the one holding draco/), or run where ../shared/data exists";
    }
    dir_ = *dir;
  }
  std::filesystem::path dir_;
};

TEST_F(DracoFilesTest, DecodesTestNmEdgebreakerFile) {
  const TriangleMesh mesh =
      DecodeMeshDraco(ReadFile(dir_ / "test_nm.obj.edgebreaker.cl10.2.2.drc"));
  EXPECT_GT(mesh.triangles.size(), 0u);
  ExpectIndicesInRange(mesh);
}

TEST_F(DracoFilesTest, EveryTestNmVersionMatchesTheObj) {
  const ObjFacts obj = ReadTriangleObj(dir_ / "test_nm.obj");
  ASSERT_GT(obj.triangles, 0u);
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("test_nm", 0) != 0 || entry.path().extension() != ".drc") continue;
    ++files;
    const TriangleMesh mesh = DecodeMeshDraco(ReadFile(entry.path()));
    EXPECT_EQ(mesh.triangles.size(), obj.triangles) << name;
    ExpectIndicesInRange(mesh);
    // Quantized at 11 bits or more (the decoded areas differ from the OBJ's by 2e-5 at most):
    // 0.1 % catches a wrong vertex mapping with a wide margin.
    EXPECT_NEAR(SurfaceArea(mesh), obj.area, 1e-3 * obj.area) << name;
  }
  EXPECT_GE(files, 10);
}

TEST_F(DracoFilesTest, PointCloudFilesThrowAClearError) {
  for (const char* name :
       {"cube_pc.drc", "pc_color.drc", "pc_kd_color.drc", "point_cloud_no_qp.drc"}) {
    const std::filesystem::path path = dir_ / name;
    if (!std::filesystem::exists(path)) continue;
    try {
      DecodeMeshDraco(ReadFile(path));
      ADD_FAILURE() << name << " decoded as a mesh";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("point cloud"), std::string::npos) << e.what();
    }
  }
}

// The Draco header, read independently of libdraco (draco/compression/decode.cc): "DRACO",
// major, minor, encoder type (0 point cloud, 1 triangular mesh), method, flags.
struct DracoHeader {
  int major = 0, minor = 0, encoder_type = -1, method = -1;
  bool metadata = false;
};
std::optional<DracoHeader> ReadDracoHeader(const std::vector<std::uint8_t>& b) {
  if (b.size() < 11 || std::string(b.begin(), b.begin() + 5) != "DRACO") return std::nullopt;
  DracoHeader h;
  h.major = b[5];
  h.minor = b[6];
  h.encoder_type = b[7];
  h.method = b[8];
  h.metadata = ((b[9] | (b[10] << 8)) & 0x8000) != 0;
  return h;
}

// Every .drc of the reference set (bitstreams 1.1 to 2.3, sequential and edgebreaker, with and
// without metadata, meshes and point clouds): a mesh decodes into valid, finite triangles; a
// point cloud is refused with a message that says so. The header's type is read by the test
// itself, so the two routes are independent.
TEST_F(DracoFilesTest, EveryReferenceBitstreamDecodesOrIsRefusedAsAPointCloud) {
  int meshes = 0, point_clouds = 0;
  std::set<std::string> versions;
  bool saw_metadata = false, saw_sequential = false, saw_edgebreaker = false;
  for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
    if (entry.path().extension() != ".drc") continue;
    const std::string name = entry.path().filename().string();
    const std::vector<std::uint8_t> bytes = ReadFile(entry.path());
    const std::optional<DracoHeader> h = ReadDracoHeader(bytes);
    ASSERT_TRUE(h.has_value()) << name;
    versions.insert(std::to_string(h->major) + "." + std::to_string(h->minor));
    if (h->encoder_type == 0) {
      ++point_clouds;
      try {
        DecodeMeshDraco(bytes);
        ADD_FAILURE() << name << ": a point cloud decoded as a mesh";
      } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find("point cloud"), std::string::npos) << e.what();
      }
      continue;
    }
    ASSERT_EQ(h->encoder_type, 1) << name;
    ++meshes;
    saw_metadata |= h->metadata;
    saw_sequential |= h->method == 0;
    saw_edgebreaker |= h->method == 1;
    const TriangleMesh mesh = DecodeMeshDraco(bytes);
    EXPECT_GT(mesh.triangles.size(), 0u) << name;
    ExpectIndicesInRange(mesh);
    for (const glm::dvec3& v : mesh.vertices) {
      ASSERT_TRUE(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z)) << name;
    }
  }
  EXPECT_GE(meshes, 15);
  EXPECT_GE(point_clouds, 3);
  EXPECT_TRUE(saw_metadata && saw_sequential && saw_edgebreaker);
  for (const char* v : {"1.1", "1.2", "2.0", "2.1", "2.2", "2.3"}) {
    EXPECT_TRUE(versions.count(v) == 1) << "no bitstream of version " << v;
  }
}

// The cube with positions, normals and texture coordinates, as a legacy v1.1 stream and as v2.2
// sequential, edgebreaker and valence-edgebreaker streams: each decodes into the OBJ's 12
// triangles and surface area; the metadata and no-metadata twins give the same triangles.
TEST_F(DracoFilesTest, CubeWithAttributesMatchesItsSourceInEveryEncoding) {
  const ObjFacts obj = ReadTriangleObj(dir_ / "cube_att.obj");
  ASSERT_EQ(obj.triangles, 12u);
  for (const char* name :
       {"cube_att.drc", "cube_att.obj.sequential.cl3.2.2.drc",
        "cube_att.obj.edgebreaker.cl4.2.2.drc", "cube_att.obj.edgebreaker.cl10.2.2.drc"}) {
    const TriangleMesh mesh = DecodeMeshDraco(ReadFile(dir_ / name));
    EXPECT_EQ(mesh.triangles.size(), obj.triangles) << name;
    EXPECT_NEAR(SurfaceArea(mesh), obj.area, 1e-3 * obj.area) << name;
  }
  const TriangleMesh with_metadata = DecodeMeshDraco(ReadFile(dir_ / "cube_att_sub_o_2.drc"));
  const TriangleMesh without = DecodeMeshDraco(ReadFile(dir_ / "cube_att_sub_o_no_metadata.drc"));
  EXPECT_EQ(with_metadata.triangles.size(), without.triangles.size());
  EXPECT_NEAR(SurfaceArea(with_metadata), SurfaceArea(without), 1e-9);
  EXPECT_NEAR(SurfaceArea(with_metadata), ReadTriangleObj(dir_ / "cube_att_sub_o_2.obj").area,
              1e-3 * SurfaceArea(without));
}

// Truncated and corrupted payloads of every mesh bitstream: a clear std::runtime_error or a
// valid mesh (a flipped byte in an attribute value can still decode), never a crash, a hang or
// an index out of range. Fixed seed; run under the sanitizers by the debug preset.
TEST_F(DracoFilesTest, TruncatedAndCorruptedPayloadsNeverCrash) {
  std::mt19937 rng(1918);
  int refused = 0, decoded = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
    if (entry.path().extension() != ".drc") continue;
    const std::vector<std::uint8_t> bytes = ReadFile(entry.path());
    const std::optional<DracoHeader> h = ReadDracoHeader(bytes);
    if (!h || h->encoder_type != 1 || bytes.size() > 20000) continue;  // small meshes: fast
    const auto attempt = [&](const std::vector<std::uint8_t>& b) {
      try {
        const TriangleMesh mesh = DecodeMeshDraco(b);
        ExpectIndicesInRange(mesh);
        ++decoded;
      } catch (const std::runtime_error&) {
        ++refused;
      }
    };
    for (const double fraction : {0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99}) {
      const auto n = static_cast<std::size_t>(fraction * static_cast<double>(bytes.size()));
      attempt(std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + static_cast<long>(n)));
    }
    std::uniform_int_distribution<std::size_t> at(0, bytes.size() - 1);
    std::uniform_int_distribution<int> bit(0, 7);
    for (int k = 0; k < 40; ++k) {
      std::vector<std::uint8_t> b = bytes;
      b[at(rng)] ^= static_cast<std::uint8_t>(1u << bit(rng));
      b[at(rng)] ^= static_cast<std::uint8_t>(1u << bit(rng));
      attempt(b);
    }
  }
  EXPECT_GT(refused, 50);  // truncations really are refused
  std::printf("[ draco ] corrupted or truncated streams: %d refused, %d still decoded\n", refused,
              decoded);
}

TEST_F(DracoFilesTest, NonDracoFileThrowsRuntimeError) {
  EXPECT_THROW(DecodeMeshDraco(ReadFile(dir_ / "test_nm.obj")), std::runtime_error);
}

// Draco's own cube with texture coordinates: every decoded triangle's (position, uv) corners are
// those of one face of the OBJ it was made from ("f v/vt/vn"), read independently of libdraco.
TEST_F(DracoFilesTest, CubeTextureCoordinatesMatchTheObjCorners) {
  std::ifstream in(dir_ / "cube_att.obj");
  ASSERT_TRUE(in);
  std::vector<glm::dvec3> v;
  std::vector<glm::dvec2> vt;
  std::vector<std::array<std::pair<glm::dvec3, glm::dvec2>, 3>> faces;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      glm::dvec3 p;
      ls >> p.x >> p.y >> p.z;
      v.push_back(p);
    } else if (tag == "vt") {
      glm::dvec2 t;
      ls >> t.x >> t.y;
      vt.push_back(t);
    } else if (tag == "f") {
      std::array<std::pair<glm::dvec3, glm::dvec2>, 3> f;
      for (auto& corner : f) {
        std::string c;
        ls >> c;
        const std::size_t slash = c.find('/');
        const int iv = std::stoi(c.substr(0, slash)) - 1;
        const int it = std::stoi(c.substr(slash + 1)) - 1;
        corner = {v.at(static_cast<std::size_t>(iv)), vt.at(static_cast<std::size_t>(it))};
      }
      faces.push_back(f);
    }
  }
  ASSERT_EQ(faces.size(), 12u);
  for (const char* name :
       {"cube_att.obj.sequential.cl3.2.2.drc", "cube_att.obj.edgebreaker.cl4.2.2.drc",
        "cube_att.obj.edgebreaker.cl10.2.2.drc"}) {
    const DracoMesh d = DecodeMeshDracoWithUv(ReadFile(dir_ / name));
    ASSERT_EQ(d.uv.size(), d.mesh.vertices.size()) << name;
    ASSERT_EQ(d.mesh.triangles.size(), 12u) << name;
    for (const glm::ivec3& t : d.mesh.triangles) {
      bool found = false;
      for (const auto& f : faces) {
        int matched = 0;
        for (int c = 0; c < 3; ++c) {
          const auto i = static_cast<std::size_t>(t[c]);
          for (const auto& [p, uv] : f) {
            if (glm::length(d.mesh.vertices[i] - p) < 1e-3 && glm::length(d.uv[i] - uv) < 1e-3) {
              ++matched;
              break;
            }
          }
        }
        found = found || matched == 3;
      }
      EXPECT_TRUE(found) << name << ": a decoded triangle matches no face of the OBJ";
    }
  }
}

// ---- The depth-map stream (codecs/depth_map_codec.h).

/// A rough map: ridges, a fine texture and a hole with a ragged edge (NaN), heights in m.
std::vector<float> RoughDepthMap(int nx, int ny) {
  std::vector<float> h(static_cast<std::size_t>(nx) * ny);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const double x = i * 0.2e-3, y = j * 0.2e-3;
      const bool hole = std::hypot(x - 6e-3, y - 4e-3) < 2e-3 + 0.3e-3 * std::sin(9.0 * x);
      h[static_cast<std::size_t>(j) * nx + i] =
          hole ? std::nanf("")
               : static_cast<float>(1.3e-3 * std::abs(std::sin(x / 1.5e-3)) +
                                    40e-6 * std::sin(x / 0.31e-3) * std::cos(y / 0.47e-3) - 2e-3);
    }
  }
  return h;
}

TEST(DepthMapCodec, RoundTripKeepsEveryHeightWithinHalfAStepAndEveryHoleWhereItWas) {
  const int nx = 97, ny = 61;  // not multiples of 8: the bitmap's last byte is partial
  const std::vector<float> h = RoughDepthMap(nx, ny);
  for (const double step : {0.25e-6, 2e-6}) {
    const std::vector<std::uint8_t> bytes = EncodeDepthMap(h, nx, ny, {step, 6});
    DecodedDepthMap d;
    std::string error;
    ASSERT_TRUE(DecodeDepthMap(bytes, 256, d, error)) << error;
    ASSERT_EQ(d.nx, nx);
    ASSERT_EQ(d.ny, ny);
    EXPECT_NEAR(d.step_m, step, 1e-6 * step);
    double worst = 0.0;
    for (std::size_t k = 0; k < h.size(); ++k) {
      ASSERT_EQ(std::isnan(h[k]), std::isnan(d.heights_m[k])) << k;
      if (!std::isnan(h[k])) worst = std::max(worst, std::abs(double(h[k]) - d.heights_m[k]));
    }
    EXPECT_LE(worst, 0.5 * step + 6e-8 * 3.3e-3) << step;
    EXPECT_GE(worst, 0.25 * step) << "the quantization is as coarse as the step";
  }
}

TEST(DepthMapCodec, ARangeBeyondSixtyFiveThousandStepsWidensTheStepToFit) {
  const int n = 40;
  std::vector<float> h(static_cast<std::size_t>(n) * n);
  for (int k = 0; k < n * n; ++k) h[static_cast<std::size_t>(k)] = static_cast<float>(k * 1e-4);
  const std::vector<std::uint8_t> bytes = EncodeDepthMap(h, n, n, {0.25e-6, 6});
  DecodedDepthMap d;
  std::string error;
  ASSERT_TRUE(DecodeDepthMap(bytes, n, d, error)) << error;
  const double q = (n * n - 1) * 1e-4 / 65534;
  EXPECT_NEAR(d.step_m, q, 1e-6 * q);
  for (std::size_t k = 0; k < h.size(); ++k) {
    EXPECT_LE(std::abs(double(h[k]) - d.heights_m[k]), 0.5 * q + 6e-8 * 0.16) << k;
  }
}

TEST(DepthMapCodec, APlaneCostsAlmostNothingAndAnEmptyMapDecodesEmpty) {
  // A tilted plane: the prediction left + up − up-left is exact, so the residuals are rounding.
  const int n = 128;
  std::vector<float> plane(static_cast<std::size_t>(n) * n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i)
      plane[static_cast<std::size_t>(j) * n + i] = float(i * 3e-6 + j * 7e-6);
  }
  const std::vector<std::uint8_t> bytes = EncodeDepthMap(plane, n, n);
  EXPECT_LT(bytes.size(), plane.size() * 2 / 50) << "at most 2 % of 16 bits a node";
  const std::vector<float> empty(25, std::nanf(""));
  DecodedDepthMap d;
  std::string error;
  ASSERT_TRUE(DecodeDepthMap(EncodeDepthMap(empty, 5, 5), 8, d, error)) << error;
  EXPECT_EQ(
      std::count_if(d.heights_m.begin(), d.heights_m.end(), [](float x) { return std::isnan(x); }),
      25);
}

TEST(DepthMapCodec, EncoderRefusesWhatItCannotCarry) {
  const std::vector<float> h(16, 0.0f);
  EXPECT_THROW(EncodeDepthMap(h, 4, 5), std::invalid_argument);
  EXPECT_THROW(EncodeDepthMap(h, 0, 16), std::invalid_argument);
  std::vector<float> inf = h;
  inf[3] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(EncodeDepthMap(inf, 4, 4), std::invalid_argument);
  EXPECT_THROW(EncodeDepthMap(h, 4, 4, {0.0, 6}), std::invalid_argument);
  EXPECT_THROW(EncodeDepthMap(h, 4, 4, {1e-6, 0}), std::invalid_argument);
}

TEST(DepthMapCodec, DecoderRejectsEveryDamagedStreamWithAReasonAndNeverCrashes) {
  const int nx = 40, ny = 33;
  const std::vector<std::uint8_t> good = EncodeDepthMap(RoughDepthMap(nx, ny), nx, ny);
  DecodedDepthMap d;
  std::string error;
  ASSERT_TRUE(DecodeDepthMap(good, 64, d, error));
  const auto rejects = [&](std::vector<std::uint8_t> bytes, int max_side, const char* what) {
    error.clear();
    EXPECT_FALSE(DecodeDepthMap(bytes, max_side, d, error)) << what;
    EXPECT_FALSE(error.empty()) << what;
  };
  rejects({good.begin(), good.begin() + 10}, 64, "shorter than the header");
  rejects({good.begin(), good.end() - 3}, 64, "the zlib stream cut");
  std::vector<std::uint8_t> b = good;
  b[0] = 2;
  rejects(b, 64, "another format");
  rejects(good, 39, "a side beyond the receiver's limit");
  b = good;
  b[13] = 0xFF;
  b[14] = 0xFF;
  rejects(b, 64, "more present nodes than nodes");
  b = good;
  b[13] ^= 1;
  rejects(b, 64, "a count the bitmap disagrees with (or the stream's length)");
  b = good;
  b.push_back(0);
  rejects(b, 64, "bytes after the stream");
  b = good;
  b[5] = b[6] = b[7] = 0;
  b[8] = 0x80;  // −0.0: not a positive step
  rejects(b, 64, "a step of zero");
  // Every single-byte change and every cut: decoded or refused, never a crash (ASan/UBSan in
  // the sanitizer build).
  std::mt19937 rng(7);
  for (std::size_t k = 0; k < good.size(); ++k) {
    b = good;
    b[k] = static_cast<std::uint8_t>(b[k] ^ (1u + rng() % 255u));
    if (DecodeDepthMap(b, 64, d, error)) {
      EXPECT_EQ(d.heights_m.size(), static_cast<std::size_t>(d.nx) * d.ny);
    }
    DecodeDepthMap({good.data(), k}, 64, d, error);
  }
}

/// A prepared field whose environment is RoughDepthMap and whose tool is a tilted face.
DepthField RoughDepthField() {
  DepthField f;
  f.id = 7;
  f.lattice_id = 3;
  f.lattice_i0 = -40;
  f.lattice_j0 = 12;
  f.tool_lattice_i0 = -30;
  f.tool_lattice_j0 = -29;
  f.cell_m = 0.2e-3;
  f.nx = 70;
  f.ny = 64;
  f.tool_offset_u_m = 0.037e-3;
  f.tool_offset_v_m = -0.081e-3;
  f.X_WF.translation = {0.01, -0.02, 0.003};
  f.X_WF.rotation = glm::normalize(glm::dquat(0.9, 0.1, -0.2, 0.3));
  f.X_WT0.translation = {0.012, -0.015, 0.03};
  f.X_WT0.rotation = glm::normalize(glm::dquat(0.8, 0.0, 0.1, -0.1));
  f.travel_margin_m = 2e-3;
  f.smooth_max_m = 2e-6;
  f.force_law = ForceLaw::kPressure;
  f.pressure_area_m2 = 3.7e-4;
  f.stride_hint = 2;
  f.env_height_m = RoughDepthMap(f.nx, f.ny);
  f.tool_height_m.resize(f.env_height_m.size());
  for (int j = 0; j < f.ny; ++j) {
    for (int i = 0; i < f.nx; ++i) {
      const bool on = i > 5 && i < 60 && j > 8 && j < 55;
      f.tool_height_m[static_cast<std::size_t>(j) * f.nx + i] =
          on ? static_cast<float>(-1.95e-3 + 1e-6 * i) : std::nanf("");
    }
  }
  EXPECT_TRUE(f.Prepare());
  return f;
}

TEST(DepthFieldCodec, RoundTripKeepsTheFieldAndItsDepthWithinTheMapsStep) {
  const DepthField f = RoughDepthField();
  const std::vector<std::uint8_t> bytes = EncodeDepthField(f);
  EXPECT_EQ(bytes.size(), kDepthFieldFixedBytes +
                              EncodeDepthMap(f.env_height_m, f.nx, f.ny).size() +
                              EncodeDepthMap(f.tool_height_m, f.nx, f.ny).size());
  DepthField g;
  DecodedDepthMap scratch;
  std::string error;
  ASSERT_TRUE(DecodeDepthField(bytes, g, scratch, error)) << error;
  EXPECT_TRUE(g.prepared);
  EXPECT_EQ(g.id, f.id);
  EXPECT_EQ(g.lattice_id, f.lattice_id);
  EXPECT_EQ(g.lattice_i0, f.lattice_i0);
  EXPECT_EQ(g.lattice_j0, f.lattice_j0);
  EXPECT_EQ(g.tool_lattice_i0, f.tool_lattice_i0);
  EXPECT_EQ(g.tool_lattice_j0, f.tool_lattice_j0);
  EXPECT_EQ(g.cell_m, f.cell_m);
  EXPECT_EQ(g.nx, f.nx);
  EXPECT_EQ(g.ny, f.ny);
  EXPECT_EQ(g.tool_offset_u_m, f.tool_offset_u_m);
  EXPECT_EQ(g.tool_offset_v_m, f.tool_offset_v_m);
  EXPECT_EQ(g.X_WF.translation, f.X_WF.translation);
  EXPECT_EQ(g.X_WF.rotation, f.X_WF.rotation);
  EXPECT_EQ(g.X_WT0.translation, f.X_WT0.translation);
  EXPECT_EQ(g.X_WT0.rotation, f.X_WT0.rotation);
  EXPECT_EQ(g.travel_margin_m, f.travel_margin_m);
  EXPECT_EQ(g.smooth_max_m, f.smooth_max_m);
  EXPECT_EQ(g.force_law, f.force_law);
  EXPECT_EQ(g.pressure_area_m2, f.pressure_area_m2);
  EXPECT_EQ(g.stride_hint, f.stride_hint);
  EXPECT_EQ(g.node_stride, f.node_stride);
  // The depth at displaced poses moves by at most the two maps' half steps (0.25 µm each).
  for (const double dx : {0.0, 0.13e-3, -0.41e-3}) {
    RigidTransform X = f.X_WT0;
    X.translation += glm::dvec3(dx, 0.5 * dx, 0.0);
    const DepthFieldEvaluation a = DepthFieldDepthAt(f, X), b = DepthFieldDepthAt(g, X);
    ASSERT_TRUE(a.valid && b.valid);
    EXPECT_NEAR(a.depth_m, b.depth_m, 0.25e-6 + 1e-9) << dx;
  }
}

TEST(DepthFieldCodec, DecoderRefusesDamagedOrInvalidFieldsWithAReason) {
  const DepthField f = RoughDepthField();
  const std::vector<std::uint8_t> good = EncodeDepthField(f);
  DepthField g;
  DecodedDepthMap scratch;
  std::string error;
  const auto rejects = [&](const std::vector<std::uint8_t>& b, const char* what) {
    error.clear();
    EXPECT_FALSE(DecodeDepthField(b, g, scratch, error)) << what;
    EXPECT_FALSE(error.empty()) << what;
    EXPECT_FALSE(g.prepared) << what;
  };
  rejects({good.begin(), good.begin() + 100}, "cut in its header");
  rejects({good.begin(), good.end() - 1}, "cut in its tool map");
  std::vector<std::uint8_t> b = good;
  b.push_back(0);
  rejects(b, "a byte after it");
  b = good;
  b[0] = 9;
  rejects(b, "another format");
  DepthField bad = f;
  bad.id = 0;
  rejects(EncodeDepthField(bad), "id 0");
  bad = f;
  bad.X_WF.translation.x = std::numeric_limits<double>::quiet_NaN();
  rejects(EncodeDepthField(bad), "a frame that is not finite");
  bad = f;
  bad.tool_offset_u_m = 3 * f.cell_m;
  rejects(EncodeDepthField(bad), "a tool offset beyond a cell");
  bad = f;
  bad.force_law = static_cast<ForceLaw>(7);
  rejects(EncodeDepthField(bad), "an unknown force law");
  bad = f;
  bad.pressure_area_m2 = -1.0;
  rejects(EncodeDepthField(bad), "the pressure law with a negative reference area");
  bad = f;
  bad.pressure_area_m2 = 1e-300;  // Σ A d² / A_ref would overflow
  rejects(EncodeDepthField(bad), "the pressure law with a vanishing reference area");
  for (const int hint : {3, 16}) {
    bad = f;
    bad.stride_hint = static_cast<std::uint8_t>(hint);
    rejects(EncodeDepthField(bad), "a stride hint that is not 0 or a power of two up to 8");
  }
  // Sides that disagree with a map's.
  b = good;
  b[33] = static_cast<std::uint8_t>(f.nx - 1);  // nx, after 33 bytes
  rejects(b, "a map's sides not the field's");
  // Every single-byte change: decoded and prepared, or refused; never a crash.
  std::mt19937 rng(11);
  for (std::size_t k = 0; k < good.size(); k += 3) {
    b = good;
    b[k] = static_cast<std::uint8_t>(b[k] ^ (1u + rng() % 255u));
    if (DecodeDepthField(b, g, scratch, error)) {
      EXPECT_TRUE(g.prepared);
    }
  }
}

}  // namespace
}  // namespace ht
