#pragma once
// Where the team's glTF test files are (../shared/data/gltf, or $HT_SHARED_DATA/gltf): tests that
// read them skip with a message when they are absent (a user's clone has no ../shared).

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <optional>

namespace ht::testing {

/// The gltf/ folder of the shared data: $HT_SHARED_DATA/gltf, else ../shared/data/gltf relative to
/// the working directory (tests run from the repository root); nullopt when neither exists.
inline std::optional<std::filesystem::path> GltfDataDir() {
  std::filesystem::path base = "../shared/data";
  if (const char* env = std::getenv("HT_SHARED_DATA"); env != nullptr && *env != '\0') base = env;
  std::error_code ec;
  if (std::filesystem::is_directory(base / "gltf", ec)) return base / "gltf";
  return std::nullopt;
}

}  // namespace ht::testing

/// Declares `dir` (std::optional<std::filesystem::path>) or skips the test with a message.
#define REQUIRE_GLTF_DATA(dir)                                                                \
  const std::optional<std::filesystem::path> dir = ::ht::testing::GltfDataDir();              \
  if (!dir) {                                                                                 \
    GTEST_SKIP() << "glTF test data not found: set HT_SHARED_DATA to the shared data folder " \
                    "(the one holding gltf/), or run from the repository root with "          \
                    "../shared/data/gltf present";                                            \
  }
