#pragma once
// Command-line errors of every program (issue 35): one line "program: error: what", exit 2,
// checked before anything starts.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>

namespace ht {

/// Parses argc/argv into `app` (CLI11). Returns std::nullopt when the program should go on, or
/// the status it should exit with: 0 after --help (CLI11 prints it on stdout), 2 after a bad
/// argument, which is printed on stderr as one line "`program`: error: <what CLI11 says>", with
/// what to do where it helps (a --key file that does not exist: `slave_sim keygen FILE`).
/// Header-only: the programs link CLI11, the libraries do not.
inline std::optional<int> ParseCommandLine(CLI::App& app, int argc, const char* const* argv,
                                           const char* program) {
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
    if (what.find("--key") != std::string::npos &&
        what.find("does not exist") != std::string::npos) {
      what += " (make one with 'slave_sim keygen FILE' and copy it to the other side)";
    }
    std::fprintf(stderr, "%s: error: %s (see %s --help)\n", program, what.c_str(), program);
    return 2;
  }
  return std::nullopt;
}

}  // namespace ht
