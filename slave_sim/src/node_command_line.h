#pragma once
// slave_sim's command line: its options by group, what they make of the node's configuration
// (RemoteNodeConfig), and its two subcommands. main.cc is the list of calls.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "haptic_core/model_build/haptic_model_build.h"
#include "slave_sim/remote_node.h"
#include "transport/command_line.h"

namespace ht {

/// The command line's values. Options that map one to one onto the node's configuration are
/// bound to `config` itself; the others (flags that turn a default off, units other than SI,
/// choices by name) are kept here until FinishNodeConfig. Bound by address (neither copied nor
/// moved).
struct NodeCommandLine {
  NodeCommandLine() = default;
  NodeCommandLine(const NodeCommandLine&) = delete;
  NodeCommandLine& operator=(const NodeCommandLine&) = delete;

  RemoteNodeConfig config;

  // The address and the scene (AddSceneOptions).
  std::string listen = "127.0.0.1:47000";
  std::string scene = "block-on-gear";
  std::string scene_tool;
  std::string scene_cache_dir = HapticModelCache::DefaultDir();
  bool no_watch = false;

  // Stage 5b and the force law (AddDepthOptions).
  bool no_refine_depth = false;
  std::string force_law = "seed";
  double pressure_stiffness = 0.0;

  // Speculative contacts (AddSpeculativeOptions).
  double speculative_speed_mm_s = RemoteNodeConfig{}.speculative_speed_m_per_s * 1e3;
  double max_speculative_floor_mm = RemoteNodeConfig{}.max_speculative_floor_m * 1e3;
  double speculative_lead_ms = 50.0;

  // The texture stage's backend (AddBackendOptions).
  std::string pd_backend = "auto";
  bool per_render_draws = false;

  // The stream (AddStreamOptions).
  double max_deadband_pct = 50.0;
  std::string out_dir;
  std::string port_file;
  KeyFileOptions key;
  int mtu = 1472;
  bool stay = false;
  bool quiet = false;

  // 'slave_sim inspect FILE'.
  CLI::App* inspect = nullptr;
  std::string inspect_path;
  std::string inspect_tool;
  std::string cache_dir = HapticModelCache::DefaultDir();
  bool no_cache = false;

  // 'slave_sim seed-models --out DIR'.
  CLI::App* seed_models = nullptr;
  std::string seed_out;
  std::vector<std::string> seed_names;
};

/// Adds every option, the keygen command and both subcommands to `app`, bound to `cl`, in the
/// order --help lists them.
void AddNodeOptions(CLI::App& app, NodeCommandLine& cl);

/// After parsing: fills cl.config from the values kept in `cl` (units, defaults that depend on
/// other options, the key file). Throws what LoadKeyOption and SocketAddress::Parse throw.
void FinishNodeConfig(const CLI::App& app, NodeCommandLine& cl);

/// 'slave_sim seed-models': writes the seed's six benchmark models (or cl.seed_names) as
/// DIR/NAME.glb with a scene description DIR/NAME.json. Returns the exit code: 0, or 2 after
/// printing the error (an unknown model name, a file that cannot be written).
int RunSeedModelsCommand(const NodeCommandLine& cl);

/// 'slave_sim inspect FILE': builds (or loads from the cache) every model of the scene and prints
/// one JSON object. Returns the exit code: 0, or 2 after printing a one-line error.
int RunInspectCommand(const NodeCommandLine& cl);

}  // namespace ht
