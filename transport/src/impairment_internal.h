#pragma once
// Private to transport/src/impairment_*.cc (not installed): what the spec, the model and the
// relay share.

#include <cstdint>

#include "transport/impairment_spec.h"

namespace ht::impairment_internal {

constexpr std::int64_t kNsPerUs = 1'000;
constexpr std::int64_t kNsPerMs = 1'000'000;
constexpr std::int64_t kNsPerS = 1'000'000'000;

// Throws std::invalid_argument when the spec's fields are outside the ranges Parse accepts, or
// the loss and burst do not make a valid Gilbert–Elliott chain (impairment_spec.cc).
void Validate(const ImpairmentSpec& s);

}  // namespace ht::impairment_internal
