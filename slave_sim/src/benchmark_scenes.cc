#include "slave_sim/benchmark_scenes.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <future>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <map>
#include <mutex>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "haptic_core/accuracy/mesh_contact_baseline.h"
#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/model_build/surface_error.h"

namespace ht {
namespace {
constexpr double kStiffness = 8000.0;  // N/m, the gear's (MakeBlockOnGearScene)

// The seed models' full-resolution meshes take up to 0.3 s each to generate: made once.
std::shared_ptr<const TriangleMesh> SeedMesh(SeedModel model) {
  static std::mutex mutex;
  static std::map<SeedModel, std::shared_ptr<const TriangleMesh>> meshes;
  const std::lock_guard<std::mutex> lock(mutex);
  auto& slot = meshes[model];
  if (!slot) slot = std::make_shared<const TriangleMesh>(MakeSeedModelFullResolution(model));
  return slot;
}

// The hammer turned head down (a half turn about x: (x, y, z) → (x, −y, −z)), so that its striking
// face looks down at the identity pose: the operator's workspace is aligned with the tool's home
// orientation, whose +z must be the scene's up.
std::shared_ptr<const TriangleMesh> HammerHeadDown() {
  static std::mutex mutex;
  static std::shared_ptr<const TriangleMesh> mesh;
  const std::lock_guard<std::mutex> lock(mutex);
  if (!mesh) {
    TriangleMesh m = *SeedMesh(SeedModel::kHammer);
    for (glm::dvec3& p : m.vertices) p = {p.x, -p.y, -p.z};
    mesh = std::make_shared<const TriangleMesh>(std::move(m));
  }
  return mesh;
}

// A copy of `model` without its texture: every face smooth, nothing reaching out of the coarse
// surface.
std::shared_ptr<const HapticModel> Untextured(const HapticModel& model) {
  auto m = std::make_shared<HapticModel>(model);
  std::fill(m->textured.begin(), m->textured.end(), std::uint8_t{0});
  m->outward_reach_m = 0.0;
  m->name += "_untextured";
  return m;
}

std::shared_ptr<const HapticModel> Finish(HapticModel model, bool textured) {
  if (!textured) return Untextured(model);
  return std::make_shared<const HapticModel>(std::move(model));
}

// A seed model through the build cache, its frame moved to its centre of mass when `centred`
// (the tool frame T); `com_out` gets where that centre was in the mesh's frame.
std::shared_ptr<const HapticModel> SeedHapticModel(
    SeedModel model, const BenchmarkModelSettings& settings, const HapticModelCache& cache,
    bool centred, glm::dvec3* com_out, std::shared_ptr<const TriangleMesh> mesh,
    const std::string& name, std::string* texture_note) {
  HapticModelBuildParams params;
  params.coarse_triangles = std::max(
      4, static_cast<int>(
             std::lround(settings.coarse_scale *
                         static_cast<double>(SeedModelSpecOf(model).seed_coarse_triangles))));
  if (settings.texture_size == 0) {
    params.texture_sizing.from_detail = true;
  } else {
    params.texture.texture_size = settings.texture_size;
  }
  const HapticModelBuild build = BuildHapticModelCached(name, *mesh, params, cache);
  if (texture_note != nullptr && settings.texture_size == 0) {
    *texture_note = name + " " + build.report.texture_size_reason;
  }
  HapticModel m = *build.model;
  if (com_out != nullptr) *com_out = m.center_of_mass_O;
  if (centred) ShiftModelFrame(m, m.center_of_mass_O);
  return Finish(std::move(m), settings.textured);
}

// A procedural model at the size its detail needs (texture_size 0, TextureSizingParams'
// defaults): `make(size)` builds it at one size, measured against `full_O`; `note` gets the
// reason.
template <typename Make>
HapticModel ProceduralAtSize(int texture_size, const TriangleMesh& full_O, const Make& make,
                             const std::string& name, std::string* note) {
  if (texture_size != 0) return make(texture_size);
  std::map<int, HapticModel> made;
  const TextureSizeChoice choice = ChooseTextureSize({}, [&](int size) {
    HapticModel m = make(size);
    const SurfaceErrorReport r = MeasureSurfaceError(m, full_O);
    // The rule keeps this size or the one before: larger textures are not held longer.
    made.erase(size / 4);
    made.emplace(size, std::move(m));
    return r;
  });
  if (note != nullptr) *note = name + " " + choice.reason;
  return std::move(made.at(choice.size));
}

}  // namespace

namespace {

// Lowest z of `mesh` posed with rotation R (translation zero), and highest z of the object mesh
// at its pose.
double LowestZ(const TriangleMesh& mesh, const glm::dquat& R) {
  double z = std::numeric_limits<double>::infinity();
  for (const glm::dvec3& p : mesh.vertices) z = std::min(z, (R * p).z);
  return z;
}
double HighestZ(const TriangleMesh& mesh, const RigidTransform& X) {
  double z = -std::numeric_limits<double>::infinity();
  for (const glm::dvec3& p : mesh.vertices) z = std::max(z, (X * p).z);
  return z;
}

// Height z of the tool mesh's frame (orientation R, position xy) at which its full-resolution
// mesh first touches the object's when lowered along −z: bisection on FCL's intersection test to
// 10 nm. NaN when nothing is under the tool within 3 cm below the object's top.
double TouchHeight(const MeshContactBaseline& meshes, const BenchmarkScene& scene,
                   const glm::dquat& R, const glm::dvec2& xy) {
  const RigidTransform X_WFe = scene.haptic.touchables.at(0).X_WO;
  const double top = HighestZ(*scene.object_mesh_Fe, X_WFe);
  double hi = top - LowestZ(*scene.tool_mesh_Ft, R) + 1e-3;  // clear above the object
  double lo = hi - 0.03;
  RigidTransform X_WFt;
  X_WFt.rotation = R;
  X_WFt.translation = {xy.x, xy.y, lo};
  if (!meshes.Intersects(X_WFt, X_WFe)) return std::numeric_limits<double>::quiet_NaN();
  while (hi - lo > 1e-8) {
    const double mid = 0.5 * (lo + hi);
    X_WFt.translation.z = mid;
    (meshes.Intersects(X_WFt, X_WFe) ? lo : hi) = mid;
  }
  return hi;
}

}  // namespace

BenchmarkModelSettings ProductModelSettings(const std::string& name) {
  BenchmarkModelSettings s;
  if (name == "fig77") {
    s.texture_size = 2048;
    s.coarse_scale = 2.0;
  } else if (name == "hammer_torus") {
    s.texture_size = 0;    // from each model's detail: 4096² for both (eighth stop)
    s.coarse_scale = 4.0;  // issue 32's twenty-eighth stop
  }
  return s;
}

const std::vector<std::string>& BenchmarkSceneNames() {
  static const std::vector<std::string> names = {"fig75", "fig76", "fig77", "hammer_torus"};
  return names;
}

std::string BenchmarkSceneOfBuiltin(const std::string& scene) {
  if (scene == "striped-blocks") return "fig76";
  if (scene == "file-on-cad-part") return "fig77";
  if (scene == "hammer-on-torus") return "hammer_torus";
  return {};
}

BenchmarkScene MakeBenchmarkScene(const std::string& name, const BenchmarkModelSettings& settings,
                                  const HapticModelCache& cache) {
  if (settings.texture_size != 0 && (settings.texture_size < 16 || settings.texture_size > 8192 ||
                                     (settings.texture_size & (settings.texture_size - 1)) != 0)) {
    throw std::invalid_argument(
        "texture size must be 0 (from the detail) or a power of two in [16, 8192], got " +
        std::to_string(settings.texture_size));
  }
  std::string tool_texture_note, object_texture_note;
  if (!(settings.coarse_scale > 0.0) || settings.coarse_scale > 16.0) {
    throw std::invalid_argument("coarse scale must be in (0, 16], got " +
                                std::to_string(settings.coarse_scale));
  }
  BenchmarkScene scene;
  scene.name = name;
  scene.haptic.name = name;
  TouchableObject object;
  object.stiffness_n_per_m = kStiffness;
  if (name == "fig75" || name == "fig76") {
    RidgedBlockParams block;
    scene.tool_mesh_Ft = std::make_shared<const TriangleMesh>(MakeRidgedBlockFullResolution());
    const auto make_block = [&](int size) {
      RidgedBlockParams b = block;
      b.texture_size = size;
      return MakeRidgedBlock(b);
    };
    scene.haptic.tool = Finish(ProceduralAtSize(settings.texture_size, *scene.tool_mesh_Ft,
                                                make_block, "ridged_block", &tool_texture_note),
                               settings.textured);
    scene.tool_name = "ridged_block";
    scene.X_TFt = RigidTransform::Identity();  // the block's frame is its centre of mass
    if (name == "fig75") {
      RidgedGearParams gear;
      gear.coarse_segments =
          std::max(8, static_cast<int>(std::lround(400 * settings.coarse_scale)));
      scene.object_mesh_Fe = std::make_shared<const TriangleMesh>(MakeRidgedGearFullResolution());
      const auto make_gear = [&](int size) {
        RidgedGearParams g = gear;
        g.texture_size = size;
        return MakeRidgedGear(g);
      };
      object.model = Finish(ProceduralAtSize(settings.texture_size, *scene.object_mesh_Fe,
                                             make_gear, "ridged_gear", &object_texture_note),
                            settings.textured);
      scene.object_name = "ridged_gear";
      scene.haptic.X_WT_home = BlockOnGearHomePose();
      scene.note = "block: 16 coarse triangles at every coarse scale (a box)";
    } else {
      // The lower striped block: the same block turned over about x, its striped face up at z = 0.
      // A model object of its own: per-model caches (the proximity query's) must not see the
      // tool and the object as one model.
      object.model = std::make_shared<const HapticModel>(*scene.haptic.tool);
      scene.object_mesh_Fe = scene.tool_mesh_Ft;
      scene.object_name = "ridged_block";
      object.X_WO.rotation = glm::angleAxis(std::numbers::pi, glm::dvec3(1.0, 0.0, 0.0));
      object.X_WO.translation = {0.0, 0.0, -block.half_extents_m.z};
      // Interlocked: the upper block's crests over the lower one's valleys (half a period in y).
      // Home 0.5 mm above touching, as the block on the gear.
      scene.haptic.X_WT_home.translation = {0.0, 0.5 * block.ridges.period_m,
                                            block.half_extents_m.z + 0.5e-3};
      scene.note = "both blocks: 16 coarse triangles at every coarse scale (boxes)";
    }
  } else if (name == "fig77" || name == "hammer_torus") {
    const bool file = name == "fig77";
    const SeedModel tool = file ? SeedModel::kFile : SeedModel::kHammer;
    const SeedModel env = file ? SeedModel::kCadPart : SeedModel::kTorus;
    glm::dvec3 com(0.0);
    scene.tool_mesh_Ft = file ? SeedMesh(tool) : HammerHeadDown();
    scene.tool_name = file ? SeedModelName(tool) : "hammer_head_down";
    // The two models are independent: the object's is built on a second thread while this one
    // builds the tool's (a cold cache spends 6-36 s per model in the decimation; the results are
    // the same bits either way). Should the tool's build throw, the future's destructor waits
    // for the object's, which writes into object_texture_note (declared before it).
    auto object_build = std::async(std::launch::async, [&] {
      return SeedHapticModel(env, settings, cache, false, nullptr, SeedMesh(env),
                             SeedModelName(env), &object_texture_note);
    });
    scene.haptic.tool = SeedHapticModel(tool, settings, cache, true, &com, scene.tool_mesh_Ft,
                                        scene.tool_name, &tool_texture_note);
    scene.X_TFt.translation = -com;
    object.model = object_build.get();
    scene.object_mesh_Fe = SeedMesh(env);
    scene.object_name = SeedModelName(env);
  } else {
    std::string known;
    for (const std::string& n : BenchmarkSceneNames()) known += (known.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown benchmark scene '" + name + "' (known: " + known + ")");
  }
  scene.haptic.touchables.push_back(object);
  for (const std::string* n : {&tool_texture_note, &object_texture_note}) {
    if (n->empty()) continue;
    scene.texture_note += (scene.texture_note.empty() ? "" : "; ") + *n;
  }
  if (name == "fig77" || name == "hammer_torus") {
    // Home: where the scraping experiment starts, 1 mm above the first full-resolution touch.
    // The file lies flat (teeth down) at x = −3 cm over the part; the hammer (its mesh head
    // down), head along x, over the torus's tube at (−3 cm, R), where the tube runs along x. The
    // home orientation is the identity: the operator's workspace is aligned with it.
    const MeshContactBaseline meshes(*scene.tool_mesh_Ft, *scene.object_mesh_Fe);
    RigidTransform X_WFt;
    if (name == "hammer_torus") {
      X_WFt.translation = {-0.03, WrinkledTorusParams{}.major_radius_m, 0.0};
    } else {
      X_WFt.translation = {-0.03, 0.0, 0.0};
    }
    const double touch =
        TouchHeight(meshes, scene, X_WFt.rotation, {X_WFt.translation.x, X_WFt.translation.y});
    if (std::isnan(touch)) throw std::logic_error(name + ": nothing under the tool's home");
    X_WFt.translation.z = touch + 1e-3;
    scene.haptic.X_WT_home = X_WFt * scene.X_TFt.Inverse();
  }
  scene.tool_coarse_triangles = static_cast<std::int64_t>(scene.haptic.tool->triangles.size());
  scene.object_coarse_triangles = static_cast<std::int64_t>(object.model->triangles.size());
  return scene;
}

namespace {

// One scripted pose before lowering: orientation, xy, and the extra depth once touching (m).
struct PoseScript {
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};
  glm::dvec2 xy{0.0};
  double depth_m = 0.0;
};

PoseScript ScriptAt(const std::string& scene, double s) {
  PoseScript p;
  const double wave = 0.5 + 0.5 * std::sin(2 * std::numbers::pi * 5 * s + 0.7);  // 0..1
  const auto deg = [](double d) { return d * std::numbers::pi / 180.0; };
  const auto rot = [](double angle, glm::dvec3 axis) { return glm::angleAxis(angle, axis); };
  const glm::dvec3 X(1, 0, 0), Y(0, 1, 0), Z(0, 0, 1);
  if (scene == "fig75") {  // along the ridges (x), across them (y), with a little tilt
    p.xy = {8e-3 * std::sin(2 * std::numbers::pi * 2 * s),
            6e-3 * std::sin(2 * std::numbers::pi * 3 * s + 0.3)};
    p.rotation = rot(deg(3.0) * std::sin(2 * std::numbers::pi * 4 * s), Z) *
                 rot(deg(1.5) * std::sin(2 * std::numbers::pi * 7 * s), X) *
                 rot(deg(1.5) * std::sin(2 * std::numbers::pi * 5 * s + 1.0), Y);
    p.depth_m = 0.05e-3 + 0.35e-3 * wave;
  } else if (scene == "fig76") {  // small oscillating rotations about n, interlocked
    p.xy = {4e-3 * std::sin(2 * std::numbers::pi * s),
            1.5e-3 + 0.2e-3 * std::sin(2 * std::numbers::pi * 3 * s)};
    p.rotation = rot(deg(3.0) * std::sin(2 * std::numbers::pi * 6 * s), Z);
    p.depth_m = 0.02e-3 + 0.18e-3 * wave;
  } else if (scene == "fig77") {  // scraping along the part, with sway and yaw (as fig77_scrape)
    p.xy = {-0.03 + 0.06 * s, 0.01 * std::sin(2 * std::numbers::pi * 2 * s)};
    p.rotation = rot(deg(5.0) * std::sin(2 * std::numbers::pi * 3 * s), Z);
    p.depth_m = 0.05e-3 + 0.35e-3 * wave;
  } else {  // hammer_torus: the head (turned down) along the tube, with wobble
    const double phi = deg(-25.0 + 50.0 * s);
    const double R = WrinkledTorusParams{}.major_radius_m;
    p.xy = {R * std::cos(phi), R * std::sin(phi)};
    p.rotation =
        rot(phi + 0.5 * std::numbers::pi + deg(8.0) * std::sin(2 * std::numbers::pi * 4 * s), Z) *
        rot(deg(3.0) * std::sin(2 * std::numbers::pi * 3 * s), X);  // the mesh is head down
    p.depth_m = 0.05e-3 + 0.35e-3 * wave;
  }
  return p;
}

}  // namespace

std::vector<RigidTransform> ScriptedContactPoses(const BenchmarkScene& scene, int count) {
  std::vector<RigidTransform> poses;
  if (count <= 0) return poses;
  const MeshContactBaseline meshes(*scene.tool_mesh_Ft, *scene.object_mesh_Fe);
  for (int i = 0; i < count; ++i) {
    const double s = (i + 0.5) / count;
    const PoseScript script = ScriptAt(scene.name, s);
    const double touch = TouchHeight(meshes, scene, script.rotation, script.xy);
    if (std::isnan(touch)) continue;  // nothing under the tool here
    RigidTransform X_WFt;
    X_WFt.rotation = script.rotation;
    X_WFt.translation = {script.xy.x, script.xy.y, touch - script.depth_m};
    poses.push_back(X_WFt);
  }
  return poses;
}

std::vector<RigidTransform> PosesFromTrace(const std::string& path, const BenchmarkScene& scene,
                                           int count, double from_s) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read the trace");
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path + ": empty trace");
  std::vector<std::string> columns;
  {
    std::stringstream header(line);
    for (std::string c; std::getline(header, c, ',');) columns.push_back(c);
  }
  const char* wanted[] = {"tool_x",  "tool_y",  "tool_z",   "tool_rx",
                          "tool_ry", "tool_rz", "contacts", "t_s"};
  int index[8];
  for (int k = 0; k < 8; ++k) {
    const auto it = std::find(columns.begin(), columns.end(), wanted[k]);
    if (it == columns.end()) {
      throw std::runtime_error(path + ": no column '" + wanted[k] +
                               "' (not a master_station trace.csv?)");
    }
    index[k] = static_cast<int>(it - columns.begin());
  }
  std::vector<RigidTransform> in_contact;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string c; std::getline(row, c, ',');) cells.push_back(c);
    if (cells.size() != columns.size()) continue;  // a truncated last row
    double v[8];
    bool ok = true;
    for (int k = 0; k < 8; ++k) {
      char* end = nullptr;
      v[k] = std::strtod(cells[index[k]].c_str(), &end);
      ok = ok && end != cells[index[k]].c_str() && std::isfinite(v[k]);
    }
    if (!ok || v[6] < 1.0 || (from_s >= 0.0 && v[7] < from_s)) continue;
    RigidTransform X_WT;
    X_WT.translation = {v[0], v[1], v[2]};
    X_WT.rotation = QuaternionFromRotationVector({v[3], v[4], v[5]});
    in_contact.push_back(X_WT * scene.X_TFt);
  }
  if (in_contact.empty()) throw std::runtime_error(path + ": no row in contact");
  std::vector<RigidTransform> out;
  const int n = std::min<int>(count, static_cast<int>(in_contact.size()));
  if (from_s >= 0.0) return {in_contact.begin(), in_contact.begin() + n};
  for (int i = 0; i < n; ++i) {
    out.push_back(in_contact[static_cast<std::size_t>((i + 0.5) * in_contact.size() / n)]);
  }
  return out;
}

}  // namespace ht
