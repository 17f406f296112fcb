// A depth field as bytes (depth_field_codec.h).

#include "codecs/depth_field_codec.h"

#include <bit>
#include <cstring>
#include <stdexcept>

namespace ht {
namespace {

// The fields are copied in host order: little-endian hosts only (x86-64, AArch64).
static_assert(std::endian::native == std::endian::little);

class Writer {
 public:
  std::vector<std::uint8_t> bytes;
  void U8(std::uint8_t v) { bytes.push_back(v); }
  void U16(std::uint16_t v) { Raw(&v, 2); }
  void U32(std::uint32_t v) { Raw(&v, 4); }
  void I32(std::int32_t v) { Raw(&v, 4); }
  void F64(double v) { Raw(&v, 8); }
  void Pose(const RigidTransform& X) {
    for (int k = 0; k < 3; ++k) F64(X.translation[k]);
    F64(X.rotation.w);
    F64(X.rotation.x);
    F64(X.rotation.y);
    F64(X.rotation.z);
  }

 private:
  void Raw(const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    bytes.insert(bytes.end(), b, b + n);
  }
};

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  bool ok() const { return ok_; }
  std::size_t left() const { return ok_ ? b_.size() - at_ : 0; }
  std::uint8_t U8() {
    std::uint8_t v = 0;
    Raw(&v, 1);
    return v;
  }
  std::uint16_t U16() {
    std::uint16_t v = 0;
    Raw(&v, 2);
    return v;
  }
  std::uint32_t U32() {
    std::uint32_t v = 0;
    Raw(&v, 4);
    return v;
  }
  std::int32_t I32() {
    std::int32_t v = 0;
    Raw(&v, 4);
    return v;
  }
  double F64() {
    double v = 0.0;
    Raw(&v, 8);
    return v;
  }
  RigidTransform Pose() {
    RigidTransform X;
    for (int k = 0; k < 3; ++k) X.translation[k] = F64();
    X.rotation.w = F64();
    X.rotation.x = F64();
    X.rotation.y = F64();
    X.rotation.z = F64();
    return X;
  }
  std::span<const std::uint8_t> Bytes(std::size_t n) {
    if (!ok_ || n > b_.size() - at_) {
      ok_ = false;
      return {};
    }
    const auto s = b_.subspan(at_, n);
    at_ += n;
    return s;
  }

 private:
  void Raw(void* p, std::size_t n) {
    if (!ok_ || n > b_.size() - at_) {
      ok_ = false;
      return;
    }
    std::memcpy(p, b_.data() + at_, n);
    at_ += n;
  }
  std::span<const std::uint8_t> b_;
  std::size_t at_ = 0;
  bool ok_ = true;
};

}  // namespace

std::vector<std::uint8_t> EncodeDepthField(const DepthField& f,
                                           const DepthMapEncodeOptions& options) {
  if (f.nx < 1 || f.ny < 1 || f.nx > kMaxDepthFieldSide || f.ny > kMaxDepthFieldSide) {
    throw std::invalid_argument("EncodeDepthField: sides " + std::to_string(f.nx) + " x " +
                                std::to_string(f.ny) + " outside [1, " +
                                std::to_string(kMaxDepthFieldSide) + "]");
  }
  const std::vector<std::uint8_t> env = EncodeDepthMap(f.env_height_m, f.nx, f.ny, options);
  const std::vector<std::uint8_t> tool = EncodeDepthMap(f.tool_height_m, f.nx, f.ny, options);
  Writer w;
  w.bytes.reserve(200 + env.size() + tool.size());
  w.U8(kDepthFieldFormat);
  w.U32(f.id);
  w.U32(f.lattice_id);
  w.I32(f.lattice_i0);
  w.I32(f.lattice_j0);
  w.I32(f.tool_lattice_i0);
  w.I32(f.tool_lattice_j0);
  w.F64(f.cell_m);
  w.U16(static_cast<std::uint16_t>(f.nx));
  w.U16(static_cast<std::uint16_t>(f.ny));
  w.F64(f.tool_offset_u_m);
  w.F64(f.tool_offset_v_m);
  w.Pose(f.X_WF);
  w.Pose(f.X_WT0);
  w.F64(f.travel_margin_m);
  w.F64(f.smooth_max_m);
  w.U32(static_cast<std::uint32_t>(env.size()));
  w.bytes.insert(w.bytes.end(), env.begin(), env.end());
  w.U32(static_cast<std::uint32_t>(tool.size()));
  w.bytes.insert(w.bytes.end(), tool.begin(), tool.end());
  return std::move(w.bytes);
}

bool DecodeDepthField(std::span<const std::uint8_t> bytes, DepthField& out,
                      DecodedDepthMap& scratch, std::string& error) {
  out.prepared = false;
  Reader r(bytes);
  const std::uint8_t format = r.U8();
  if (r.ok() && format != kDepthFieldFormat) {
    error = "depth-field format " + std::to_string(format) + " is not " +
            std::to_string(kDepthFieldFormat);
    return false;
  }
  out.id = r.U32();
  out.lattice_id = r.U32();
  out.lattice_i0 = r.I32();
  out.lattice_j0 = r.I32();
  out.tool_lattice_i0 = r.I32();
  out.tool_lattice_j0 = r.I32();
  out.cell_m = r.F64();
  out.nx = r.U16();
  out.ny = r.U16();
  out.tool_offset_u_m = r.F64();
  out.tool_offset_v_m = r.F64();
  out.X_WF = r.Pose();
  out.X_WT0 = r.Pose();
  out.travel_margin_m = r.F64();
  out.smooth_max_m = r.F64();
  for (const bool tool : {false, true}) {
    const std::uint32_t n = r.U32();
    const std::span<const std::uint8_t> map = r.Bytes(n);
    if (!r.ok()) {
      error = "a depth field of " + std::to_string(bytes.size()) + " bytes ends early";
      return false;
    }
    if (!DecodeDepthMap(map, kMaxDepthFieldSide, scratch, error)) {
      error = std::string(tool ? "the tool's" : "the environment's") + " map: " + error;
      return false;
    }
    if (scratch.nx != out.nx || scratch.ny != out.ny) {
      error = "a map of " + std::to_string(scratch.nx) + " x " + std::to_string(scratch.ny) +
              " nodes in a field of " + std::to_string(out.nx) + " x " + std::to_string(out.ny);
      return false;
    }
    (tool ? out.tool_height_m : out.env_height_m).swap(scratch.heights_m);
  }
  if (r.left() != 0) {
    error = std::to_string(r.left()) + " bytes follow the depth field";
    return false;
  }
  if (!out.Prepare()) {
    error = "the depth field is not valid (DepthField::Prepare: id, frames, sides, margin, width)";
    return false;
  }
  return true;
}

}  // namespace ht
