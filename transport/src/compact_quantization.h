#pragma once
// The compact messages' quantization (protocol.h, CompactContactModel and CompactToolState): the
// sender's way to the wire bodies and the receiver's way back, with their value checks (internal to
// the wire format's files). No NaN, infinite or out-of-range double is ever converted to an
// integer.

#include <cstdint>

#include "wire_fields.h"

namespace ht::wire::detail {

/// The contact model's compact body: each quantity at protocol.h's step, a non-finite one as its
/// marker.
CompactContactModelBody QuantizeContactModel(const ContactModelMessage& m) noexcept;
/// The compact body's values: the marker, steps and ranges protocol.h allows.
DecodeStatus Check(const CompactContactModelBody& m);
/// The contact model back from its compact body, stamped `receive_time_ns` (ns) where the body
/// carries ages.
ContactModelMessage DequantizeContactModel(const CompactContactModelBody& b,
                                           std::int64_t receive_time_ns) noexcept;
/// The tool state's compact body.
CompactToolStateBody QuantizeToolState(const ToolStateMessage& m) noexcept;
/// The compact tool state's values.
DecodeStatus Check(const CompactToolStateBody& m);
/// The tool state back from its compact body.
ToolStateMessage DequantizeToolState(const CompactToolStateBody& b) noexcept;

}  // namespace ht::wire::detail
