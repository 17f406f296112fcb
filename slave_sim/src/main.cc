// slave_sim: the remote simulation node. Listens for tool states over UDP and streams contact
// models computed with 6-DoF haptic texture rendering on the scene.

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "codecs/draco_mesh_codec.h"
#include "codecs/glb_writer.h"
#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/haptic_scene.h"
#include "slave_sim/benchmark_scenes.h"
#include "slave_sim/remote_node.h"
#include "slave_sim/scene_build.h"
#include "slave_sim/watched_scene.h"
#include "transport/command_line.h"

namespace {
std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop.store(true); }
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "slave_sim: remote simulation node of the networked 6-DoF haptic texture rendering system.\n"
      "Per step it takes the latest tool pose received, runs the coarse contact query and the\n"
      "texture penetration depth with its gradient, and sends the linearized contact model back.\n"
      "Every datagram is authenticated with a pre-shared key (--key; make one with 'slave_sim\n"
      "keygen FILE' and copy it to the operator machine). Stops on SIGINT/SIGTERM or when the\n"
      "operator side says goodbye (unless --stay)."};
  app.set_config("--config", "",
                 "read options from a TOML file (key = value, long option names without dashes);\n"
                 "command-line options override it");
  std::string listen = "127.0.0.1:47000", out_dir, port_file, scene = "block-on-gear";
  ht::RemoteNodeConfig config;
  bool quiet = false, stay = false;
  std::string pd_backend = "auto";
  app.add_option("--listen", listen, "UDP address HOST:PORT to listen on (port 0 = any free)")
      ->capture_default_str();
  app.add_option("--scene", scene,
                 "built-in scene: block-on-gear (seed Fig. 75), stiff-wall (the same block on a\n"
                 "flat wall five times stiffer, a stability hard case), striped-blocks (two\n"
                 "interlocked striped blocks, seed Fig. 76), file-on-cad-part (seed Fig. 77) or\n"
                 "hammer-on-torus (seed Fig. 73; these two build the seed models through the\n"
                 "cache, about a minute each when cold); or a scene file (.gltf,\n"
                 ".glb, or a scene description .json), built through the model cache (see\n"
                 "'slave_sim inspect'); its glTF animation 0, if any, plays in a loop")
      ->capture_default_str();
  std::string scene_tool, scene_cache_dir = ht::HapticModelCache::DefaultDir();
  app.add_option("--tool", scene_tool,
                 "with a scene file: the node (name or #index) that is the tool; default the\n"
                 "description's, else the built-in probe");
  bool no_watch = false;
  app.add_flag("--no-watch", no_watch,
               "with a scene file: do not watch it (by default a change of the file on disk\n"
               "rebuilds the scene through the cache, switches the pipeline to it between two\n"
               "steps and streams the changed meshes to the operator)");
  app.add_option("--cache-dir", scene_cache_dir,
                 "with a scene file or a seed-model scene: the model cache folder")
      ->capture_default_str();
  app.add_option("--grid", config.pipeline.grid_resolution,
                 "penetration-depth grid N (N x N cells per contact)")
      ->check(CLI::Range(2, 1024))
      ->capture_default_str();
  app.add_option("--window", config.pipeline.window_extent_m,
                 "smallest contact window side W in metres (with the grid N: the cell W/N)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  CLI::Option* max_window_option =
      app.add_option("--max-window", config.pipeline.max_window_extent_m,
                     "largest contact window side in metres: a cluster spread wider than W gets a\n"
                     "window sized to it at the same cell (N grows with it); overlapping windows\n"
                     "with agreeing normals merge while they fit. Default 3 x --window; equal to\n"
                     "--window: every window W x W")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
  config.pipeline.texture_threads = ht::DefaultTextureThreads();
  app.add_option("--texture-threads", config.pipeline.texture_threads,
                 "threads of the CPU texture stage (a step's contacts spread over them); the\n"
                 "default leaves one core to the operator on a loopback machine")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  std::string rotation_gradient = "rendered";
  app.add_option("--rotation-gradient", rotation_gradient,
                 "rotation part of each contact's gradient (CPU texture stage): rendered (six\n"
                 "rotated tool renders), warp (rotation samples from the base render) or lever\n"
                 "(the deepest cell's r x dδ/dx); warp and lever render the tool once per contact\n"
                 "instead of seven times and are approximations: see docs/frontier/issue15")
      ->check(CLI::IsMember({"rendered", "warp", "lever"}))
      ->capture_default_str();
  bool no_grazing_guard = false;
  app.add_flag("--no-grazing-guard", no_grazing_guard,
               "keep contacts whose depth exceeds what their coarse geometry allows (the\n"
               "cluster's hull penetration + both texture reaches + a cell); by default they are\n"
               "dropped and counted (remote_summary.json grazing_dropped_contacts): along a\n"
               "grazing direction the depth is a sideways overlap, not a penetration");
  bool no_kink_planes = false;
  app.add_flag("--no-kink-planes", no_kink_planes,
               "send one plane per contact: by default a contact whose depth is a V in the tilt\n"
               "(a face resting on ridges, its two edges bearing in turn) also carries the V's\n"
               "arms, so that the operator's loop finds where the torque flips between two models\n"
               "(docs/hard-cases.md)");
  bool no_refine_depth = false;
  app.add_flag("--no-refine-depth", no_refine_depth,
               "the grid's cell samples alone: by default each contact's depth is refined to the\n"
               "texture's full resolution around the grid's deepest cells (stage 5b,\n"
               "docs/DESIGN.md §4), which the grid's mip-filtered samples read tens of\n"
               "micrometres low; faster by 7-26 % of the step (docs/frontier/issue32)");
  bool parallax = true;
  app.add_flag("--parallax,!--no-parallax", parallax,
               "stage 5b reads each height where the textured surface p + h*N crosses the line\n"
               "along the window's normal (parallax; on by default) instead of h*(N.n) at the\n"
               "coarse point under it, which on coarse facets tilted from the normal under large\n"
               "heights reads another part of the surface; --no-parallax: the render's form,\n"
               "less accurate on such surfaces and 3-37 % faster there\n"
               "(docs/frontier/issue32/twenty_eighth_stop)");
  bool no_parallax_offset_seeds = false;
  app.add_flag("--no-parallax-offset-seeds", no_parallax_offset_seeds,
               "stage 5b searches only the grid's deepest cells: by default it also searches\n"
               "where parallax carries them (a facet tilted from the window's normal under a\n"
               "large height shows its peak up to several cells beside where the grid's\n"
               "render puts it; docs/frontier/issue32/thirty_third_stop)");
  bool no_neighbour_peak_seeds = false;
  app.add_flag("--no-neighbour-peak-seeds", no_neighbour_peak_seeds,
               "stage 5b does not search half a cell and a cell beside its deepest point for a\n"
               "neighbouring peak: by default it does (beside a trough's vertex the other\n"
               "flank's maximum lies in the next cell, which is never a seed of its own; it costs\n"
               "4-35 % of the texture stage; docs/frontier/issue32/thirty_fourth_stop)");
  double clustering_angle_deg = ht::PipelineOptions{}.clustering_angle_deg;
  app.add_option("--clustering-angle-deg", clustering_angle_deg,
                 "contact clustering: leaf pairs (and clusters) whose normals differ by less than\n"
                 "this merge into one contact (degrees; 30 before issue 32's thirty-third stop)")
      ->check(CLI::Range(1.0, 89.0))
      ->capture_default_str();
  bool no_seed_from_last_step = false;
  app.add_flag("--no-seed-from-last-step", no_seed_from_last_step,
               "each step's contacts from their own grid alone: by default stage 5b also\n"
               "searches each contact from the previous step's deepest point (kept in the\n"
               "tool's frame), so that a narrow peak the filtered grid finds on one step and\n"
               "misses on the next is not lost for that step (docs/frontier/issue32/\n"
               "twenty_fifth_stop)");
  bool kink_hang_other_arm = false;
  app.add_flag(
      "--kink-hang-other-arm", kink_hang_other_arm,
      "where a contact's depth is a V in the tool's tilt (a face resting on ridges), hang\n"
      "the arm it does not bear on below its depth by the two arms' gap instead of through\n"
      "its own sample: the resting block's torque turns over smoothly through level, but\n"
      "the torque error against the truth is a little higher and the striped blocks' loop\n"
      "rougher (docs/frontier/issue32/twenty_sixth_stop)");
  double translation_patch_rtt_ms = ht::RemoteNodeConfig{}.translation_patch_rtt_ms;
  auto* rtt_option =
      app.add_option(
             "--translation-patch-rtt-ms", translation_patch_rtt_ms,
             "each contact model also carries its contacts' depth over in-plane\n"
             "translations of the tool (a 5x5 patch one grid cell apart, 75 bytes a\n"
             "contact) from when the round trip the operator measures (its pings carry\n"
             "it) reaches this many ms until it falls below 0.8 of it: the operator's\n"
             "loop then follows the texture's ridges a round trip away from where the\n"
             "model was made instead of extending the tangent. The remote step costs\n"
             "20-80 % more while they go, nothing below. 10 ms is half a grid cell of hand\n"
             "motion at 20-50 mm/s with the default --window and --grid (0.4 mm cells);\n"
             "0: from the first measured round trip (issue 33; docs/passivity)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 60000.0));
  bool translation_patch = false;
  app.add_flag("--translation-patch", translation_patch,
               "always send the translation patches, whatever the round trip")
      ->excludes(rtt_option);
  bool no_translation_patch = false;
  app.add_flag("--no-translation-patch", no_translation_patch,
               "never send translation patches, whatever the round trip")
      ->excludes("--translation-patch")
      ->excludes(rtt_option);
  bool translation_patch_follows_rotation = false;
  app.add_flag("--translation-patch-follows-rotation", translation_patch_follows_rotation,
               "whenever translation patches go: the loop also reads the patch where a turn of\n"
               "the tool slides the contact (its lever from the tool's centre of mass)")
      ->excludes("--no-translation-patch");
  int translation_patch_spacing_cells = 1;
  app.add_option("--translation-patch-spacing-cells", translation_patch_spacing_cells,
                 "whenever translation patches go: their nodes' spacing in grid cells, so that\n"
                 "a patch spans ±2 spacings (wider for a tool that moves further in a round trip,\n"
                 "coarser on the ridges)")
      ->check(CLI::Range(1, ht::kMaxTranslationPatchSpacing))
      ->capture_default_str();
  double translation_patch_step_texels = 0.0;
  auto* patch_texels_option = app.add_option(
      "--translation-patch-step-texels", translation_patch_step_texels,
      "whenever translation patches go: their nodes' spacing in level-0 texels instead of\n"
      "grid cells (with --texel-scale-gradient --secant-rotation-gradient and 2, the\n"
      "slope's own steps): the loop then holds a V between two ridges' flanks and its\n"
      "curvature (fig75's valleys no longer ring), over +/-2 spacings only, so pair it\n"
      "with --translation-patch on a loopback or LAN (docs/frontier/issue32/\n"
      "thirty_fourth_stop)");
  patch_texels_option->check(CLI::Range(0.0, 64.0))->excludes("--translation-patch-spacing-cells");
  bool texel_scale_gradient = false;
  app.add_flag("--texel-scale-gradient", texel_scale_gradient,
               "each refined contact's gradient as the refined maximum's derivative at\n"
               "--gradient-step-texels instead of the secant over one grid cell: closer to the\n"
               "full-resolution truth pose by pose, but where a face lies between two ridges'\n"
               "flanks it gives one flank's slope and the tool chatters in the closed loop\n"
               "(docs/frontier/issue32/seventh_stop)");
  double gradient_step_texels = ht::DepthRefinementOptions{}.gradient_step_texels;
  app.add_option("--gradient-step-texels", gradient_step_texels,
                 "with --texel-scale-gradient: its translation step, in level-0 texels of the\n"
                 "finer surface at the contact point (the rotation step is this over half the\n"
                 "window)")
      ->check(CLI::Range(0.01, 1000.0))
      ->capture_default_str();
  double secant_at_kinks_um = ht::DepthRefinementOptions{}.secant_at_kinks_m * 1e6;
  app.add_option("--secant-at-kinks-um", secant_at_kinks_um,
                 "with --texel-scale-gradient, per axis: where the samples one grid cell\n"
                 "away lie above the texel-scale tangent by more than this (a kink: another\n"
                 "maximum takes over within the cell), the cell's secant instead; 0 = off")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  bool secant_rotation_gradient = false;
  app.add_flag("--secant-rotation-gradient", secant_rotation_gradient,
               "with --texel-scale-gradient: only its translation part at texel scale, the\n"
               "rotation part the one-cell secant as by default (at texel scale a face resting on\n"
               "ridges rocks between its tilt's arms; issue 32, ninth stop)");
  bool translation_kink_planes = false;
  app.add_flag("--translation-kink-planes", translation_kink_planes,
               "with --texel-scale-gradient: each contact also carries the arms of its\n"
               "depth's V along the window's two in-plane axes (a face between two ridges'\n"
               "flanks), so that the operator's loop finds the vertex between two models\n"
               "instead of being pushed across it by one arm (issue 32, ninth stop)");
  double split_windows_link_mm = 10.0;
  app.add_option(
         "--split-windows-link-mm", split_windows_link_mm,
         "stage 5a: a contact window whose overlap falls into regions farther apart than this\n"
         "(mm) also pushes with each other region's own depth, as contact clustering would\n"
         "group the textured contact (CPU texture stage; docs/frontier/issue32/seventh_stop)")
      ->check(CLI::Range(0.1, 1000.0))
      ->capture_default_str();
  double split_continuous_um = 400.0;
  app.add_option(
         "--split-continuous-um", split_continuous_um,
         "stage 5a's fades (um): the deepest region keeps the whole window, each other region\n"
         "fades in with its overlap and out as it joins a deeper one over this depth (birth\n"
         "ramp and bridge fade); narrower fades are closer to the truth on the frontier but\n"
         "rock the loop (100 um: fig76 25.5 % force error, 256 contact steps on one clock;\n"
         "400 um: 28.6 %, 11; without the split 39.8 %, 6). 0: the seventh stop's plain\n"
         "split (docs/frontier/issue32/thirty_first_stop)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  bool no_split = false;
  app.add_flag("--no-split", no_split,
               "stage 5a off: one window per contact cluster whatever its overlap (the default\n"
               "before issue 32's thirty-first stop; the GPU texture stage always runs without\n"
               "the split)");
  bool no_share_connected_contacts = false;
  app.add_flag("--no-share-connected-contacts", no_share_connected_contacts,
               "every contact pushes with its whole penalty: by default contacts on one object\n"
               "whose textured overlaps come within 10 mm of each other are one contact region\n"
               "and share one penalty (stage 5c), as the pipeline truth links its patches: a\n"
               "large flat contact that the coarse clustering left in two windows pushes once,\n"
               "not twice (docs/frontier/issue32/tenth_stop)");
  double speculative_speed_mm_s = ht::RemoteNodeConfig{}.speculative_speed_m_per_s * 1e3;
  app.add_option("--speculative-speed-mm-s", speculative_speed_mm_s,
                 "speculative contacts by the round trip: the step also models every surface\n"
                 "within this speed times the operator's round trip of the tool (at most\n"
                 "--max-speculative-floor-mm; depth < 0, no force yet) while the tool touches\n"
                 "nothing, so that under delay a hand that lifts and presses again feels the\n"
                 "surface where it is, not a round trip later inside it (0 = off; a loopback's\n"
                 "or a LAN's round trip makes it a few micrometres)")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  double max_speculative_floor_mm = ht::RemoteNodeConfig{}.max_speculative_floor_m * 1e3;
  app.add_option("--max-speculative-floor-mm", max_speculative_floor_mm,
                 "the largest distance --speculative-speed-mm-s models surfaces at (mm)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  double speculative_lead_ms = 50.0;
  app.add_option("--speculative-lead-ms", speculative_lead_ms,
                 "speculative contacts: a separated pair beyond the textures' reach is modelled\n"
                 "(depth < 0, no force yet) when the tool closes it within this time at its\n"
                 "twist, so that the operator's local model has the surface before the tool\n"
                 "reaches it however late the model (0 = off; at most 2 mm ahead)")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  app.add_option("--pd-backend", pd_backend,
                 "where the texture penetration depth runs: cpu (software rasterizer), gpu\n"
                 "(headless EGL, OpenGL ES 3.1; Mesa llvmpipe when there is no GPU), or auto (a\n"
                 "hardware GPU when one starts, else cpu). A GPU that cannot start or fails\n"
                 "mid-run falls back to cpu with a message")
      ->check(CLI::IsMember({"cpu", "gpu", "auto"}))
      ->capture_default_str();
  app.add_option("--depth-bits", config.gpu.depth_bits,
                 "GPU depth buffer precision: 16 (fixed point, as the seed) or 32 (float)")
      ->check(CLI::IsMember({16, 32}))
      ->capture_default_str();
  bool per_render_draws = false;
  app.add_flag("--gpu-per-render-draws", per_render_draws,
               "GPU backend: one draw per render (12 per contact), not one instanced draw per\n"
               "side per batch (the default where the driver has GL_EXT_clip_cull_distance); the\n"
               "same depths within a quantum, for a driver whose instancing misbehaves");
  app.add_option("--max-rate", config.max_rate_hz, "cap on the step rate in Hz (0 = none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--display-rate", config.display_rate_hz,
                 "rate of the moving scene nodes' poses streamed for the operator's display (Hz)")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  double max_deadband_pct = 50.0;
  app.add_option("--max-deadband", max_deadband_pct,
                 "largest perceptual deadband an operator may ask on either stream, percent (a "
                 "Weber fraction); a Hello asking more is refused with a Reject that says so")
      ->check(CLI::Range(0.0, 99.0))
      ->capture_default_str();
  // The contact-model deadband's floors (the Weber fraction k itself is the operator's, agreed
  // in the Hello): each threshold is max(k·|value|, k·floor), ContactModelDeadbandConfig.
  app.add_option("--model-deadband-force-floor", config.model_deadband.force_floor_scale_n,
                 "contact-model deadband: force floor scale, N (the floor is k times it)")
      ->check(CLI::Range(1e-3, 1e3))
      ->capture_default_str();
  app.add_option("--model-deadband-torque-floor", config.model_deadband.torque_floor_scale_nm,
                 "contact-model deadband: torque floor scale, N*m (the floor is k times it)")
      ->check(CLI::Range(1e-5, 1e2))
      ->capture_default_str();
  app.add_option("--model-deadband-stiffness-floor",
                 config.model_deadband.stiffness_floor_scale_n_per_m,
                 "contact-model deadband: floor scale of the stiffness's translational block,\n"
                 "N/m (the floor is k times it)")
      ->check(CLI::Range(1e-3, 1e9))
      ->capture_default_str();
  app.add_option("--model-deadband-rotational-stiffness-floor",
                 config.model_deadband.rotational_stiffness_floor_scale_nm_per_rad,
                 "contact-model deadband: floor scale of the stiffness's rotational block,\n"
                 "N*m/rad (the floor is k times it)")
      ->check(CLI::Range(1e-6, 1e6))
      ->capture_default_str();
  app.add_option("--out", out_dir,
                 "directory for remote_summary.json and remote_steps.csv (one row per step)");
  app.add_option("--port-file", port_file, "write the bound UDP port to this file");
  ht::KeyFileOptions key;
  int mtu = 1472;
  ht::AddKeyOption(app, key);
  app.add_option("--mtu", mtu, "largest UDP datagram for scene-update fragments, bytes")
      ->check(CLI::Range(548, 1472))
      ->capture_default_str();
  app.add_option("--peer-timeout", config.peer_timeout_ms,
                 "declare the operator lost after this long without an authenticated datagram, ms")
      ->check(CLI::Range(50, 60000))
      ->capture_default_str();
  app.add_option("--scene-rate", config.scene_rate_bytes_per_s,
                 "pace of scene-update fragments, bytes per second")
      ->check(CLI::Range(1e4, 1e9))
      ->capture_default_str();
  app.add_flag("--stay", stay, "keep running after the operator says goodbye");
  ht::AddKeygenCommand(app, key);
  std::string inspect_path, inspect_tool, cache_dir = ht::HapticModelCache::DefaultDir();
  bool no_cache = false;
  CLI::App* inspect = app.add_subcommand(
      "inspect",
      "load a scene (a glTF 2.0 .gltf/.glb file, or a scene description .json naming one),\n"
      "build the haptic model of every tool and touchable node (coarse mesh, haptic texture,\n"
      "convex-hull hierarchy) or load it from the cache, and print one JSON object: per object\n"
      "its name, role, full and coarse triangle counts, hull count, texture size, bake error and\n"
      "time per stage. Progress goes to stderr. A bad file gives a one-line error and exit 2");
  inspect->add_option("file", inspect_path, "scene file (.gltf, .glb or .json)")->required();
  inspect->add_option("--tool", inspect_tool,
                      "node (name or #index) that is the tool; default: the description's, else\n"
                      "the built-in probe (a small ridged block)");
  inspect
      ->add_option("--cache-dir", cache_dir,
                   "folder of built models, keyed by content and build parameters\n"
                   "(default: $HT_CACHE_DIR, else $XDG_CACHE_HOME/haptic_teleop, else\n"
                   "~/.cache/haptic_teleop)")
      ->capture_default_str();
  inspect->add_flag("--no-cache", no_cache, "build every model, read and write no cache");
  inspect->add_flag("--quiet", quiet, "no progress lines on stderr");
  std::string seed_out;
  std::vector<std::string> seed_names;
  CLI::App* seed_models = app.add_subcommand(
      "seed-models",
      "generate the seed's six benchmark models (block, gear, hammer, cad_part, file, torus;\n"
      "seed Table 6) procedurally at the seed's full-resolution triangle counts and write each as\n"
      "DIR/NAME.glb with a scene description DIR/NAME.json (coarse target = the seed's coarse\n"
      "count, 1024x1024 texture); then 'slave_sim inspect DIR/NAME.json' builds it");
  seed_models->add_option("--out", seed_out, "folder to write into (created)")->required();
  seed_models->add_option("--model", seed_names, "only these models (repeatable)");
  seed_models->add_flag("--quiet", quiet, "no progress lines");
  app.add_flag("--quiet", quiet,
               "no progress or start-up lines (errors, warnings, session events and the last "
               "line stay)");
  if (const auto rc = ht::ParseCommandLine(app, argc, argv, "slave_sim")) return *rc;
  if (max_window_option->count() == 0) {
    config.pipeline.max_window_extent_m =
        ht::kDefaultMaxWindowPerWindow * config.pipeline.window_extent_m;
  }
  config.max_deadband = max_deadband_pct / 100.0;
  config.gpu.instanced_draws = !per_render_draws;

  if (*seed_models) {
    try {
      for (const std::string& n : seed_names) ht::ParseSeedModelName(n);  // a typo is an error
      std::filesystem::create_directories(seed_out);
      for (const ht::SeedModelSpec& spec : ht::SeedModelSpecs()) {
        if (!seed_names.empty() &&
            std::find(seed_names.begin(), seed_names.end(), spec.name) == seed_names.end()) {
          continue;
        }
        ht::TriangleMesh mesh = ht::MakeSeedModelFullResolution(spec.model);
        const std::string glb = seed_out + "/" + spec.name + ".glb";
        const std::size_t triangles = mesh.triangles.size();
        ht::WriteGlb(glb, {{spec.name, std::move(mesh), glm::dmat4(1.0), ""}});
        nlohmann::json desc = {{"scene", std::string(spec.name) + ".glb"},
                               {"defaults",
                                {{"role", "touchable"},
                                 {"coarse_triangles", spec.seed_coarse_triangles},
                                 {"texture_size", 1024}}}};
        const std::string json_path = seed_out + "/" + spec.name + ".json";
        std::ofstream json_file(json_path);
        json_file << desc.dump(2) << "\n";
        if (!json_file.flush()) throw std::runtime_error("cannot write " + json_path);
        if (!quiet) {
          std::printf("seed-models: %s: %zu triangles (seed %lld) -> %s\n", spec.name, triangles,
                      static_cast<long long>(spec.seed_full_triangles), glb.c_str());
        }
      }
      return 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "slave_sim seed-models: error: %s\n", e.what());
      return 2;
    }
  }

  if (*inspect) {
    try {
      const ht::SceneDescription description = ht::LoadSceneInput(inspect_path, inspect_tool);
      const ht::HapticModelCache cache(no_cache ? std::string() : cache_dir);
      const ht::BuiltScene built =
          ht::BuildScene(description, cache, [&](const std::string& node, int index, int count) {
            if (!quiet) {
              std::fprintf(stderr, "[inspect] model %d/%d: node '%s'\n", index, count,
                           node.c_str());
            }
          });
      for (const std::string& w : built.warnings) {
        std::fprintf(stderr, "[inspect] warning: %s\n", w.c_str());
      }
      nlohmann::json out = ht::InspectJson(built);
      struct rusage usage {};
      getrusage(RUSAGE_SELF, &usage);
      out["peak_rss_mb"] = static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is KiB
      out["cache_dir"] = cache.dir();
      std::printf("%s\n", out.dump(2).c_str());
      return 0;
    } catch (const std::exception& e) {
      std::string line = e.what();
      for (char& c : line) {
        if (c == '\n' || c == '\r') c = ' ';
      }
      std::fprintf(stderr, "slave_sim inspect: error: %s\n", line.c_str());
      return 2;
    }
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    if (ht::RunKeygenIfAsked(key, "slave_sim")) return 0;
    config.key = ht::LoadKeyOption(key, "slave_sim keygen FILE");
    config.mtu = static_cast<std::size_t>(mtu);
    config.listen_address = ht::SocketAddress::Parse(listen);
    config.pd_backend = ht::ParsePdBackendChoice(pd_backend);
    config.pipeline.rotation_gradient = ht::ParseRotationGradient(rotation_gradient);
    config.pipeline.grazing_guard = !no_grazing_guard;
    config.pipeline.kink_planes = !no_kink_planes;
    config.pipeline.refine_depth = !no_refine_depth;
    config.pipeline.depth_refinement.texel_scale_gradient = texel_scale_gradient;
    config.pipeline.depth_refinement.parallax = parallax;
    config.pipeline.depth_refinement.seed_from_last_step = !no_seed_from_last_step;
    config.pipeline.depth_refinement.parallax_offset_seeds = !no_parallax_offset_seeds;
    config.pipeline.depth_refinement.neighbour_peak_seeds = !no_neighbour_peak_seeds;
    config.pipeline.clustering_angle_deg = clustering_angle_deg;
    config.pipeline.kink_hang_other_arm = kink_hang_other_arm;
    config.pipeline.depth_refinement.translation_patch = translation_patch;
    config.pipeline.depth_refinement.translation_patch_follows_rotation =
        translation_patch_follows_rotation;
    config.pipeline.depth_refinement.translation_patch_spacing_cells =
        translation_patch_spacing_cells;
    config.pipeline.depth_refinement.translation_patch_step_texels = translation_patch_step_texels;
    if (translation_patch_step_texels > 0.0 && no_translation_patch) {
      throw std::invalid_argument(
          "--translation-patch-step-texels sets the patches' spacing, and --no-translation-patch "
          "sends none: drop one");
    }
    config.translation_patch_rtt_ms =
        no_translation_patch ? std::numeric_limits<double>::infinity() : translation_patch_rtt_ms;
    if ((translation_patch || rtt_option->count() > 0) && no_refine_depth) {
      throw std::invalid_argument(
          std::string(translation_patch ? "--translation-patch" : "--translation-patch-rtt-ms") +
          " needs stage 5b (drop --no-refine-depth): the patch's nodes are refined maxima");
    }
    config.pipeline.depth_refinement.gradient_step_texels = gradient_step_texels;
    config.pipeline.depth_refinement.secant_at_kinks_m = secant_at_kinks_um * 1e-6;
    config.pipeline.depth_refinement.translation_kink_planes = translation_kink_planes;
    config.pipeline.depth_refinement.texel_scale_rotation = !secant_rotation_gradient;
    if (secant_rotation_gradient && !texel_scale_gradient) {
      throw std::invalid_argument(
          "--secant-rotation-gradient needs --texel-scale-gradient (without it the whole "
          "gradient is the secant already)");
    }
    if (translation_kink_planes && !texel_scale_gradient) {
      throw std::invalid_argument(
          "--translation-kink-planes needs --texel-scale-gradient (the arms are the texel-scale "
          "slopes on either side of the vertex)");
    }
    config.pipeline.share_connected_contacts = !no_share_connected_contacts;
    config.pipeline.split_windows_at_separated_overlap = !no_split;
    config.pipeline.split_link_m = split_windows_link_mm * 1e-3;
    const bool continuous = split_continuous_um > 0.0;
    config.pipeline.split_birth_ramp_m = split_continuous_um * 1e-6;
    config.pipeline.split_bridge_fade_m = split_continuous_um * 1e-6;
    config.pipeline.split_keeps_parent_rotation_step = continuous;
    config.pipeline.split_keeps_parent_window = continuous;
    const bool split_asked =
        app.count("--split-windows-link-mm") > 0 || app.count("--split-continuous-um") > 0;
    if (no_split && split_asked) {
      throw std::invalid_argument(
          "--no-split turns stage 5a off; drop it or --split-windows-link-mm / "
          "--split-continuous-um");
    }
    config.pipeline.speculative_lead_s = speculative_lead_ms * 1e-3;
    config.speculative_speed_m_per_s = speculative_speed_mm_s * 1e-3;
    config.max_speculative_floor_m = max_speculative_floor_mm * 1e-3;
    if (config.pipeline.rotation_gradient != ht::RotationGradient::kRenderedSamples) {
      if (config.pd_backend == ht::PdBackendChoice::kGpu) {
        throw std::invalid_argument("--rotation-gradient " + rotation_gradient +
                                    " is an option of the CPU texture stage; the GPU backend "
                                    "renders the rotated samples (use --pd-backend cpu, or drop "
                                    "the option)");
      }
      if (config.pd_backend == ht::PdBackendChoice::kAuto) {
        std::fprintf(stderr, "slave_sim: --rotation-gradient %s: using the CPU texture stage\n",
                     rotation_gradient.c_str());
        config.pd_backend = ht::PdBackendChoice::kCpu;
      }
    }
    if (config.pipeline.split_windows_at_separated_overlap &&
        config.pd_backend == ht::PdBackendChoice::kGpu) {
      if (split_asked) {
        throw std::invalid_argument(
            "--split-windows-link-mm and --split-continuous-um are options of the CPU texture "
            "stage; the GPU backend takes one window size per batch (use --pd-backend cpu, or "
            "drop the option)");
      }
      std::fprintf(stderr,
                   "slave_sim: stage 5a's split is a CPU texture stage option: off with "
                   "--pd-backend gpu\n");
      config.pipeline.split_windows_at_separated_overlap = false;
    }
    config.port_file = port_file;
    config.exit_on_goodbye = !stay;
    config.progress_period_s = quiet ? 0.0 : 1.0;
    ht::HapticScene builtin_scene;
    std::unique_ptr<ht::WatchedScene> file_scene;
    const bool watch = !no_watch;
    if (!out_dir.empty()) {
      std::filesystem::create_directories(out_dir);
      config.step_trace_path = out_dir + "/remote_steps.csv";
    }
    const std::string benchmark_name = ht::BenchmarkSceneOfBuiltin(scene);
    if (scene == "block-on-gear" || scene == "stiff-wall") {
      builtin_scene = scene == "stiff-wall" ? ht::MakeStiffWallScene() : ht::MakeBlockOnGearScene();
      config.scene_objects = ht::BlockOnGearDisplayStream(builtin_scene).objects;
    } else if (!benchmark_name.empty()) {
      if (!quiet)
        std::printf("[slave] building scene %s (model cache: %s)\n", scene.c_str(),
                    scene_cache_dir.empty() ? "none" : scene_cache_dir.c_str());
      const ht::BenchmarkScene bench =
          ht::MakeBenchmarkScene(benchmark_name, ht::ProductModelSettings(benchmark_name),
                                 ht::HapticModelCache(scene_cache_dir));
      builtin_scene = bench.haptic;
      builtin_scene.name = scene;
      // The full-resolution meshes in their own frames, with the scene graph, for display.
      config.scene_objects = ht::MakeDisplayStream(builtin_scene, *bench.tool_mesh_Ft, bench.X_TFt,
                                                   {bench.object_mesh_Fe.get()})
                                 .objects;
      const ht::RigidTransform& home = bench.haptic.X_WT_home;
      if (!quiet) {
        std::printf("[slave] scene %s: tool %s on %s; tool home position in W %.4f,%.4f,%.4f\n",
                    scene.c_str(), bench.tool_name.c_str(), bench.object_name.c_str(),
                    home.translation.x, home.translation.y, home.translation.z);
      }
    } else {
      if (!std::filesystem::exists(scene)) {
        throw std::invalid_argument("--scene " + scene +
                                    ": neither a built-in scene (block-on-gear, stiff-wall, "
                                    "striped-blocks, file-on-cad-part, hammer-on-torus) nor an "
                                    "existing file");
      }
      file_scene = std::make_unique<ht::WatchedScene>(
          scene, scene_tool, ht::HapticModelCache(scene_cache_dir),
          [&](const std::string& node, int index, int count) {
            if (!quiet) {
              std::printf("[slave] model %d/%d: node '%s'\n", index, count, node.c_str());
            }
          });
      // The scene as a scene for display: its graph, each mesh once in its own frame, the
      // base-colour images; the moving nodes' poses follow at the display rate.
      config.scene_objects = file_scene->stream().objects;
      if (config.scene_objects.size() > 65535) {
        throw std::invalid_argument("--scene " + scene + ": " +
                                    std::to_string(config.scene_objects.size()) +
                                    " display objects (meshes and images); at most 65535 stream");
      }
      config.display_poses = [&](double t_s, std::vector<ht::wire::NodePose>* poses) {
        file_scene->DisplayPoses(t_s, poses);
      };
      config.animate = [&](double t_s) { file_scene->Animate(t_s); };
      if (watch) {
        // A change of the file on disk rebuilds the scene (through the cache) and switches to it.
        file_scene->StartWatching(0.5);
        config.take_reload = [&](std::vector<ht::StreamObject>* objects) -> const ht::HapticScene* {
          if (!file_scene->TakeReload()) return nullptr;
          *objects = file_scene->stream().objects;
          return &file_scene->haptic();
        };
      }
      const ht::BuiltScene& built = file_scene->built();
      for (const std::string& w : built.warnings) {
        std::fprintf(stderr, "[slave] warning: %s\n", w.c_str());
      }
      const ht::RigidTransform& home = built.haptic.X_WT_home;
      if (!quiet) {
        std::printf(
            "[slave] scene file %s: %zu touchable(s), tool %s; tool home position in W %.4f,%.4f,"
            "%.4f (the operator's workspace centre: sent in the Welcome)%s\n",
            scene.c_str(), built.haptic.touchables.size(),
            built.builtin_probe ? "built-in probe" : scene_tool.c_str(), home.translation.x,
            home.translation.y, home.translation.z, watch ? "; watching the file for changes" : "");
      }
    }
    const ht::HapticScene& haptic_scene = file_scene ? file_scene->haptic() : builtin_scene;
    nlohmann::json summary = ht::RunRemoteNode(config, haptic_scene, g_stop);
    if (file_scene) summary["scene_file"] = file_scene->StatsJson();
    std::printf("[slave] done: %llu steps, %.1f steps/s, step p50 %.0f us\n",
                static_cast<unsigned long long>(summary["steps"].get<std::uint64_t>()),
                summary["rate_hz"].get<double>(), summary["step_p50_us"].get<double>());
    if (!out_dir.empty()) {
      std::filesystem::create_directories(out_dir);
      std::ofstream f(out_dir + "/remote_summary.json");
      f << summary.dump(2) << "\n";
      if (!f) throw std::runtime_error("cannot write " + out_dir + "/remote_summary.json");
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "slave_sim: error: %s\n", e.what());
    return 2;
  }
}
