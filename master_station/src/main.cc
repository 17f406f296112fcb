// master_station: the operator side. Runs the 1 kHz haptic loop on a (simulated) device against
// the contact models streamed by slave_sim, and writes trace.csv and summary.json.

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <exception>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <sstream>

#include "haptic_core/demo/demo_scenes.h"
#include "master_station/experiment.h"
#include "master_station/falcon.h"
#include "master_station/force_dimension.h"
#include "master_station/openhaptics.h"
#include "master_station/operator_station.h"
#include "master_station/replay_device.h"
#include "master_station/simulated_operator.h"
#include "master_station/spacemouse.h"
#include "transport/command_line.h"

namespace {

// The default perceptual deadband on both streams (percent): the largest of the measured table
// (docs/deadband.md) whose RMS force error stays within 5 %.
constexpr double kDefaultDeadbandPercent = 10.0;

// Set by SIGINT / SIGTERM: the loop ramps the force to zero and the run ends normally.
std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

glm::dvec3 ParseVector(const std::string& text) {
  std::stringstream ss(text);
  glm::dvec3 v;
  char c1 = 0, c2 = 0;
  if (!(ss >> v.x >> c1 >> v.y >> c2 >> v.z) || c1 != ',' || c2 != ',' || !ss.eof()) {
    throw std::invalid_argument("'" + text + "' must be three numbers X,Y,Z");
  }
  return v;
}

int MergeSummary(const std::string& summary_path, const std::string& remote_path,
                 const std::string& relay_path) {
  std::ifstream in(summary_path), rin(remote_path);
  if (!in) throw std::runtime_error("cannot read " + summary_path);
  if (!rin) throw std::runtime_error("cannot read " + remote_path);
  nlohmann::json s = nlohmann::json::parse(in), r = nlohmann::json::parse(rin);
  s["remote"] = r;
  if (r.contains("pd_backend")) {  // which penetration-depth backend ran, and on what renderer
    s["pd_backend"] = r["pd_backend"]["used"];
    s["gl_renderer"] = r["pd_backend"]["gl_renderer"];
  }
  // Per stream, what the other side counted, next to what this side counted.
  if (r.contains("transport") && s.contains("transport")) {
    for (auto& [name, stream] : r["transport"]["streams"].items()) {
      s["transport"]["streams"][name]["remote"] = stream;
    }
    s["transport"]["remote_rejected_total"] = r["transport"]["rejected_total"];
    s["transport"]["remote_rejected_by_reason"] = r["transport"]["rejected_by_reason"];
  }
  if (!relay_path.empty()) {  // what the impairment relay did, for comparison with the streams
    std::ifstream lin(relay_path);
    if (!lin) throw std::runtime_error("cannot read " + relay_path);
    s["relay"] = nlohmann::json::parse(lin);
  }
  std::ofstream out(summary_path);
  out << s.dump(2) << "\n";
  return out ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "master_station: operator side of the networked 6-DoF haptic texture rendering system.\n"
      "Runs the haptic loop (virtual coupling + implicit Euler on the local contact model) with a\n"
      "simulated operator hand that follows an experiment script, exchanging tool states and\n"
      "contact models with slave_sim over UDP. Every datagram is authenticated with the\n"
      "pre-shared key (--key) that slave_sim uses."};
  ht::UseTwoLevelHelp(app);
  app.set_config("--config", "",
                 "read options from a TOML file (key = value, long option names without dashes,\n"
                 "the advanced ones too); command-line options override it");
  // What a user needs is the app's own (--help); research comparisons and tuning are Advanced
  // (--help-all), with the same names, defaults and --config keys.
  CLI::App& adv = *app.add_option_group(
      "Advanced",
      "the loop rate, the display's camera, the network's and the stream's settings, the\n"
      "passivity stage and the energy-bounded switch, the deadband's per-stream settings and\n"
      "floors, the encodings, and the depth fields switched off for comparison; each default's\n"
      "reason and figure: docs/DESIGN.md, docs/deadband.md, docs/measurements.md");
  std::string remote = "127.0.0.1:47000", bind = "127.0.0.1:0", experiment_name = "fig75";
  std::string out_dir, origin_text;
  double duration_s = 5.0, rate_hz = 1000.0, connect_timeout_s = 10.0;
  bool quiet = false;
  app.add_option("--remote", remote, "slave_sim address HOST:PORT")->capture_default_str();
  app.add_option("--bind", bind, "local UDP address HOST:PORT (port 0 = any)")
      ->capture_default_str();
  app.add_option("--experiment", experiment_name,
                 "scripted operator motion: fig75 (the seed's Fig. 75 on the built-in scene:\n"
                 "press, slide along x, along y, lift and press), fig76 (striped-blocks: press,\n"
                 "then rotate back and forth about the scene's up; run it for 12 s), fig77\n"
                 "(file-on-cad-part or hammer-on-torus: press, then scrape 6 cm along x with sway\n"
                 "and yaw; 10 s), or explore (any scene: visit\n"
                 "the touchable objects the remote node lists, press on each under force control,\n"
                 "slide, release, move on)")
      ->capture_default_str();
  app.add_option("--duration", duration_s,
                 "experiment duration in seconds (default 5; with a real --device the session\n"
                 "lasts until Ctrl-C or SIGTERM unless this is given)")
      ->check(CLI::Range(0.1, 1e6))
      ->capture_default_str();
  double trace_max_mb = 0.0;
  app.add_option("--trace-max-mb", trace_max_mb,
                 "largest trace.csv in MiB (0 = no cap); rows past it are counted, not written")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  adv.add_option("--rate", rate_hz, "haptic loop rate in Hz (100..4000)")
      ->check(CLI::Range(100.0, 4000.0))
      ->capture_default_str();
  app.add_option("--out", out_dir, "directory for trace.csv and summary.json");
  std::string display_mode = "none", frames_dir;
  double frame_rate_hz = 10.0;
  int max_frames = 0;
  std::string frame_size = "640x480";
  app.add_option("--display", display_mode,
                 "show the remote scene as received: none, headless (PNG frames through a\n"
                 "headless EGL context; llvmpipe without a GPU) or window (needs a display server)")
      ->check(CLI::IsMember({"none", "headless", "window"}))
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->capture_default_str();
  app.add_option("--frames-dir", frames_dir,
                 "folder for --display headless frames (default: <--out>/frames)");
  app.add_option("--frame-rate", frame_rate_hz, "display frames per second (0.1..120)")
      ->check(CLI::Range(0.1, 120.0))
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->capture_default_str();
  app.add_option("--frame-size", frame_size, "display image size, WIDTHxHEIGHT pixels")
      ->capture_default_str();
  double camera_distance_m = 0.0;
  std::string display_camera = "follow";
  adv.add_option("--display-camera", display_camera,
                 "the display's camera: follow (behind and above the tool, which stays in view) "
                 "or file (the scene file's own camera, where it has one)")
      ->check(CLI::IsMember({"follow", "file"}))
      ->capture_default_str();
  bool no_frame_overlay = false;
  adv.add_flag("--no-frame-overlay", no_frame_overlay,
               "do not print the run time, the phase and the contact force |F| in the display's "
               "frames");
  adv.add_option("--camera-distance", camera_distance_m,
                 "distance of the display's camera behind and above the tool, m (0 = five times "
                 "the tool's radius)")
      ->check(CLI::Range(0.0, 1e4))
      ->capture_default_str();
  adv.add_option("--max-frames", max_frames, "stop the display after this many frames (0 = none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option(
      "--workspace-origin", origin_text,
      "X,Y,Z (m): where the device workspace centre lands in the remote world\n"
      "(default: the tool's home position the remote node gives when the session opens)");
  adv.add_option("--connect-timeout", connect_timeout_s,
                 "seconds to wait for the first contact model")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_flag("--quiet", quiet,
               "no progress or start-up lines (errors, warnings, session events and the last "
               "lines stay)");
  ht::KeyFileOptions key;
  ht::StationConfig defaults;
  int mtu = defaults.mtu, peer_timeout_ms = defaults.peer_timeout_ms, max_grid = 0;
  ht::AddKeyOption(app, key);
  adv.add_option("--mtu", mtu, "largest UDP datagram for scene-update fragments, bytes")
      ->check(CLI::Range(548, 1472))
      ->capture_default_str();
  adv.add_option("--peer-timeout", peer_timeout_ms,
                 "declare the remote node lost after this long without an authenticated datagram, "
                 "ms (it is then asked for a new session every 250 ms)")
      ->check(CLI::Range(150, 60000))
      ->capture_default_str();
  double max_model_rate = 0.0;
  adv.add_option("--max-model-rate", max_model_rate,
                 "most contact models per second asked of the remote node (0 = the loop rate)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  adv.add_option("--max-grid", max_grid,
                 "refuse a remote node whose penetration-depth grid is larger (0 = any)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  std::string device_name = "simulated", replay_file;
  app.add_option(
         "--device", device_name,
         "operator device: simulated (a scripted hand following --experiment) or replay\n"
         "(a recorded handle trajectory, --replay FILE), spacemouse (3Dconnexion 6-DoF mouse\n"
         "through hidapi, rate control, no force), falcon (Novint Falcon through libusb, 3-DoF\n"
         "position and force; needs --falcon-firmware), forcedimension (omega, sigma, delta,\n"
         "lambda through Force Dimension's libdhd, loaded at start) or openhaptics (3D Systems\n"
         "Touch, Touch X, Phantom through OpenHaptics' libHD, loaded at start)")
      ->check(CLI::IsMember(
          {"simulated", "replay", "spacemouse", "falcon", "forcedimension", "openhaptics"}))
      ->capture_default_str();
  app.add_option(
         "--replay", replay_file,
         "CSV for --device replay: header with t_s and x,y,z (m, device base) and optional\n"
         "rx,ry,rz (rad); or a trace.csv of this station (hand_x,hand_y,hand_z)")
      ->check(CLI::ExistingFile);
  std::string spacemouse_path, falcon_firmware;
  app.add_option("--spacemouse-path", spacemouse_path,
                 "hidraw path of the SpaceMouse (default: the first 6-DoF 3Dconnexion device)");
  app.add_option("--falcon-firmware", falcon_firmware,
                 "Falcon firmware image (not shipped; e.g. from libnifalcon's or Novint's files)");
  std::string device_library;
  app.add_option(
      "--device-library", device_library,
      "the vendor library for --device forcedimension or openhaptics (default: libdhd.so\n"
      "or libHD.so through LD_LIBRARY_PATH and the loader's cache)");
  bool no_passivity = false;
  double model_timeout_s = defaults.safety.model_timeout_s;
  double hunt_crossley = defaults.hunt_crossley_s_per_m;
  app.add_option(
         "--contact-damping-hc", hunt_crossley,
         "Hunt-Crossley contact damping of the simulated tool, alpha in s/m: each\n"
         "contact's force -k depth (1 + alpha d(depth)/dt); it grows with the depth and\n"
         "vanishes at first touch (at a 0.1 mm press, 20 s/m damps as a 2 ms linear damper\n"
         "would; docs/measurements.md); 0 = none")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  double max_contact_force_n = defaults.max_contact_force_n;
  app.add_option("--max-contact-force", max_contact_force_n,
                 "bound on each contact's force on the simulated tool, N (0 = none): a contact\n"
                 "beyond it pushes with the bound and adds no stiffness (DESIGN.md 5; grazing\n"
                 "contacts, docs/hard-cases.md)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  adv.add_flag("--no-passivity", no_passivity,
               "turn off the time-domain passivity controller (for comparison only)");
  double passivity_reserve_mj = ht::StationConfig{}.passivity_reserve_j * 1e3;
  adv.add_option("--passivity-reserve-mj", passivity_reserve_mj,
                 "energy the passivity controller keeps in store, mJ (0 = none): while the "
                 "observed energy is below it, a damping of at most --passivity-refill-pct of "
                 "the wrench refills it, so that a hand too slow for the damping to act draws on "
                 "the store instead of a cut of the force")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  double passivity_refill_pct = ht::StationConfig{}.passivity_refill_fraction * 100.0;
  adv.add_option("--passivity-refill-pct", passivity_refill_pct,
                 "the most the reserve's refill may change the wrench, percent of it")
      ->check(CLI::Range(0.0, 99.0))
      ->capture_default_str();
  double passivity_release_ms = ht::StationConfig{}.passivity_release_ms;
  adv.add_option("--passivity-release-ms", passivity_release_ms,
                 "a force the passivity stage cut comes back over this long instead of on the "
                 "next tick, ms (0 = at once; docs/measurements.md)")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  bool no_energy_bounded_switch = false;
  adv.add_flag("--no-energy-bounded-switch", no_energy_bounded_switch,
               "let a new contact model put its whole stored energy into the loop at once (by "
               "default it may raise the contact potential at the tool by no more than the "
               "passivity observer holds spare; beyond that its surface is moved out of the "
               "tool and given back as that energy allows, within --switch-offset-release-ms)");
  double switch_offset_release_ms = ht::StationConfig{}.switch_offset_release_ms;
  adv.add_option("--switch-offset-release-ms", switch_offset_release_ms,
                 "the longest the energy-bounded switch holds its surface offset, ms (0 = as "
                 "long as the energy budget says)")
      ->check(CLI::Range(0.0, 1e9))
      ->capture_default_str();
  adv.add_option("--model-timeout", model_timeout_s,
                 "fade the force to zero when the contact model is older than this, s")
      ->check(CLI::Range(0.01, 60.0))
      ->capture_default_str();
  // Perceptual deadband (transport/deadband.h): the measured table is in docs/deadband.md.
  double deadband_pct = kDefaultDeadbandPercent;
  std::optional<double> tool_state_deadband_pct, model_deadband_pct;
  double deadband_keepalive_ms = 100.0;
  bool deadband_velocity_adaptive = false, float_models = false, float_tool_states = false;
  bool no_depth_fields = false;
  app.add_option("--deadband", deadband_pct,
                 "perceptual deadband on both streams, percent (a Weber fraction: a tool state or "
                 "contact model is sent only when it differs from what the other side predicts "
                 "by more than this; 0 = off, every sample sent)")
      ->check(CLI::Range(0.0, 99.0))
      ->capture_default_str();
  adv.add_option("--tool-state-deadband", tool_state_deadband_pct,
                 "deadband on the tool states this station sends, percent (default: --deadband)")
      ->check(CLI::Range(0.0, 99.0));
  adv.add_option("--model-deadband", model_deadband_pct,
                 "deadband asked of the remote node for its contact models, percent (default: "
                 "--deadband)")
      ->check(CLI::Range(0.0, 99.0));
  adv.add_option("--deadband-keepalive", deadband_keepalive_ms,
                 "longest gap either stream leaves while its deadband holds samples back, ms "
                 "(below --model-timeout)")
      ->check(CLI::Range(1.0, 60000.0))
      ->capture_default_str();
  bool deadband_velocity = false;
  adv.add_flag("--deadband-velocity", deadband_velocity,
               "also send a tool state when its twist changed beyond the deadband (by default "
               "only the pose's departure from the remote node's extrapolation counts)");
  adv.add_flag("--deadband-velocity-adaptive", deadband_velocity_adaptive,
               "widen the tool-state position and rotation floors while the tool moves fast "
               "(1 + speed / 0.05 m/s)");
  double contact_floor_mm = 0.2, contact_floor_mrad = 20.0;
  adv.add_option("--deadband-contact-floor-mm", contact_floor_mm,
                 "near contact, the tool-state deadband's position floor scale, mm: a tool state "
                 "is sent once the pose leaves the remote node's prediction by the deadband times "
                 "this (free space: 2 mm)")
      ->check(CLI::Range(1e-3, 100.0))
      ->capture_default_str();
  adv.add_option("--deadband-contact-floor-mrad", contact_floor_mrad,
                 "near contact, the tool-state deadband's rotation floor scale, mrad (the same as "
                 "in free space by default)")
      ->check(CLI::Range(1e-3, 1000.0))
      ->capture_default_str();
  double contact_depth_floor_um = ht::ToolStateDeadbandConfig{}.contact_depth_floor_scale_m * 1e6;
  adv.add_option("--deadband-contact-depth-floor-um", contact_depth_floor_um,
                 "near contact, also send a tool state when a contact's depth in the held model "
                 "differs between the tool's pose and the remote node's prediction by more than "
                 "the deadband times max(depth, this), um (0 = off): the remote node linearizes "
                 "at its prediction, so this bounds that point's depth error where the depth "
                 "changes fast (a ridge's flank) and nowhere else")
      ->check(CLI::Range(0.0, 10000.0))
      ->capture_default_str();
  double contact_hold_ms = 500.0;
  adv.add_option("--deadband-contact-hold-ms", contact_hold_ms,
                 "the contact floors stay this long after the held model last had contacts, ms "
                 "(covers a bounce off the surface; 0 = drop them at once)")
      ->check(CLI::Range(0.0, 60000.0))
      ->capture_default_str();
  adv.add_flag(
      "--float-tool-states", float_tool_states,
      "send tool states in the f64 encoding (138 bytes a datagram) rather than the compact "
      "quantized one (66 bytes; transport/protocol.h states its error bounds)");
  adv.add_flag("--float-models", float_models,
               "ask for contact models in the float encoding rather than the compact quantized "
               "one (transport/protocol.h states its error bounds)");
  adv.add_flag("--no-depth-fields", no_depth_fields,
               "render every contact from the linearization the remote node made at the pose it "
               "answered (δ0 + J·Δq) instead of evaluating the contact's depth field, the two "
               "surfaces, at the tool's current pose every tick");
  ht::AddKeygenCommand(app, key);
  std::string merge_summary, merge_remote;
  CLI::App* merge = app.add_subcommand(
      "merge-summary", "add the remote node's remote_summary.json into summary.json and exit");
  merge->add_option("summary", merge_summary, "summary.json to update")->required();
  merge->add_option("remote", merge_remote, "remote_summary.json from slave_sim")->required();
  std::string merge_relay;
  merge->add_option("--relay", merge_relay, "relay_stats.json from ht_relay, kept under \"relay\"");
  if (const auto rc = ht::ParseCommandLine(app, argc, argv, "master_station")) return *rc;

  try {
    if (*merge) return MergeSummary(merge_summary, merge_remote, merge_relay);
    if (ht::RunKeygenIfAsked(key, "master_station")) return 0;
    const ht::MacKey mac_key =
        ht::LoadKeyOption(key, "master_station keygen FILE, and give slave_sim the same file");
    ht::StationConfig config;
    config.remote_address = ht::SocketAddress::Parse(remote);
    config.local_address = ht::SocketAddress::Parse(bind);
    config.loop_rate_hz = rate_hz;
    config.connect_timeout_s = connect_timeout_s;
    config.key = mac_key;
    config.mtu = mtu;
    config.peer_timeout_ms = peer_timeout_ms;
    config.max_grid = max_grid;
    config.max_model_rate_hz = max_model_rate;
    config.passivity = !no_passivity;
    config.max_contact_force_n = max_contact_force_n;
    config.hunt_crossley_s_per_m = hunt_crossley;
    config.passivity_reserve_j = passivity_reserve_mj * 1e-3;
    config.passivity_refill_fraction = passivity_refill_pct / 100.0;
    config.passivity_release_ms = passivity_release_ms;
    config.energy_bounded_switch = !no_energy_bounded_switch;
    config.switch_offset_release_ms = switch_offset_release_ms > 0.0
                                          ? switch_offset_release_ms
                                          : std::numeric_limits<double>::infinity();
    config.safety.model_timeout_s = model_timeout_s;
    config.tool_state_deadband.weber_fraction =
        tool_state_deadband_pct.value_or(deadband_pct) / 100.0;
    config.tool_state_deadband.keepalive_s = deadband_keepalive_ms * 1e-3;
    config.tool_state_deadband.velocity_adaptive = deadband_velocity_adaptive;
    config.tool_state_deadband.velocity_criterion = deadband_velocity;
    config.tool_state_deadband.contact_position_floor_scale_m = contact_floor_mm * 1e-3;
    config.tool_state_deadband.contact_floor_hold_s = contact_hold_ms * 1e-3;
    config.tool_state_deadband.contact_depth_floor_scale_m = contact_depth_floor_um * 1e-6;
    config.tool_state_deadband.contact_rotation_floor_scale_rad = contact_floor_mrad * 1e-3;
    config.model_deadband = model_deadband_pct.value_or(deadband_pct) / 100.0;
    config.model_keepalive_s = deadband_keepalive_ms * 1e-3;
    config.compact_models = !float_models;
    config.depth_fields = !no_depth_fields;
    config.compact_tool_states = !float_tool_states;
    config.out_dir = out_dir;
    config.display.mode = display_mode == "headless" ? ht::DisplayConfig::Mode::kHeadless
                          : display_mode == "window" ? ht::DisplayConfig::Mode::kWindow
                                                     : ht::DisplayConfig::Mode::kNone;
    config.display.frames_dir = frames_dir;
    config.display.frame_rate_hz = frame_rate_hz;
    config.display.max_frames = max_frames;
    config.display.camera_distance_m = camera_distance_m;
    config.display.file_camera = display_camera == "file";
    config.display.overlay = !no_frame_overlay;
    if (std::sscanf(frame_size.c_str(), "%dx%d", &config.display.width, &config.display.height) !=
        2) {
      throw std::invalid_argument("--frame-size " + frame_size +
                                  ": expected WIDTHxHEIGHT, e.g. 640x480");
    }
    config.progress_period_s = quiet ? 0.0 : 0.5;
    // The remote node's Welcome gives the workspace pose (the tool's home) and the tool's
    // inertia; these are used only by a remote node that gives none.
    config.X_WM = ht::BlockOnGearHomePose();
    config.tool_inertia = ht::BlockOnGearToolInertia();
    if (!origin_text.empty()) {
      config.workspace_origin_W = ParseVector(origin_text);
      config.X_WM.translation = *config.workspace_origin_W;
    }

    std::unique_ptr<ht::HapticDevice> device;
    std::unique_ptr<ht::Experiment> experiment;
    if (device_name == "replay") {
      if (replay_file.empty()) throw std::invalid_argument("--device replay needs --replay FILE");
      auto replay = std::make_unique<ht::ReplayDevice>(
          ht::LoadReplayTrace(replay_file, config.X_WM.translation), replay_file);
      // The run lasts as long as the recording unless --duration says otherwise.
      if (app.count("--duration") == 0) duration_s = std::max(0.1, replay->duration_s());
      experiment = ht::MakeExperiment(experiment_name, duration_s);
      device = std::move(replay);
    } else {
      // A person at a real device: the session lasts until they stop it, unless --duration.
      const bool real_device = device_name != "simulated";
      config.run_until_stopped = real_device && app.count("--duration") == 0;
      experiment = ht::MakeExperiment(experiment_name, duration_s);
      if (device_name == "spacemouse") {
        ht::SpaceMouseConfig sm;
        sm.path = spacemouse_path;
        device = std::make_unique<ht::SpaceMouseDevice>(sm);
      } else if (device_name == "falcon") {
        ht::falcon::FalconConfig fc;
        fc.firmware_path = falcon_firmware;
        device = std::make_unique<ht::falcon::FalconDevice>(fc);
      } else if (device_name == "forcedimension") {
        ht::force_dimension::ForceDimensionConfig fd;
        fd.library_path = device_library;
        device = std::make_unique<ht::force_dimension::ForceDimensionDevice>(fd);
      } else if (device_name == "openhaptics") {
        ht::openhaptics::OpenHapticsConfig oh;
        oh.library_path = device_library;
        device = std::make_unique<ht::openhaptics::OpenHapticsDevice>(oh);
      } else {
        device = std::make_unique<ht::SimulatedOperatorDevice>(*experiment);
      }
    }
    if (!quiet) {
      std::printf("[master] device: %s; loop %.0f Hz; remote %s; experiment %s (%.2f s)\n",
                  device->capabilities().name.c_str(), rate_hz, remote.c_str(),
                  experiment_name.c_str(), duration_s);
      std::fflush(stdout);
    }
    // Ctrl-C and SIGTERM: the force is ramped to zero, the device commanded zero and closed,
    // the summary written, exit 0.
    std::signal(SIGINT, OnStopSignal);
    std::signal(SIGTERM, OnStopSignal);
    config.stop_requested = &g_stop;
    config.trace_max_bytes = static_cast<std::uint64_t>(trace_max_mb * 1024.0 * 1024.0);
    const nlohmann::json summary = ht::RunOperatorStation(config, *device, *experiment);
    if (summary["stopped_by_request"].get<bool>()) {
      std::printf("[master] stopped on request after %.1f s: force ramped to zero, device closed\n",
                  summary["duration_s"].get<double>());
    }
    std::printf(
        "[master] done: loop %.1f Hz (tick p99 %.1f us), remote %.1f Hz (compute of the steps "
        "whose models arrived p50 %.0f us), rtt p50 %.3f ms, contacts max %d, non-finite %lld\n",
        summary["operator_rate_hz"].get<double>(), summary["operator_tick_p99_us"].get<double>(),
        summary["remote_rate_hz"].get<double>(),
        summary["remote_step_of_models_p50_us"].get<double>(), summary["rtt_ms_p50"].get<double>(),
        summary["contacts_max"].get<int>(),
        static_cast<long long>(summary["nonfinite_count"].get<std::int64_t>()));
    // What a person must see, said once at the end: deploy/report lists the same.
    const auto number = [&](const nlohmann::json& j, const char* name) {
      return j.is_object() && j.contains(name) && j[name].is_number() ? j[name].get<double>() : 0.0;
    };
    if (const double n = number(summary, "saturated_contact_ticks"); n > 0.0) {
      std::printf(
          "[master] note: on %.0f ticks a contact pushed with its bound (%.1f N, "
          "--max-contact-force); the largest contact force was %.2f N: the tool sank in there\n",
          n, number(summary, "contact_force_bound_n"), number(summary, "contact_force_max_n"));
    }
    if (summary.contains("transport") && summary["transport"].contains("rejected_by_reason")) {
      if (const double bad = number(summary["transport"]["rejected_by_reason"], "bad_mac");
          bad > 0.0) {
        std::printf(
            "[master] note: %.0f datagram(s) failed authentication (bad MAC): the two "
            "sides use different --key files\n",
            bad);
      }
    }
    if (const double n = number(summary["wedged"], "count"); n > 0.0) {
      const nlohmann::json& first = summary["wedged"]["phase_ends"][0];
      std::printf(
          "[master] note: %.0f phase(s) that should end with the tool free ended with it still "
          "pushed by more than %.1f N (wedged), the first %s at %.2f s (%.2f N); summary.json "
          "wedged lists them\n",
          n, number(summary["wedged"], "above_n"), first["phase"].get<std::string>().c_str(),
          first["t_s"].get<double>(), first["contact_force_n"].get<double>());
    }
    if (summary.contains("safety")) {
      if (const double c = number(summary["safety"], "clamped_ticks"); c > 0.0) {
        std::printf("[master] note: the safety stage clamped the device's force on %.0f ticks\n",
                    c);
      }
    }
    if (!out_dir.empty()) {
      std::printf("[master] trace:   %s/trace.csv\n[master] summary: %s/summary.json\n",
                  out_dir.c_str(), out_dir.c_str());
    }
    return summary["nonfinite_count"].get<std::int64_t>() == 0 ? 0 : 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "master_station: error: %s\n", e.what());
    return 2;
  }
}
