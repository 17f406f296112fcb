#pragma once
// Command-line errors of every program (issue 35): one line "program: error: what", exit 2,
// checked before anything starts.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "transport/auth.h"

namespace ht {

/// The keys a --config file of `app` may hold: its configurable long options without their
/// dashes, sorted, comma-separated ("--help" and --config itself are not keys).
inline std::string ConfigFileKeys(const CLI::App& app) {
  std::vector<std::string> keys;
  for (const CLI::Option* option : app.get_options()) {
    if (!option->get_configurable() || option->get_lnames().empty()) continue;
    if (option->get_lnames().front() == "help") continue;
    keys.push_back(option->get_lnames().front());
  }
  std::sort(keys.begin(), keys.end());
  std::string out;
  for (const std::string& key : keys) out += (out.empty() ? "" : ", ") + key;
  return out;
}

/// Parses argc/argv into `app` (CLI11). Returns std::nullopt when the program should go on, or
/// the status it should exit with: 0 after --help (CLI11 prints it on stdout), 2 after a bad
/// argument, which is printed on stderr as one line "`program`: error: <what CLI11 says>", with
/// what to do where it helps (a --key file that does not exist: `slave_sim keygen FILE`). A
/// --config file's key that names no option is refused the same way, with the known keys.
/// Header-only: the programs link CLI11, the libraries do not.
inline std::optional<int> ParseCommandLine(CLI::App& app, int argc, const char* const* argv,
                                           const char* program) {
  app.allow_config_extras(CLI::config_extras_mode::error);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::string what = e.what();
    // CLI11 says "INI was not able to parse KEY" for a key no option has.
    static constexpr std::string_view kExtra = "INI was not able to parse ";
    if (dynamic_cast<const CLI::ConfigError*>(&e) != nullptr && what.starts_with(kExtra)) {
      const CLI::Option* config = app.get_config_ptr();
      const std::string file =
          config != nullptr && config->count() > 0 ? config->as<std::string>() : "--config";
      what = file + ": unknown key '" + what.substr(kExtra.size()) +
             "' (known: " + ConfigFileKeys(app) + ")";
    }
    if (what.find("--key") != std::string::npos &&
        what.find("does not exist") != std::string::npos) {
      what += " (make one with 'slave_sim keygen FILE' and copy it to the other side)";
    }
    std::fprintf(stderr, "%s: error: %s (see %s --help)\n", program, what.c_str(), program);
    return 2;
  }
  return std::nullopt;
}

/// The pre-shared key's command line, the same on both sides (issue 34: written once): `--key
/// FILE` and the `keygen PATH [--force]` subcommand.
struct KeyFileOptions {
  std::string key_file;     ///< --key
  std::string keygen_path;  ///< keygen's PATH
  bool keygen_force = false;
  CLI::App* keygen = nullptr;  ///< the subcommand, once added
};

/// Adds `--key FILE` (it must exist) to `app`; `options` must outlive the parse.
inline void AddKeyOption(CLI::App& app, KeyFileOptions& options) {
  app.add_option("--key", options.key_file,
                 "pre-shared key file (64 hex characters, mode 0600); required")
      ->check(CLI::ExistingFile);
}

/// Adds the `keygen PATH [--force]` subcommand to `app`; `options` must outlive the parse.
inline void AddKeygenCommand(CLI::App& app, KeyFileOptions& options) {
  options.keygen = app.add_subcommand(
      "keygen",
      "write a new random pre-shared key (mode 0600) to PATH and exit; copy the same\n"
      "file to the other machine");
  options.keygen->add_option("path", options.keygen_path, "where to write the key")->required();
  options.keygen->add_flag("--force", options.keygen_force, "overwrite an existing file");
}

/// After the parse: when `keygen` was given, writes a new random key to its PATH (WriteKeyFile,
/// which throws when the file exists without --force or cannot be written), says so on stdout as
/// `program`, and returns true (the program then exits 0); false otherwise.
inline bool RunKeygenIfAsked(const KeyFileOptions& options, const char* program) {
  if (options.keygen == nullptr || !*options.keygen) return false;
  WriteKeyFile(options.keygen_path, MacKey::Generate(), options.keygen_force);
  std::printf("%s: wrote a new key to %s (mode 0600); copy it to the other side\n", program,
              options.keygen_path.c_str());
  return true;
}

/// The key of `--key` (LoadKeyFile). Throws std::invalid_argument when --key was not given:
/// "--key FILE is required: every datagram is authenticated (create a key with: `how_to_make`)",
/// and what LoadKeyFile throws for a bad file.
inline MacKey LoadKeyOption(const KeyFileOptions& options, const std::string& how_to_make) {
  if (options.key_file.empty()) {
    throw std::invalid_argument(
        "--key FILE is required: every datagram is authenticated (create a key with: " +
        how_to_make + ")");
  }
  return LoadKeyFile(options.key_file);
}

}  // namespace ht
