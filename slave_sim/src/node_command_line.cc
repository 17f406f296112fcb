// slave_sim's command line (node_command_line.h): the options by group, in --help's order, and
// what they make of the node's configuration. Each Add* function puts what a user needs in `app`
// (listed by --help) and research comparisons and tuning in `adv`, the Advanced option group
// (listed by --help-all; the same names and --config keys).

#include "node_command_line.h"

#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

namespace ht {
namespace {

// The address, the scene and its model cache.
void AddSceneOptions(CLI::App& app, NodeCommandLine& cl) {
  app.add_option("--listen", cl.listen, "UDP address HOST:PORT to listen on (port 0 = any free)")
      ->capture_default_str();
  app.add_option("--scene", cl.scene,
                 "built-in scene: block-on-gear (seed Fig. 75), stiff-wall (the same block on a\n"
                 "flat wall five times stiffer, a stability hard case), striped-blocks (two\n"
                 "interlocked striped blocks, seed Fig. 76), file-on-cad-part (seed Fig. 77) or\n"
                 "hammer-on-torus (seed Fig. 73; these two build the seed models through the\n"
                 "cache, about a minute each when cold); or a scene file (.gltf,\n"
                 ".glb, or a scene description .json), built through the model cache (see\n"
                 "'slave_sim inspect'); its glTF animation 0, if any, plays in a loop")
      ->capture_default_str();
  app.add_option("--tool", cl.scene_tool,
                 "with a scene file: the node (name or #index) that is the tool; default the\n"
                 "description's, else the built-in probe");
  app.add_flag("--no-watch", cl.no_watch,
               "with a scene file: do not watch it (by default a change of the file on disk\n"
               "rebuilds the scene through the cache, switches the pipeline to it between two\n"
               "steps and streams the changed meshes to the operator)");
  app.add_option("--cache-dir", cl.scene_cache_dir,
                 "with a scene file or a seed-model scene: the model cache folder")
      ->capture_default_str();
}

// The contact windows' grid and sizes, and the texture stage's threads.
void AddWindowOptions(CLI::App& app, CLI::App& adv, NodeCommandLine& cl) {
  app.add_option("--grid", cl.config.pipeline.grid_resolution,
                 "penetration-depth grid N (N x N cells per contact)")
      ->check(CLI::Range(2, 1024))
      ->capture_default_str();
  app.add_option("--window", cl.config.pipeline.window_extent_m,
                 "smallest contact window side W in metres (with the grid N: the cell W/N)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  adv.add_option("--max-window", cl.config.pipeline.max_window_extent_m,
                 "largest contact window side in metres: a cluster spread wider than W gets a\n"
                 "window sized to it at the same cell (N grows with it); overlapping windows\n"
                 "with agreeing normals merge while they fit. Default 3 x --window; equal to\n"
                 "--window: every window W x W")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cl.config.pipeline.texture_threads = DefaultTextureThreads();
  app.add_option("--texture-threads", cl.config.pipeline.texture_threads,
                 "threads of the CPU texture stage (a step's contacts spread over them); the\n"
                 "default leaves one core to the operator on a loopback machine")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
}

// Stage 5b's depth refinement and the force law.
void AddDepthOptions(CLI::App& app, CLI::App& adv, NodeCommandLine& cl) {
  app.add_option("--force-law", cl.force_law,
                 "the law the depth fields render: seed (the directional penetration depth's\n"
                 "penalty, F = -k d grad d: the deepest point bears; the seed's experiments) or\n"
                 "pressure (a pressure k_p d on every overlapping cell, the wrench of\n"
                 "U = 1/2 k_p sum d^2 A: every cell in contact bears, so that a face resting on\n"
                 "many ridges gets their moment). Sent with every field; contacts without a\n"
                 "field keep the seed's law")
      ->check(CLI::IsMember({"seed", "pressure"}))
      ->capture_default_str();
  adv.add_option("--pressure-stiffness", cl.pressure_stiffness,
                 "the pressure law's k_p in N/m^3 (0: each object's stiffness k over the tool's\n"
                 "contact area, the largest face of its bounding box, so that a flat face of\n"
                 "that area pressed into a flat plate feels k under either law)")
      ->check(CLI::Range(0.0, 1e15))
      ->capture_default_str();
  adv.add_flag("--no-refine-depth", cl.no_refine_depth,
               "the grid's cell samples alone: by default each contact's depth is refined to the\n"
               "texture's full resolution around the grid's deepest cells (stage 5b,\n"
               "docs/DESIGN.md §4), which the grid's mip-filtered samples read tens of\n"
               "micrometres low; off is 7-26 % faster a step (docs/measurements.md). Only for an\n"
               "operator without depth fields (master_station --no-depth-fields): with them each\n"
               "contact's depth is its field's");
}

// Speculative contacts.
void AddSpeculativeOptions(CLI::App& adv, NodeCommandLine& cl) {
  adv.add_option("--speculative-speed-mm-s", cl.speculative_speed_mm_s,
                 "speculative contacts by the round trip: the step also models every surface\n"
                 "within this speed times the operator's round trip of the tool (at most\n"
                 "--max-speculative-floor-mm; depth < 0, no force yet) while the tool touches\n"
                 "nothing, so that under delay a hand that lifts and presses again feels the\n"
                 "surface where it is, not a round trip later inside it (0 = off; a loopback's\n"
                 "or a LAN's round trip makes it a few micrometres)")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  adv.add_option("--max-speculative-floor-mm", cl.max_speculative_floor_mm,
                 "the largest distance --speculative-speed-mm-s models surfaces at (mm)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  adv.add_option("--speculative-lead-ms", cl.speculative_lead_ms,
                 "speculative contacts: a separated pair beyond the textures' reach is modelled\n"
                 "(depth < 0, no force yet) when the tool closes it within this time at its\n"
                 "twist, so that the operator's local model has the surface before the tool\n"
                 "reaches it however late the model (0 = off; at most 2 mm ahead)")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
}

// Where the texture penetration depth runs.
void AddBackendOptions(CLI::App& app, CLI::App& adv, NodeCommandLine& cl) {
  app.add_option("--pd-backend", cl.pd_backend,
                 "where the texture penetration depth runs: cpu (software rasterizer), gpu\n"
                 "(headless EGL, OpenGL ES 3.1; Mesa llvmpipe when there is no GPU), or auto (a\n"
                 "hardware GPU when one starts, else cpu). A GPU that cannot start or fails\n"
                 "mid-run falls back to cpu with a message")
      ->check(CLI::IsMember({"cpu", "gpu", "auto"}))
      ->capture_default_str();
  adv.add_option("--depth-bits", cl.config.gpu.depth_bits,
                 "GPU depth buffer precision: 16 (fixed point, as the seed) or 32 (float)")
      ->check(CLI::IsMember({16, 32}))
      ->capture_default_str();
  adv.add_flag("--gpu-per-render-draws", cl.per_render_draws,
               "GPU backend: one draw per render (12 per contact), not one instanced draw per\n"
               "side per batch (the default where the driver has GL_EXT_clip_cull_distance); the\n"
               "same depths within a quantum, for a driver whose instancing misbehaves");
}

// Rates, deadbands, files, the key and the UDP stream.
void AddStreamOptions(CLI::App& app, CLI::App& adv, NodeCommandLine& cl) {
  adv.add_option("--max-rate", cl.config.max_rate_hz, "cap on the step rate in Hz (0 = none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  adv.add_option("--display-rate", cl.config.display_rate_hz,
                 "rate of the moving scene nodes' poses streamed for the operator's display (Hz)")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  app.add_option("--max-deadband", cl.max_deadband_pct,
                 "largest perceptual deadband an operator may ask on either stream, percent (a "
                 "Weber fraction); a Hello asking more is refused with a Reject that says so")
      ->check(CLI::Range(0.0, 99.0))
      ->capture_default_str();
  // The contact-model deadband's floors (the Weber fraction k itself is the operator's, agreed
  // in the Hello): each threshold is max(k·|value|, k·floor), ContactModelDeadbandConfig.
  adv.add_option("--model-deadband-force-floor", cl.config.model_deadband.force_floor_scale_n,
                 "contact-model deadband: force floor scale, N (the floor is k times it)")
      ->check(CLI::Range(1e-3, 1e3))
      ->capture_default_str();
  adv.add_option("--model-deadband-torque-floor", cl.config.model_deadband.torque_floor_scale_nm,
                 "contact-model deadband: torque floor scale, N*m (the floor is k times it)")
      ->check(CLI::Range(1e-5, 1e2))
      ->capture_default_str();
  adv.add_option("--model-deadband-stiffness-floor",
                 cl.config.model_deadband.stiffness_floor_scale_n_per_m,
                 "contact-model deadband: floor scale of the stiffness's translational block,\n"
                 "N/m (the floor is k times it)")
      ->check(CLI::Range(1e-3, 1e9))
      ->capture_default_str();
  adv.add_option("--model-deadband-rotational-stiffness-floor",
                 cl.config.model_deadband.rotational_stiffness_floor_scale_nm_per_rad,
                 "contact-model deadband: floor scale of the stiffness's rotational block,\n"
                 "N*m/rad (the floor is k times it)")
      ->check(CLI::Range(1e-6, 1e6))
      ->capture_default_str();
  app.add_option("--out", cl.out_dir,
                 "directory for remote_summary.json and remote_steps.csv (one row per step)");
  app.add_option("--port-file", cl.port_file, "write the bound UDP port to this file");
  AddKeyOption(app, cl.key);
  adv.add_option("--mtu", cl.mtu, "largest UDP datagram for scene-update fragments, bytes")
      ->check(CLI::Range(548, 1472))
      ->capture_default_str();
  adv.add_option("--peer-timeout", cl.config.peer_timeout_ms,
                 "declare the operator lost after this long without an authenticated datagram, ms")
      ->check(CLI::Range(50, 60000))
      ->capture_default_str();
  adv.add_option("--scene-rate", cl.config.scene_rate_bytes_per_s,
                 "pace of scene-update fragments, bytes per second")
      ->check(CLI::Range(1e4, 1e9))
      ->capture_default_str();
  app.add_flag("--stay", cl.stay, "keep running after the operator says goodbye");
  AddKeygenCommand(app, cl.key);
}

// 'inspect' and 'seed-models'.
void AddSubcommands(CLI::App& app, NodeCommandLine& cl) {
  cl.inspect = app.add_subcommand(
      "inspect",
      "load a scene (a glTF 2.0 .gltf/.glb file, or a scene description .json naming one),\n"
      "build the haptic model of every tool and touchable node (coarse mesh, haptic texture,\n"
      "convex-hull hierarchy) or load it from the cache, and print one JSON object: per object\n"
      "its name, role, full and coarse triangle counts, hull count, texture size, bake error and\n"
      "time per stage. Progress goes to stderr. A bad file gives a one-line error and exit 2");
  cl.inspect->add_option("file", cl.inspect_path, "scene file (.gltf, .glb or .json)")->required();
  cl.inspect->add_option(
      "--tool", cl.inspect_tool,
      "node (name or #index) that is the tool; default: the description's, else\n"
      "the built-in probe (a small ridged block)");
  cl.inspect
      ->add_option("--cache-dir", cl.cache_dir,
                   "folder of built models, keyed by content and build parameters\n"
                   "(default: $HT_CACHE_DIR, else $XDG_CACHE_HOME/haptic_teleop, else\n"
                   "~/.cache/haptic_teleop)")
      ->capture_default_str();
  cl.inspect->add_flag("--no-cache", cl.no_cache, "build every model, read and write no cache");
  cl.inspect->add_flag("--quiet", cl.quiet, "no progress lines on stderr");
  cl.seed_models = app.add_subcommand(
      "seed-models",
      "generate the seed's six benchmark models (block, gear, hammer, cad_part, file, torus;\n"
      "seed Table 6) procedurally at the seed's full-resolution triangle counts and write each as\n"
      "DIR/NAME.glb with a scene description DIR/NAME.json (coarse target = the seed's coarse\n"
      "count, 1024x1024 texture); then 'slave_sim inspect DIR/NAME.json' builds it");
  cl.seed_models->add_option("--out", cl.seed_out, "folder to write into (created)")->required();
  cl.seed_models->add_option("--model", cl.seed_names, "only these models (repeatable)");
  cl.seed_models->add_flag("--quiet", cl.quiet, "no progress lines");
}

// The key, the address and the stream's own settings.
void FinishStreamConfig(const CLI::App& app, const NodeCommandLine& cl, RemoteNodeConfig& config) {
  config.key = LoadKeyOption(cl.key, "slave_sim keygen FILE");
  config.mtu = static_cast<std::size_t>(cl.mtu);
  config.listen_address = SocketAddress::Parse(cl.listen);
  config.pd_backend = ParsePdBackendChoice(cl.pd_backend);
  if (app.count("--max-window") == 0) {
    config.pipeline.max_window_extent_m =
        kDefaultMaxWindowPerWindow * config.pipeline.window_extent_m;
  }
  config.max_deadband = cl.max_deadband_pct / 100.0;
  config.gpu.instanced_draws = !cl.per_render_draws;
  config.port_file = cl.port_file;
  config.exit_on_goodbye = !cl.stay;
  config.progress_period_s = cl.quiet ? 0.0 : 1.0;
  if (!cl.out_dir.empty()) config.step_trace_path = cl.out_dir + "/remote_steps.csv";
}

// Stage 5b.
void FinishDepthConfig(const NodeCommandLine& cl, RemoteNodeConfig& config) {
  PipelineOptions& pipeline = config.pipeline;
  pipeline.refine_depth = !cl.no_refine_depth;
  pipeline.force_law = cl.force_law == "pressure" ? ForceLaw::kPressure : ForceLaw::kSeed;
  pipeline.pressure_stiffness_n_per_m3 = cl.pressure_stiffness;
}

// Speculative contacts.
void FinishSpeculativeConfig(const NodeCommandLine& cl, RemoteNodeConfig& config) {
  config.pipeline.speculative_lead_s = cl.speculative_lead_ms * 1e-3;
  config.speculative_speed_m_per_s = cl.speculative_speed_mm_s * 1e-3;
  config.max_speculative_floor_m = cl.max_speculative_floor_mm * 1e-3;
}

}  // namespace

void AddNodeOptions(CLI::App& app, NodeCommandLine& cl) {
  UseTwoLevelHelp(app);
  app.set_config("--config", "",
                 "read options from a TOML file (key = value, long option names without dashes,\n"
                 "the advanced ones too); command-line options override it");
  CLI::App& adv = *app.add_option_group(
      "Advanced",
      "the remote step's stages switched off for comparison and their tuning, the contact-model\n"
      "deadband's floors, the GPU backend, the stream and the network; each default's reason\n"
      "and figure: docs/DESIGN.md, docs/measurements.md");
  AddSceneOptions(app, cl);
  AddWindowOptions(app, adv, cl);
  AddDepthOptions(app, adv, cl);
  AddSpeculativeOptions(adv, cl);
  AddBackendOptions(app, adv, cl);
  AddStreamOptions(app, adv, cl);
  AddSubcommands(app, cl);
  app.add_flag("--quiet", cl.quiet,
               "no progress or start-up lines (errors, warnings, session events and the last "
               "line stay)");
}

void FinishNodeConfig(const CLI::App& app, NodeCommandLine& cl) {
  RemoteNodeConfig& config = cl.config;
  FinishStreamConfig(app, cl, config);
  FinishDepthConfig(cl, config);
  FinishSpeculativeConfig(cl, config);
}

}  // namespace ht
