#pragma once
// What every program's command line shares: errors as one line "program: error: what", exit 2,
// checked before anything starts; help in two levels (--help, --help-all); the pre-shared key's
// options.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "transport/auth.h"

namespace ht {

namespace detail {
inline void AddConfigFileKeys(const CLI::App& app, std::vector<std::string>& keys) {
  for (const CLI::Option* option : app.get_options()) {
    if (!option->get_configurable() || option->get_lnames().empty()) continue;
    const std::string& name = option->get_lnames().front();
    if (name == "help" || name == "help-all") continue;
    keys.push_back(name);
  }
  // Option groups (add_option_group) are nameless subcommands whose options are the app's own.
  for (const CLI::App* group : app.get_subcommands({})) {
    if (group->get_name().empty()) AddConfigFileKeys(*group, keys);
  }
}
}  // namespace detail

/// The keys a --config file of `app` may hold: its configurable long options without their
/// dashes, those of its option groups included, sorted, comma-separated ("--help", "--help-all"
/// and --config itself are not keys).
inline std::string ConfigFileKeys(const CLI::App& app) {
  std::vector<std::string> keys;
  detail::AddConfigFileKeys(app, keys);
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  std::string out;
  for (const std::string& key : keys) out += (out.empty() ? "" : ", ") + key;
  return out;
}

/// Help in two levels. --help lists the app's own options and names each option group with the
/// number of its options; --help-all lists the groups' options too. The options of a group parse
/// and load from a --config file exactly as the app's own (CLI11 looks options up through
/// nameless subcommands, which option groups are).
class TwoLevelHelpFormatter : public CLI::Formatter {
 public:
  std::string make_help(const CLI::App* app, std::string name,
                        CLI::AppFormatMode mode) const override {
    // Subcommands listed under --help-all are formatted with mode Sub: keep the caller's level.
    if (mode != CLI::AppFormatMode::Sub) all_ = mode == CLI::AppFormatMode::All;
    return CLI::Formatter::make_help(app, std::move(name), mode);
  }
  std::string make_expanded(const CLI::App* sub) const override {
    if (!sub->get_name().empty()) return CLI::Formatter::make_expanded(sub);
    if (all_) {  // "[Option Group: NAME]" and the group indented: "NAME:" as the app's own groups
      const std::string text = CLI::Formatter::make_expanded(sub);
      return "\n" + sub->get_group() + ":" + text.substr(text.find('\n'));
    }
    const std::size_t n =
        sub->get_options([sub](const CLI::Option* option) {
             return option != sub->get_help_ptr() && option != sub->get_help_all_ptr();
           })
            .size();
    std::string description = sub->get_description();
    for (std::size_t at = description.find('\n'); at != std::string::npos;
         at = description.find('\n', at + 1)) {
      description.insert(at + 1, "  ");
    }
    return "\n" + sub->get_group() + " (" + std::to_string(n) +
           " options, listed by --help-all):\n  " + description + "\n";
  }

 private:
  mutable bool all_ = false;
};

/// Gives `app` the two-level help (TwoLevelHelpFormatter) and its --help-all flag. Call it before
/// adding option groups or subcommands: they inherit the formatter when they are added.
inline void UseTwoLevelHelp(CLI::App& app) {
  app.formatter(std::make_shared<TwoLevelHelpFormatter>());
  app.set_help_all_flag("--help-all", "Print the help of every option, the advanced ones too");
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
    // An option of an Advanced group is listed by --help-all only (UseTwoLevelHelp).
    const char* help = app.get_help_all_ptr() != nullptr ? "--help-all" : "--help";
    std::fprintf(stderr, "%s: error: %s (see %s %s)\n", program, what.c_str(), program, help);
    return 2;
  }
  return std::nullopt;
}

/// The pre-shared key's command line, the same on both sides: `--key FILE` and the
/// `keygen PATH [--force]` subcommand.
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
