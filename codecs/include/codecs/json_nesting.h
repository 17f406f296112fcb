#pragma once
// A guard for JSON read from files (hostile input): the parsers the project uses
// (nlohmann::json, tinygltf's) recurse once per nesting level when they build, copy, print or
// destroy a document, so a few hundred kilobytes of "[[[[…" overflow the stack. Files are
// scanned for their nesting depth before any parser sees them.

#include <cstddef>
#include <string_view>

namespace ht {

/// The deepest nesting of arrays and objects allowed in a scene file's JSON (glTF documents and
/// scene descriptions nest a handful of levels; glTF "extras" a few more).
inline constexpr std::size_t kMaxJsonNesting = 256;

/// Largest nesting depth of `[`/`{` in `text`, counting only brackets outside strings (escapes
/// inside strings are honoured). Linear time, no allocation, never throws; any bytes are fine
/// (malformed JSON gives a depth, and the parser then refuses it).
std::size_t JsonNestingDepth(std::string_view text) noexcept;

}  // namespace ht
