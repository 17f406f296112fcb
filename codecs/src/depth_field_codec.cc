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
  template <class T>
  void Put(T v) {
    const auto* b = reinterpret_cast<const std::uint8_t*>(&v);
    bytes.insert(bytes.end(), b, b + sizeof v);
  }
  void Pose(const RigidTransform& X) {
    for (const double v : {X.translation.x, X.translation.y, X.translation.z, X.rotation.w,
                           X.rotation.x, X.rotation.y, X.rotation.z}) {
      Put(v);
    }
  }
};

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  bool ok() const { return ok_; }
  std::size_t left() const { return ok_ ? b_.size() - at_ : 0; }
  /// The next sizeof(T) bytes as a T (0 once the bytes have run out; ok() says so).
  template <class T>
  T Get() {
    T v{};
    const std::span<const std::uint8_t> raw = Bytes(sizeof v);
    if (ok_) std::memcpy(&v, raw.data(), sizeof v);
    return v;
  }
  RigidTransform Pose() {
    RigidTransform X;
    for (int k = 0; k < 3; ++k) X.translation[k] = Get<double>();
    X.rotation.w = Get<double>();
    X.rotation.x = Get<double>();
    X.rotation.y = Get<double>();
    X.rotation.z = Get<double>();
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
  w.Put<std::uint8_t>(kDepthFieldFormat);
  w.Put<std::uint32_t>(f.id);
  w.Put<std::uint32_t>(f.lattice_id);
  w.Put<std::int32_t>(f.lattice_i0);
  w.Put<std::int32_t>(f.lattice_j0);
  w.Put<std::int32_t>(f.tool_lattice_i0);
  w.Put<std::int32_t>(f.tool_lattice_j0);
  w.Put<double>(f.cell_m);
  w.Put<std::uint16_t>(static_cast<std::uint16_t>(f.nx));
  w.Put<std::uint16_t>(static_cast<std::uint16_t>(f.ny));
  w.Put<double>(f.tool_offset_u_m);
  w.Put<double>(f.tool_offset_v_m);
  w.Pose(f.X_WF);
  w.Pose(f.X_WT0);
  w.Put<double>(f.travel_margin_m);
  w.Put<double>(f.smooth_max_m);
  w.Put<std::uint8_t>(static_cast<std::uint8_t>(f.force_law));
  w.Put<double>(f.pressure_area_m2);
  w.Put<std::uint8_t>(f.stride_hint);
  w.Put<std::uint32_t>(static_cast<std::uint32_t>(env.size()));
  w.bytes.insert(w.bytes.end(), env.begin(), env.end());
  w.Put<std::uint32_t>(static_cast<std::uint32_t>(tool.size()));
  w.bytes.insert(w.bytes.end(), tool.begin(), tool.end());
  return std::move(w.bytes);
}

bool DecodeDepthField(std::span<const std::uint8_t> bytes, DepthField& out,
                      DecodedDepthMap& scratch, std::string& error) {
  out.prepared = false;
  Reader r(bytes);
  const std::uint8_t format = r.Get<std::uint8_t>();
  if (r.ok() && format != kDepthFieldFormat) {
    error = "depth-field format " + std::to_string(format) + " is not " +
            std::to_string(kDepthFieldFormat);
    return false;
  }
  out.id = r.Get<std::uint32_t>();
  out.lattice_id = r.Get<std::uint32_t>();
  out.lattice_i0 = r.Get<std::int32_t>();
  out.lattice_j0 = r.Get<std::int32_t>();
  out.tool_lattice_i0 = r.Get<std::int32_t>();
  out.tool_lattice_j0 = r.Get<std::int32_t>();
  out.cell_m = r.Get<double>();
  out.nx = r.Get<std::uint16_t>();
  out.ny = r.Get<std::uint16_t>();
  out.tool_offset_u_m = r.Get<double>();
  out.tool_offset_v_m = r.Get<double>();
  out.X_WF = r.Pose();
  out.X_WT0 = r.Pose();
  out.travel_margin_m = r.Get<double>();
  out.smooth_max_m = r.Get<double>();
  out.force_law = static_cast<ForceLaw>(r.Get<std::uint8_t>());
  out.pressure_area_m2 = r.Get<double>();
  out.stride_hint = r.Get<std::uint8_t>();
  for (const bool tool : {false, true}) {
    const std::uint32_t n = r.Get<std::uint32_t>();
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
    error =
        "the depth field is not valid (DepthField::Prepare: id, frames, sides, margin, width, law)";
    return false;
  }
  return true;
}

}  // namespace ht
