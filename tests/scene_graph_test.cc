// The scene-graph object (transport/scene_graph.h): random graphs round-trip exactly, the encoder
// refuses every broken graph with a message naming what is wrong, the decoder refuses every
// truncation, flipped byte and impossible count without crashing or allocating for counts the
// bytes cannot hold, world poses compose as worked out by hand, NodePoses apply newest-wins, and
// a scene sent as a scene (graph, meshes, an image) arrives through the scene stream.
#include "transport/scene_graph.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <iterator>
#include <limits>
#include <new>
#include <numbers>
#include <random>
#include <stdexcept>

#include "haptic_core/byte_order.h"
#include "transport/scene_stream.h"

// Largest single allocation while asked: shows that a decoder refuses a count the bytes cannot
// hold before it allocates for it.
#include "allocation_counter.h"

namespace ht {
namespace {

constexpr double kPi = std::numbers::pi;

/// A name of 0..max_bytes bytes of UTF-8, with 1- to 4-byte characters.
std::string RandomName(std::mt19937& rng, std::size_t max_bytes) {
  static const char* const kPieces[] = {"a", "Z", "_", "7", "é", "ß", "€", "→", "𝄞", "😀", " "};
  std::string s;
  const std::size_t target = rng() % (max_bytes + 1);
  while (true) {
    const std::string piece = kPieces[rng() % std::size(kPieces)];
    if (s.size() + piece.size() > target) break;
    s += piece;
  }
  return s;
}

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

SceneGraphDescription RandomGraph(std::mt19937& rng) {
  SceneGraphDescription g;
  g.scene_name = RandomName(rng, rng() % 4 == 0 ? 255 : 20);
  const std::size_t materials = rng() % 6;
  for (std::size_t i = 0; i < materials; ++i) {
    SceneMaterial m;
    m.name = RandomName(rng, 30);
    m.base_colour_rgba = {static_cast<float>(Uniform(rng, 0, 1)),
                          static_cast<float>(Uniform(rng, 0, 1)),
                          static_cast<float>(Uniform(rng, 0, 1)), 1.0f};
    if (rng() % 2 == 0) {
      m.base_colour_texture_object = 1000 + static_cast<std::uint32_t>(i);
      m.texture_mime = rng() % 2 == 0 ? "image/png" : "image/jpeg";
    }
    g.materials.push_back(m);
  }
  const std::size_t nodes = rng() % 40;
  for (std::size_t i = 0; i < nodes; ++i) {
    SceneGraphNode n;
    n.name = RandomName(rng, rng() % 8 == 0 ? 255 : 24);
    n.parent = static_cast<std::int32_t>(rng() % (i + 1)) - 1;  // -1 .. i-1
    n.translation = {Uniform(rng, -2, 2), Uniform(rng, -2, 2), Uniform(rng, -2, 2)};
    n.rotation = glm::normalize(glm::dquat(Uniform(rng, -1, 1), Uniform(rng, -1, 1),
                                           Uniform(rng, -1, 1), Uniform(rng, -1, 1)));
    n.scale = {Uniform(rng, 0.1, 3), Uniform(rng, 0.1, 3), Uniform(rng, 0.1, 3)};
    n.mesh_object = rng() % 3 == 0 ? 0 : static_cast<std::uint32_t>(rng());
    n.material = static_cast<std::int32_t>(rng() % (materials + 1)) - 1;
    n.flags = static_cast<std::uint8_t>(rng() % 8);
    g.nodes.push_back(n);
  }
  if (rng() % 2 == 0) {
    SceneGraphCamera c;
    c.node = static_cast<std::int32_t>(rng() % (nodes + 1)) - 1;
    c.yfov_rad = Uniform(rng, 0.1, 3.0);
    c.znear_m = Uniform(rng, 0.001, 0.1);
    c.zfar_m = rng() % 2 == 0 ? 0.0 : c.znear_m + Uniform(rng, 0.1, 100);
    g.camera = c;
  }
  return g;
}

/// Field-by-field equality, exact (every value is sent at the precision it has).
void ExpectSameGraph(const SceneGraphDescription& a, const SceneGraphDescription& b) {
  EXPECT_EQ(a.scene_name, b.scene_name);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    const SceneGraphNode &x = a.nodes[i], &y = b.nodes[i];
    EXPECT_EQ(x.name, y.name) << i;
    EXPECT_EQ(x.parent, y.parent) << i;
    EXPECT_EQ(x.translation, y.translation) << i;
    EXPECT_EQ(x.rotation, y.rotation) << i;
    EXPECT_EQ(x.scale, y.scale) << i;
    EXPECT_EQ(x.mesh_object, y.mesh_object) << i;
    EXPECT_EQ(x.material, y.material) << i;
    EXPECT_EQ(x.flags, y.flags) << i;
  }
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (std::size_t i = 0; i < a.materials.size(); ++i) {
    const SceneMaterial &x = a.materials[i], &y = b.materials[i];
    EXPECT_EQ(x.name, y.name) << i;
    EXPECT_EQ(x.base_colour_rgba, y.base_colour_rgba) << i;
    EXPECT_EQ(x.base_colour_texture_object, y.base_colour_texture_object) << i;
    EXPECT_EQ(x.texture_mime, y.texture_mime) << i;
  }
  ASSERT_EQ(a.camera.has_value(), b.camera.has_value());
  if (a.camera) {
    EXPECT_EQ(a.camera->node, b.camera->node);
    EXPECT_EQ(a.camera->yfov_rad, b.camera->yfov_rad);
    EXPECT_EQ(a.camera->znear_m, b.camera->znear_m);
    EXPECT_EQ(a.camera->zfar_m, b.camera->zfar_m);
  }
}

/// A small valid graph: a table, a gear on it, a tool; two materials, one textured; a camera.
SceneGraphDescription SampleGraph() {
  SceneGraphDescription g;
  g.scene_name = "block_on_gear";
  g.materials = {{"steel", {0.6f, 0.6f, 0.65f, 1.0f}, 0, ""},
                 {"wood", {1.0f, 1.0f, 1.0f, 1.0f}, 30, "image/jpeg"}};
  g.nodes.resize(3);
  g.nodes[0] = {"table", -1, {0, 0, -0.01}, {1, 0, 0, 0}, {1, 1, 1}, 10, 1, kSceneNodeTouchable};
  g.nodes[1] = {"gear",
                0,
                {0, 0, 0.01},
                glm::angleAxis(0.3, glm::dvec3(0, 0, 1)),
                {1, 1, 1},
                11,
                0,
                kSceneNodeTouchable | kSceneNodeMoving};
  g.nodes[2] = {"tool", -1, {0, 0, 0.05}, {1, 0, 0, 0}, {1, 1, 1}, 12, 0, kSceneNodeTool};
  g.camera = SceneGraphCamera{-1, 0.9, 0.005, 5.0};
  return g;
}

/// The encoder's message for `g`, or "" when it accepts it.
std::string EncodeError(const SceneGraphDescription& g) {
  try {
    EncodeSceneGraph(g);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(SceneGraph, RandomGraphsRoundTripExactly) {
  std::mt19937 rng(5);
  int with_camera = 0, with_nodes = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const SceneGraphDescription g = RandomGraph(rng);
    const std::vector<std::uint8_t> bytes = EncodeSceneGraph(g);
    SceneGraphDescription back;
    std::string error;
    ASSERT_TRUE(DecodeSceneGraph(bytes, &back, &error)) << trial << ": " << error;
    ExpectSameGraph(g, back);
    EXPECT_EQ(EncodeSceneGraph(back), bytes) << trial;  // one encoding per graph
    with_camera += g.camera.has_value();
    with_nodes += !g.nodes.empty();
  }
  EXPECT_GT(with_camera, 100);
  EXPECT_GT(with_nodes, 250);
}

TEST(SceneGraph, TheLayoutIsTheDocumentedOne) {
  // An empty graph: magic, format version, empty scene name, two zero counts, no camera.
  const std::vector<std::uint8_t> empty = EncodeSceneGraph({});
  const std::vector<std::uint8_t> expected = {'H', 'T', 'S', 'G', 1, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(empty, expected);
  // One node of empty name: the smallest node; one material likewise; a camera.
  SceneGraphDescription g;
  g.nodes.emplace_back();
  g.materials.emplace_back();
  g.camera = SceneGraphCamera{};
  EXPECT_EQ(EncodeSceneGraph(g).size(), expected.size() + wire::kSceneGraphNodeMinBytes +
                                            wire::kSceneMaterialMinBytes +
                                            wire::kSceneGraphCameraBytes);
  // A node's fields in order: the parent right after the name, then the translation as f64.
  g = {};
  g.nodes.push_back({"n", -1, {0.25, 0, 0}, {1, 0, 0, 0}, {1, 1, 1}, 0x01020304u, -1, 5});
  const std::vector<std::uint8_t> b = EncodeSceneGraph(g);
  const std::size_t node = 11;  // after the header (6), name length (1), counts (4)
  EXPECT_EQ(b[node], 1);
  EXPECT_EQ(b[node + 1], 'n');
  EXPECT_EQ(LoadLe<std::uint32_t>(&b[node + 2]), 0xFFFFFFFFu);  // parent -1
  EXPECT_EQ(std::bit_cast<double>(LoadLe<std::uint64_t>(&b[node + 6])), 0.25);
  EXPECT_EQ(LoadLe<std::uint32_t>(&b[node + 6 + 80]), 0x01020304u);  // mesh_object
  EXPECT_EQ(b[node + 6 + 80 + 8], 5);                                // flags
}

TEST(SceneGraph, TheEncoderRefusesEveryBrokenGraphNamingWhatIsWrong) {
  ASSERT_EQ(EncodeError(SampleGraph()), "");
  const auto refused = [](const std::string& text, std::initializer_list<const char*> parts) {
    EXPECT_FALSE(text.empty());
    for (const char* part : parts) EXPECT_TRUE(Contains(text, part)) << text << " / " << part;
  };
  SceneGraphDescription g = SampleGraph();
  g.nodes[1].parent = 1;  // itself
  refused(EncodeError(g), {"node 1", "gear", "parent 1"});
  g = SampleGraph();
  g.nodes[0].parent = 2;  // a later node
  refused(EncodeError(g), {"node 0", "parent 2"});
  g = SampleGraph();
  g.nodes[2].parent = -2;
  refused(EncodeError(g), {"node 2", "parent -2"});
  g = SampleGraph();
  g.nodes[1].translation.y = std::numeric_limits<double>::quiet_NaN();
  refused(EncodeError(g), {"node 1", "translation"});
  g = SampleGraph();
  g.nodes[1].rotation.x = std::numeric_limits<double>::infinity();
  refused(EncodeError(g), {"node 1", "rotation"});
  g = SampleGraph();
  g.nodes[2].rotation = glm::dquat(0, 0, 0, 0);
  refused(EncodeError(g), {"node 2", "rotation", "zero length"});
  g = SampleGraph();
  g.nodes[2].rotation = glm::dquat(1e-200, 0, 0, 0);  // its square underflows
  refused(EncodeError(g), {"node 2", "rotation"});
  g = SampleGraph();
  g.nodes[0].scale.z = -std::numeric_limits<double>::infinity();
  refused(EncodeError(g), {"node 0", "scale"});
  g = SampleGraph();
  g.nodes[1].name = std::string(256, 'x');
  refused(EncodeError(g), {"node 1", "name", "256"});
  g = SampleGraph();
  g.nodes[1].name = "\xC3\x28";  // a broken two-byte sequence
  refused(EncodeError(g), {"node 1", "UTF-8"});
  g = SampleGraph();
  g.nodes[1].name = "\xED\xA0\x80";  // a surrogate
  refused(EncodeError(g), {"UTF-8"});
  g = SampleGraph();
  g.scene_name = std::string(300, 'x');
  refused(EncodeError(g), {"scene name", "300"});
  g = SampleGraph();
  g.materials[1].name = std::string(256, 'm');
  refused(EncodeError(g), {"material 1", "name"});
  g = SampleGraph();
  g.materials[1].texture_mime = std::string(256, 'm');
  refused(EncodeError(g), {"material 1", "texture_mime"});
  g = SampleGraph();
  g.materials[0].base_colour_rgba.a = std::numeric_limits<float>::quiet_NaN();
  refused(EncodeError(g), {"material 0", "base_colour_rgba"});
  g = SampleGraph();
  g.nodes[2].material = 2;  // two materials
  refused(EncodeError(g), {"node 2", "material 2"});
  g = SampleGraph();
  g.nodes[2].material = -5;
  refused(EncodeError(g), {"node 2", "material -5"});
  g = SampleGraph();
  g.nodes[0].flags = 8;
  refused(EncodeError(g), {"node 0", "flags"});
  g = SampleGraph();
  g.nodes.resize(kMaxSceneGraphNodes + 1);
  refused(EncodeError(g), {"65536 nodes"});
  g = SampleGraph();
  g.materials.resize(kMaxSceneMaterials + 1);
  refused(EncodeError(g), {"4097 materials"});
  g = SampleGraph();
  g.camera->node = 3;
  refused(EncodeError(g), {"camera", "node 3"});
  g = SampleGraph();
  g.camera->yfov_rad = kPi;
  refused(EncodeError(g), {"camera", "yfov_rad"});
  g = SampleGraph();
  g.camera->znear_m = 0.0;
  refused(EncodeError(g), {"camera", "znear_m"});
  g = SampleGraph();
  g.camera->zfar_m = 0.004;  // below znear
  refused(EncodeError(g), {"camera", "zfar_m"});
  g = SampleGraph();
  g.camera->zfar_m = std::numeric_limits<double>::infinity();
  refused(EncodeError(g), {"camera", "not finite"});
  // The limits themselves are accepted.
  g = SampleGraph();
  g.nodes.resize(kMaxSceneGraphNodes);
  g.materials.resize(kMaxSceneMaterials);
  g.nodes[1].name = std::string(255, 'x');
  g.scene_name = std::string(255, 'y');
  EXPECT_EQ(EncodeError(g), "");
}

TEST(SceneGraph, EveryTruncatedPrefixIsRefusedCleanly) {
  for (const SceneGraphDescription& g : {SampleGraph(), SceneGraphDescription{}}) {
    const std::vector<std::uint8_t> bytes = EncodeSceneGraph(g);
    for (std::size_t len = 0; len < bytes.size(); ++len) {
      // A copy of exactly `len` bytes, so that a read past its end is a heap overflow that the
      // sanitizers (and often the allocator) catch.
      const std::vector<std::uint8_t> prefix(bytes.begin(),
                                             bytes.begin() + static_cast<std::ptrdiff_t>(len));
      SceneGraphDescription out;
      out.scene_name = "untouched";
      std::string error;
      EXPECT_FALSE(DecodeSceneGraph(prefix, &out, &error)) << len;
      EXPECT_FALSE(error.empty()) << len;
      EXPECT_EQ(out.scene_name, "untouched") << len;
    }
    // A trailing byte is refused too.
    std::vector<std::uint8_t> longer = bytes;
    longer.push_back(0);
    SceneGraphDescription out;
    std::string error;
    EXPECT_FALSE(DecodeSceneGraph(longer, &out, &error));
    EXPECT_TRUE(Contains(error, "after the end")) << error;
  }
}

TEST(SceneGraph, RandomByteFlipsNeverCrashAndDecodeOnlyToValidGraphs) {
  std::mt19937 rng(11);
  int decoded = 0, refused = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    std::vector<std::uint8_t> bytes =
        EncodeSceneGraph(trial % 2 ? SampleGraph() : RandomGraph(rng));
    if (bytes.empty()) continue;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int f = 0; f < flips; ++f) {
      bytes[rng() % bytes.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    }
    SceneGraphDescription out;
    std::string error;
    if (DecodeSceneGraph(bytes, &out, &error)) {
      // Valid: the encoder accepts it and gives these very bytes.
      std::vector<std::uint8_t> again;
      ASSERT_NO_THROW(again = EncodeSceneGraph(out)) << trial;
      EXPECT_EQ(again, bytes) << trial;
      EXPECT_NO_THROW(ComposeWorldPoses(out)) << trial;
      ++decoded;
    } else {
      EXPECT_FALSE(error.empty());
      ++refused;
    }
  }
  EXPECT_GT(refused, 500);
  EXPECT_GT(decoded, 100);  // flips of names, flags, ids and values that stay valid
}

/// The header of a graph with the given counts and `extra` bytes after them.
std::vector<std::uint8_t> HeaderWithCounts(std::uint16_t nodes, std::uint16_t materials,
                                           std::size_t extra) {
  std::vector<std::uint8_t> b = {'H', 'T', 'S', 'G', 1, 0, 0};
  AppendLe(b, nodes);
  AppendLe(b, materials);
  b.resize(b.size() + extra, 0);
  return b;
}

TEST(SceneGraph, CountsBeyondTheBytesOrTheLimitsAreRefusedBeforeAllocating) {
  struct Case {
    std::uint16_t nodes, materials;
    std::size_t extra;
    const char* says;
  };
  for (const Case& c :
       {Case{65535, 0, 200, "need at least"}, Case{0, 4096, 100, "need at least"},
        Case{1000, 1000, 1000, "need at least"}, Case{0, 4097, 1000000, "limit is 4096"},
        Case{65535, 4096, 10, "need at least"}}) {
    const std::vector<std::uint8_t> bytes = HeaderWithCounts(c.nodes, c.materials, c.extra);
    SceneGraphDescription out;
    std::string error;
    error.reserve(512);
    testing_support::StartLargestAllocation();
    const bool ok = DecodeSceneGraph(bytes, &out, &error);
    const std::size_t largest = testing_support::StopLargestAllocation();
    EXPECT_FALSE(ok);
    EXPECT_TRUE(Contains(error, c.says)) << error;
    // Only small strings (the message) were allocated: nothing sized by the counts.
    EXPECT_LT(largest, 1024u) << c.nodes << " " << c.materials;
  }
  // The counter does see a decoder's allocations: a real graph of 3000 nodes needs a vector of
  // them.
  SceneGraphDescription big;
  big.nodes.resize(3000);
  const std::vector<std::uint8_t> bytes = EncodeSceneGraph(big);
  SceneGraphDescription out;
  testing_support::StartLargestAllocation();
  const bool ok = DecodeSceneGraph(bytes, &out, nullptr);
  const std::size_t largest = testing_support::StopLargestAllocation();
  EXPECT_TRUE(ok);
  EXPECT_GE(largest, 3000 * sizeof(SceneGraphNode));
}

TEST(SceneGraph, BadMagicVersionAndCameraFlagAreRefused) {
  const std::vector<std::uint8_t> good = EncodeSceneGraph(SampleGraph());
  SceneGraphDescription out;
  std::string error;
  std::vector<std::uint8_t> b = good;
  b[0] = 'X';
  EXPECT_FALSE(DecodeSceneGraph(b, &out, &error));
  EXPECT_TRUE(Contains(error, "magic")) << error;
  b = good;
  b[4] = 2;
  EXPECT_FALSE(DecodeSceneGraph(b, &out, &error));
  EXPECT_TRUE(Contains(error, "format version 2")) << error;
  b = good;
  b[b.size() - wire::kSceneGraphCameraBytes - 1] = 2;  // has_camera
  EXPECT_FALSE(DecodeSceneGraph(b, &out, &error));
  EXPECT_TRUE(Contains(error, "has_camera")) << error;
  // A value the encoder refuses, written by hand: node 1's parent set to 1.
  b = good;
  const std::size_t node1 = 6 + 1 + 13 + 4 + (1 + 5 + wire::kSceneGraphNodeMinBytes - 1);
  ASSERT_EQ(b[node1], 4);  // "gear"
  b[node1 + 1 + 4] = 1;
  EXPECT_FALSE(DecodeSceneGraph(b, &out, &error));
  EXPECT_TRUE(Contains(error, "node 1") && Contains(error, "parent 1")) << error;
  EXPECT_FALSE(DecodeSceneGraph(good, nullptr, &error));
}

/// X_WN's translation column.
glm::dvec3 Origin(const glm::dmat4& X) { return glm::dvec3(X[3]); }

TEST(SceneGraph, WorldPosesComposeFromTheRootsDownAsWorkedOutByHand) {
  // Parent P: turned 90° about z, at (1, 2, 3). Child C: at (0.5, 0, 0) in P.
  // By hand: R_WP takes x to y, so p_WC = (1, 2, 3) + (0, 0.5, 0) = (1, 2.5, 3), and C's x axis
  // points along W's y.
  SceneGraphDescription g;
  g.nodes.push_back(
      {"parent", -1, {1, 2, 3}, glm::angleAxis(kPi / 2, glm::dvec3(0, 0, 1)), {1, 1, 1}, 0, -1, 0});
  g.nodes.push_back({"child", 0, {0.5, 0, 0}, {1, 0, 0, 0}, {1, 1, 1}, 0, -1, 0});
  std::vector<glm::dmat4> X_WN = ComposeWorldPoses(g);
  ASSERT_EQ(X_WN.size(), 2u);
  const auto near = [](const glm::dvec3& a, const glm::dvec3& b) {
    return glm::length(a - b) < 1e-12;
  };
  EXPECT_TRUE(near(Origin(X_WN[0]), {1, 2, 3}));
  EXPECT_TRUE(near(Origin(X_WN[1]), {1, 2.5, 3})) << Origin(X_WN[1]).x << " " << Origin(X_WN[1]).y;
  EXPECT_TRUE(near(glm::dvec3(X_WN[1][0]), {0, 1, 0}));  // C's x axis in W
  EXPECT_TRUE(near(glm::dvec3(X_WN[1][2]), {0, 0, 1}));  // z unchanged
  // The parent's scale (2) scales the child's offset: (1, 2, 3) + (0, 1, 0). A rotation given
  // unnormalized (times 3) is normalized first.
  g.nodes[0].scale = {2, 2, 2};
  g.nodes[0].rotation = g.nodes[0].rotation * 3.0;
  X_WN = ComposeWorldPoses(g);
  EXPECT_TRUE(near(Origin(X_WN[1]), {1, 3, 3}));
  // A local override replaces the child's rest pose: at (0, 0.5, 0) in P it lands at
  // (1, 2, 3) + 2·(−0.5, 0, 0) = (0, 2, 3).
  std::vector<SceneNodeTransform> local = RestTransforms(g);
  local[1].translation = {0, 0.5, 0};
  X_WN = ComposeWorldPoses(g, local);
  EXPECT_TRUE(near(Origin(X_WN[1]), {0, 2, 3}));
  // A point on the child, by the matrices and by the chain of rotations and offsets.
  std::mt19937 rng(3);
  for (int i = 0; i < 20; ++i) {
    SceneGraphDescription r = RandomGraph(rng);
    if (r.nodes.empty()) continue;
    const std::vector<glm::dmat4> X = ComposeWorldPoses(r);
    const std::size_t leaf = r.nodes.size() - 1;
    const glm::dvec3 p_N{0.1, -0.2, 0.3};
    glm::dvec3 p = p_N;
    for (std::int32_t n = static_cast<std::int32_t>(leaf); n >= 0; n = r.nodes[n].parent) {
      const SceneGraphNode& node = r.nodes[static_cast<std::size_t>(n)];
      p = node.translation + glm::normalize(node.rotation) * (node.scale * p);
    }
    const glm::dvec3 by_matrix = glm::dvec3(X[leaf] * glm::dvec4(p_N, 1.0));
    EXPECT_LT(glm::length(by_matrix - p), 1e-9) << i;
  }
  // A parent out of order and a local array of the wrong size are refused.
  g.nodes[0].parent = 1;
  EXPECT_THROW(ComposeWorldPoses(g), std::invalid_argument);
  g.nodes[0].parent = -1;
  local.pop_back();
  EXPECT_THROW(ComposeWorldPoses(g, local), std::invalid_argument);
}

wire::NodePosesMessage Poses(std::uint32_t graph_version, double t,
                             std::initializer_list<std::pair<std::uint16_t, float>> entries) {
  wire::NodePosesMessage m;
  m.graph_version = graph_version;
  m.scene_time_s = t;
  for (const auto& [node, x] : entries) {
    wire::NodePose& p = m.poses[m.count++];
    p.node = node;
    p.translation = {x, 0.0f, 0.0f};
  }
  return m;
}

TEST(SceneNodePoses, TheNewestSceneTimeWinsPerNode) {
  const SceneGraphDescription g = SampleGraph();
  SceneNodePoses poses(g, 7);
  EXPECT_EQ(poses.local()[1].translation, g.nodes[1].translation);  // rest pose
  EXPECT_EQ(poses.node_time_s(1), -std::numeric_limits<double>::infinity());
  // Frame at t = 2 s in two datagrams; then a late datagram of the frame at t = 1 s.
  EXPECT_EQ(poses.Apply(Poses(7, 2.0, {{1, 0.2f}})), 1u);
  EXPECT_EQ(poses.Apply(Poses(7, 2.0, {{2, 0.3f}})), 1u);
  EXPECT_EQ(poses.Apply(Poses(7, 1.0, {{1, 0.1f}, {0, 0.05f}})), 1u);  // node 0 was at rest
  EXPECT_FLOAT_EQ(static_cast<float>(poses.local()[1].translation.x), 0.2f);
  EXPECT_FLOAT_EQ(static_cast<float>(poses.local()[2].translation.x), 0.3f);
  EXPECT_FLOAT_EQ(static_cast<float>(poses.local()[0].translation.x), 0.05f);
  EXPECT_EQ(poses.stats().entries_stale, 1u);
  EXPECT_EQ(poses.node_time_s(1), 2.0);
  EXPECT_EQ(poses.newest_time_s(), 2.0);
  // Another graph's poses and unknown nodes are not applied.
  EXPECT_EQ(poses.Apply(Poses(8, 3.0, {{1, 9.0f}})), 0u);
  EXPECT_EQ(poses.Apply(Poses(7, 3.0, {{3, 9.0f}, {1, 0.4f}})), 1u);
  EXPECT_EQ(poses.stats().messages_other_graph, 1u);
  EXPECT_EQ(poses.stats().entries_bad_node, 1u);
  EXPECT_FLOAT_EQ(static_cast<float>(poses.local()[1].translation.x), 0.4f);
  // The gear (node 1) at (0.4, 0, 0) in the table (node 0), which its pose of t = 1 s put at
  // (0.05, 0, 0) in W, both unrotated: p_WGear = (0.45, 0, 0).
  const std::vector<glm::dmat4> X_WN = ComposeWorldPoses(g, poses.local());
  EXPECT_NEAR(X_WN[1][3].x, 0.45, 1e-7);
  EXPECT_NEAR(X_WN[1][3].y, 0.0, 1e-12);
  EXPECT_NEAR(X_WN[1][3].z, 0.0, 1e-12);
}

TEST(SceneGraph, ASceneSentAsASceneArrivesThroughTheSceneStream) {
  // The remote side: one object per distinct mesh, an image, the graph naming them.
  const SceneGraphDescription g = SampleGraph();
  const std::vector<std::uint8_t> graph_bytes = EncodeSceneGraph(g);
  SceneSender sender(wire::kMinMtuBytes);
  for (std::uint32_t id : {10u, 11u, 12u})
    sender.Update(id, std::vector<std::uint8_t>(700 + id, static_cast<std::uint8_t>(id)));
  sender.Update(30, std::vector<std::uint8_t>(2000, 0xd8), wire::SceneObjectKind::kImage);
  EXPECT_EQ(sender.Update(1, graph_bytes, wire::SceneObjectKind::kSceneGraph), 1u);
  EXPECT_THROW(sender.Update(2, {1}, static_cast<wire::SceneObjectKind>(9)), std::invalid_argument);
  // Through the wire: manifests and fragments encoded, opened and decoded.
  const MacKey key = MacKey::Generate();
  SceneReassembler rx(wire::kMinMtuBytes);
  const auto deliver = [&](std::int64_t now) {
    for (const wire::SceneManifestMessage& m : sender.Manifest()) {
      const wire::Datagram d = wire::EncodeSceneManifest({}, m, key);
      wire::Header h;
      std::span<const std::uint8_t> body;
      ASSERT_EQ(wire::OpenDatagram(d.view(), key, h, body), wire::DecodeStatus::kOk);
      wire::SceneManifestMessage got;
      ASSERT_EQ(wire::DecodeSceneManifest(body, got), wire::DecodeStatus::kOk);
      rx.OnManifest(got, now);
    }
    wire::SceneFragmentMessage f;
    while (sender.Next(f)) {
      const wire::Datagram d = wire::EncodeSceneFragment({}, f, key);
      wire::Header h;
      std::span<const std::uint8_t> body;
      ASSERT_EQ(wire::OpenDatagram(d.view(), key, h, body), wire::DecodeStatus::kOk);
      wire::SceneFragmentMessage got;
      ASSERT_EQ(wire::DecodeSceneFragment(body, got), wire::DecodeStatus::kOk);
      rx.Add(got, now);
    }
  };
  EXPECT_FALSE(rx.ObjectKind(1).has_value());  // before any manifest
  deliver(1);
  ASSERT_TRUE(rx.SceneComplete());
  // The operator finds the graph among the objects and reads it.
  std::uint32_t graph_id = 0;
  for (std::uint32_t id : {1u, 10u, 11u, 12u, 30u}) {
    if (rx.ObjectKind(id) == wire::SceneObjectKind::kSceneGraph) graph_id = id;
  }
  ASSERT_EQ(graph_id, 1u);
  EXPECT_EQ(rx.ObjectKind(30), wire::SceneObjectKind::kImage);
  EXPECT_EQ(rx.ObjectKind(10), wire::SceneObjectKind::kDracoMesh);
  EXPECT_FALSE(rx.ObjectKind(99).has_value());
  SceneGraphDescription got;
  std::string error;
  ASSERT_TRUE(DecodeSceneGraph(rx.CompletedBytes(graph_id), &got, &error)) << error;
  ExpectSameGraph(g, got);
  for (const SceneGraphNode& n : got.nodes) EXPECT_EQ(rx.CompletedVersion(n.mesh_object), 1u);
  EXPECT_EQ(rx.CompletedVersion(got.materials[1].base_colour_texture_object), 1u);
  EXPECT_EQ(rx.CompletedVersion(99), 0u);
  // A new version of one mesh: 0 while under way, then 2.
  sender.Update(11, std::vector<std::uint8_t>(900, 0x42));
  wire::SceneFragmentMessage f;
  ASSERT_TRUE(sender.Next(f));
  std::vector<std::uint8_t> first(f.payload.begin(), f.payload.end());
  f.payload = first;
  rx.Add(f, 2);
  EXPECT_EQ(rx.CompletedVersion(11), 0u);
  deliver(3);
  EXPECT_EQ(rx.CompletedVersion(11), 2u);
  EXPECT_EQ(rx.CompletedVersion(10), 1u);
}

}  // namespace
}  // namespace ht

namespace ht {
namespace {

// Names from files have no limit: SceneGraphName keeps what a graph can carry, cut between two
// characters, and the encoder takes it.
TEST(SceneGraph, NamesFromFilesAreCutToWhatTheGraphCarries) {
  const std::string e_acute = "\xC3\xA9";  // é, two bytes
  std::string long_name;
  for (int i = 0; i < 200; ++i) long_name += e_acute;  // 400 bytes
  const std::string cut = SceneGraphName(long_name);
  EXPECT_LE(cut.size(), kMaxSceneGraphNameBytes);
  EXPECT_EQ(cut.size(), 254u);  // 127 characters: the 128th would end at byte 256
  EXPECT_EQ(SceneGraphName("wheel"), "wheel");
  EXPECT_EQ(SceneGraphName(std::string("bad \xC0\x80 name")), "");  // overlong: not UTF-8
  SceneGraphDescription g;
  g.nodes.resize(1);
  g.nodes[0].name = cut;
  g.scene_name = SceneGraphName(std::string(300, 'x'));
  EXPECT_EQ(g.scene_name.size(), kMaxSceneGraphNameBytes);
  SceneGraphDescription back;
  std::string error;
  ASSERT_TRUE(DecodeSceneGraph(EncodeSceneGraph(g), &back, &error)) << error;
  EXPECT_EQ(back.nodes[0].name, cut);
}

}  // namespace
}  // namespace ht
