// 3Dconnexion SpaceMouse, the device: the model table's lookup and built-in descriptors, and
// SpaceMouseDevice (hidapi enumeration and open, report descriptor from hidapi, sysfs or built-in,
// reader thread, lock-free hand-off to ReadState).

#include "master_station/spacemouse.h"

#include <hidapi.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

#include "spacemouse_internal.h"

// hid_get_report_descriptor arrived in hidapi 0.14.0; Debian 12 ships 0.13.1.
#if defined(HID_API_VERSION) && defined(HID_API_MAKE_VERSION)
#if HID_API_VERSION >= HID_API_MAKE_VERSION(0, 14, 0)
#define HT_HIDAPI_HAS_GET_REPORT_DESCRIPTOR 1
#endif
#endif

namespace ht {

// ------------------------------------------------------------------------------------------------
// 3. Device table
// ------------------------------------------------------------------------------------------------

const SpaceMouseModel* FindSpaceMouseModel(std::uint16_t vendor_id,
                                           std::uint16_t product_id) noexcept {
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    if (m.vendor_id == vendor_id && m.product_id == product_id) return &m;
  }
  return nullptr;
}

namespace {

// Written from the layout facts (HID usages, 16-bit little-endian axes with logical range
// -350..350, buttons in report 3), keeping each family's Input flags: the split (Logitech-era)
// firmwares flag the axes Relative (0x06), the six-axis ones Absolute (0x02).
// clang-format off
constexpr std::uint8_t kSplitDescriptor[] = {
    0x05, 0x01, 0x09, 0x08, 0xA1, 0x01,              // Generic Desktop, Multi-axis Controller
    0xA1, 0x00, 0x85, 0x01,                          //   report 1: translation
    0x16, 0xA2, 0xFE, 0x26, 0x5E, 0x01,              //   logical -350..350
    0x09, 0x30, 0x09, 0x31, 0x09, 0x32,              //   X Y Z
    0x75, 0x10, 0x95, 0x03, 0x81, 0x06, 0xC0,        //   3 x 16 bits, Data Var Rel
    0xA1, 0x00, 0x85, 0x02,                          //   report 2: rotation
    0x09, 0x33, 0x09, 0x34, 0x09, 0x35,              //   Rx Ry Rz
    0x75, 0x10, 0x95, 0x03, 0x81, 0x06, 0xC0,
    0xA1, 0x02, 0x85, 0x03, 0x05, 0x09,              //   report 3: buttons 1..16
    0x19, 0x01, 0x29, 0x10, 0x15, 0x00, 0x25, 0x01,
    0x75, 0x01, 0x95, 0x10, 0x81, 0x02, 0xC0,
    0xC0};
constexpr std::uint8_t kSixAxisDescriptor[] = {
    0x05, 0x01, 0x09, 0x08, 0xA1, 0x01,              // Generic Desktop, Multi-axis Controller
    0xA1, 0x00, 0x85, 0x01,                          //   report 1: all six axes
    0x16, 0xA2, 0xFE, 0x26, 0x5E, 0x01,              //   logical -350..350
    0x09, 0x30, 0x09, 0x31, 0x09, 0x32,              //   X Y Z
    0x09, 0x33, 0x09, 0x34, 0x09, 0x35,              //   Rx Ry Rz
    0x75, 0x10, 0x95, 0x06, 0x81, 0x02, 0xC0,        //   6 x 16 bits, Data Var Abs
    0xA1, 0x02, 0x85, 0x03, 0x05, 0x09,              //   report 3: buttons 1..16
    0x19, 0x01, 0x29, 0x10, 0x15, 0x00, 0x25, 0x01,
    0x75, 0x01, 0x95, 0x10, 0x81, 0x02, 0xC0,
    0xC0};
// clang-format on

}  // namespace

std::span<const std::uint8_t> BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle style) noexcept {
  switch (style) {
    case SpaceMouseReportStyle::kSplit:
      return kSplitDescriptor;
    case SpaceMouseReportStyle::kSixAxis:
      return kSixAxisDescriptor;
    default:
      return {};
  }
}

// ------------------------------------------------------------------------------------------------
// 5. The device
// ------------------------------------------------------------------------------------------------

namespace {

using detail::Format;

constexpr const char* kUdevHint = "see deploy/udev/70-haptic-spacemouse.rules";

std::string Narrow(const wchar_t* w) {
  if (w == nullptr) return "no error text";
  std::string s;
  for (; *w != L'\0'; ++w) {
    s.push_back(*w > 0 && *w < 128 ? static_cast<char>(*w) : '?');
  }
  return s;
}

std::string LookedFor() {
  std::string s;
  for (const SpaceMouseModel& m : kSpaceMouseModels) {
    if (!m.six_dof) continue;
    if (!s.empty()) s += ", ";
    s += Format("%04x:%04x", static_cast<unsigned>(m.vendor_id),
                static_cast<unsigned>(m.product_id));
  }
  return s;
}

struct Candidate {
  std::string path;
  const SpaceMouseModel* model = nullptr;
  bool multi_axis_interface = false;  // usage page 1, usage 8 (or unknown)
};

// hidraw: /dev/hidrawN → /sys/class/hidraw/hidrawN/device/report_descriptor.
std::vector<std::uint8_t> ReadSysfsDescriptor(const std::string& path) {
  const std::string prefix = "/dev/";
  if (path.rfind(prefix + "hidraw", 0) != 0) return {};
  const std::string node = path.substr(prefix.size());
  std::ifstream in("/sys/class/hidraw/" + node + "/device/report_descriptor", std::ios::binary);
  if (!in) return {};
  std::vector<std::uint8_t> bytes(4096);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  bytes.resize(static_cast<std::size_t>(std::max<std::streamsize>(0, in.gcount())));
  return bytes;
}

}  // namespace

SpaceMouseDevice::SpaceMouseDevice(const SpaceMouseConfig& config)
    : config_(config), mapper_(config) {}

SpaceMouseDevice::~SpaceMouseDevice() { Close(); }

DeviceCapabilities SpaceMouseDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "3Dconnexion " + (model_name_.empty() ? std::string("SpaceMouse") : model_name_) +
           " (hidapi, input only)";
  c.max_force_n = 0.0;
  c.max_torque_nm = 0.0;
  c.max_stiffness_n_per_m = 0.0;
  c.max_rotational_stiffness_nm_per_rad = 0.0;
  c.max_damping_ns_per_m = 0.0;
  c.rated_loop_rate_hz = 1000.0;
  c.workspace_half_extents_m = config_.workspace_half_extents_m;
  c.dof_in = 6;
  c.dof_out = 0;
  return c;
}

void SpaceMouseDevice::Open() {
  Close();
  if (hid_init() != 0) {
    throw std::runtime_error("spacemouse: hid_init failed: " + Narrow(hid_error(nullptr)));
  }
  // Find the device: the table's 6-DoF models on both vendor ids, or the path given.
  std::vector<Candidate> found;
  const bool by_path = !config_.path.empty();
  auto scan = [&](unsigned short vendor_id) {
    hid_device_info* list = hid_enumerate(vendor_id, 0);
    for (hid_device_info* i = list; i != nullptr; i = i->next) {
      if (i->path == nullptr) continue;
      const SpaceMouseModel* model = FindSpaceMouseModel(i->vendor_id, i->product_id);
      if (by_path) {
        if (config_.path == i->path) found.push_back({i->path, model, true});
        continue;
      }
      if (model == nullptr || !model->six_dof) continue;
      const bool multi_axis = i->usage_page == 0 || (i->usage_page == kHidPageGenericDesktop &&
                                                     i->usage == kHidUsageMultiAxisController);
      found.push_back({i->path, model, multi_axis});
    }
    hid_free_enumeration(list);
  };
  if (by_path) {
    scan(0);
  } else {
    scan(0x046d);
    scan(0x256f);
  }
  // Prefer the multi-axis interface of a device that exposes several.
  std::stable_sort(found.begin(), found.end(), [](const Candidate& a, const Candidate& b) {
    return a.multi_axis_interface && !b.multi_axis_interface;
  });
  Candidate chosen;
  if (!found.empty()) {
    chosen = found.front();
  } else if (by_path) {
    chosen.path = config_.path;  // not enumerated (e.g. a path outside udev): try it anyway
  } else {
    throw std::runtime_error("no 3Dconnexion device found (looked for " + LookedFor() +
                             "); is it plugged in, and does /dev/hidraw* allow you to read it? " +
                             kUdevHint);
  }
  const std::string name =
      chosen.model != nullptr ? std::string(chosen.model->name) : std::string("HID device");
  hid_device* handle = hid_open_path(chosen.path.c_str());
  if (handle == nullptr) {
    throw std::runtime_error("spacemouse: could not open " + name + " at " + chosen.path + " (" +
                             Narrow(hid_error(nullptr)) +
                             "); is it plugged in, and does /dev/hidraw* allow you to read it? " +
                             kUdevHint);
  }
  // The report descriptor: from hidapi, else sysfs, else the built-in one of the model's style.
  std::vector<std::uint8_t> bytes;
  SpaceMouseDescriptorSource source = SpaceMouseDescriptorSource::kNone;
#ifdef HT_HIDAPI_HAS_GET_REPORT_DESCRIPTOR
  {
    std::vector<std::uint8_t> buf(HID_API_MAX_REPORT_DESCRIPTOR_SIZE);
    const int n = hid_get_report_descriptor(handle, buf.data(), buf.size());
    if (n > 0) {
      buf.resize(static_cast<std::size_t>(n));
      bytes = std::move(buf);
      source = SpaceMouseDescriptorSource::kHidapi;
    }
  }
#endif
  if (bytes.empty()) {
    bytes = ReadSysfsDescriptor(chosen.path);
    if (!bytes.empty()) source = SpaceMouseDescriptorSource::kSysfs;
  }
  bool accept_longer = false;
  if (bytes.empty()) {
    if (chosen.model == nullptr || chosen.model->style == SpaceMouseReportStyle::kNone) {
      hid_close(handle);
      throw std::runtime_error("spacemouse: cannot read the report descriptor of " + name + " at " +
                               chosen.path +
                               " (hidapi " HID_API_VERSION_STR
                               " has no hid_get_report_descriptor and sysfs has none) and it is "
                               "not a known 6-DoF model");
    }
    const auto builtin = BuiltInSpaceMouseDescriptor(chosen.model->style);
    bytes.assign(builtin.begin(), builtin.end());
    source = SpaceMouseDescriptorSource::kBuiltIn;
    accept_longer = true;
  }
  const HidReportDescriptor descriptor = ParseHidReportDescriptor(bytes);
  std::optional<SpaceMouseReportParser> parser;
  try {
    parser.emplace(descriptor, config_.axis_map, accept_longer);
  } catch (const std::invalid_argument& e) {
    hid_close(handle);
    throw std::runtime_error("spacemouse: " + name + " at " + chosen.path + ": " + e.what() +
                             (descriptor.complete ? "" : "; descriptor: " + descriptor.problem));
  }
  handle_ = handle;
  model_name_ = name;
  device_path_ = chosen.path;
  descriptor_source_ = source;
  descriptor_problem_ = descriptor.problem;
  mapper_.Reset();
  latest_ = {};
  SpaceMouseSample stale;
  while (handoff_.Read(stale)) {
  }
  stop_.store(false, std::memory_order_relaxed);
  lost_.store(false, std::memory_order_relaxed);
  read_errors_.store(0, std::memory_order_relaxed);
  reader_ = std::thread(&SpaceMouseDevice::ReaderLoop, this, std::move(*parser));
  open_ = true;
}

void SpaceMouseDevice::ReaderLoop(SpaceMouseReportParser parser) noexcept {
  std::array<std::uint8_t, 4097> buf{};  // the longest report the parser accepts, plus its id
  while (!stop_.load(std::memory_order_acquire)) {
    const int n = hid_read_timeout(handle_, buf.data(), buf.size(), config_.read_timeout_ms);
    if (n < 0) {  // unplugged or revoked: stop; ReadState reports the loss
      read_errors_.fetch_add(1, std::memory_order_relaxed);
      lost_.store(true, std::memory_order_release);
      return;
    }
    if (n == 0) continue;
    const std::int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::steady_clock::now().time_since_epoch())
                                    .count();
    parser.Feed(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)), now_ns);
    handoff_.Write(parser.sample());
  }
}

void SpaceMouseDevice::Close() noexcept {
  stop_.store(true, std::memory_order_release);
  if (reader_.joinable()) reader_.join();
  if (handle_ != nullptr) {
    hid_close(handle_);
    handle_ = nullptr;
  }
  open_ = false;
}

bool SpaceMouseDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_) return false;
  handoff_.Read(latest_);
  mapper_.Step(latest_, now_ns, state);
  return !lost_.load(std::memory_order_acquire) && IsFiniteRigidTransform(state.X_MH) &&
         IsFinite(state.V_MH_M);
}

bool SpaceMouseDevice::WriteWrench(const Wrench&, std::int64_t) noexcept { return true; }

}  // namespace ht
