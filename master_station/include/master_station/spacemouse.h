#pragma once
// 3Dconnexion SpaceMouse family as an input-only 6-DoF device, through hidapi (hidraw backend).
//
// The pipeline, one stage per declaration below:
//   1. ParseHidReportDescriptor: HID 1.11 §6.2.2 item parser → per input report, the fields with
//      bit offset, size, logical range, usage and the Relative flag.
//   2. SpaceMouseReportParser: raw input reports (first byte = report id) → the latest six axes,
//      normalized to [-1, 1] by the descriptor's logical range, and the buttons. The same code
//      parses bytes from hid_read_timeout and bytes from the tests.
//   3. kSpaceMouseModels: VID/PID facts from spacenavd's device table (6-DoF or not, report style).
//   4. ShapeSpaceMouseAxes + SpaceMousePoseMapper: dead zone, hold-then-decay of stale axes, and
//      the mapping of cap deflection to the handle pose X_MH (rate control or position control).
//   5. SpaceMouseDevice: the HapticDevice (enumerate, open, reader thread, lock-free handoff).
//
// Frames. The HID axes (usages X, Y, Z, Rx, Ry, Rz) are in the device's own frame D: x to the
// right, y towards the user, z down, right-handed (PySpaceMouse negates y and z to get "forward"
// and "up"). Frame M of this project is x right, y forward (away from the user), z up: the proper
// rotation by pi about x, so that M = (x, -y, -z) for the translations and, being a proper
// rotation, also (rx, -ry, -rz) for the rotation vector. spacenavd's SWAPYZ|INVYZ, (x, -z, -y) for
// both, is a reflection (det = -1): it yields its own left-handed frame and is not used here.
// Every device in the table uses the same D (PySpaceMouse lists identical signs for all 13 of its
// devices), so one SpaceMouseAxisMap serves all; it is configurable in case a firmware differs.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"

struct hid_device_;  // hidapi's opaque device (hidapi.h: typedef struct hid_device_ hid_device).

namespace ht {

// ------------------------------------------------------------------------------------------------
// 1. HID report descriptor
// ------------------------------------------------------------------------------------------------

/// HID usage pages and usages used here (HID Usage Tables 1.12 §4, §12).
inline constexpr std::uint16_t kHidPageGenericDesktop = 0x01;
inline constexpr std::uint16_t kHidPageButton = 0x09;
inline constexpr std::uint16_t kHidUsageMultiAxisController = 0x08;
inline constexpr std::uint16_t kHidUsageX = 0x30;  ///< X, Y, Z, Rx, Ry, Rz are 0x30..0x35.

/// One data value of an input report as a report descriptor lays it out.
struct HidField {
  std::uint32_t bit_offset = 0;  ///< First bit after the report-id byte, LSB-first (HID §5.8).
  std::uint32_t bit_size = 0;    ///< Report Size, 1..32 bits.
  std::int64_t logical_min = 0;  ///< Logical Minimum; the value is signed when this is < 0.
  std::int64_t logical_max = 0;  ///< Logical Maximum.
  std::uint16_t usage_page = 0;
  /// Variable field: its usage. Array field: the usage that value `logical_min` selects.
  std::uint16_t usage = 0;
  std::uint16_t usage_max = 0;  ///< Array field: the last usage of its range; = usage otherwise.
  bool relative = false;        ///< Input item flag bit 2 (Relative) was set.
  bool array = false;           ///< Input item flag bit 1 clear: the value is a usage index.
};

/// One input report: its id and the fields in it.
struct HidInputReport {
  std::uint8_t report_id = 0;    ///< 0 when the descriptor declares no report ids.
  std::uint32_t size_bits = 0;   ///< Payload bits, padding included, report-id byte excluded.
  std::vector<HidField> fields;  ///< Data fields in bit order; constant (padding) items omitted.
  /// Payload bytes that follow the report-id byte.
  std::size_t payload_bytes() const noexcept { return (size_bits + 7u) / 8u; }
};

/// What ParseHidReportDescriptor found. Output and feature reports are parsed (their items change
/// the global state) but not listed.
struct HidReportDescriptor {
  bool uses_report_ids = false;               ///< Input reports then begin with a report-id byte.
  std::vector<HidInputReport> input_reports;  ///< In order of first appearance.
  /// False when parsing stopped early (truncated or malformed item) or collections were left
  /// open; `problem` then says what and at which byte offset. The reports parsed before the
  /// problem are kept, without the main item that was cut.
  bool complete = true;
  std::string problem;
  std::size_t bytes_parsed = 0;  ///< Bytes covered by whole items.
  /// The input report with that id, or nullptr.
  const HidInputReport* FindInput(std::uint8_t report_id) const noexcept;
};

/// Parses a HID report descriptor (HID 1.11 §6.2.2): short items of the main, global and local
/// types; Push/Pop; Report ID/Size/Count; Logical Minimum/Maximum (sign-extended; the maximum is
/// read unsigned when the minimum is not negative, as Linux hid-core does); Usage Page, Usage
/// (extended 32-bit usages too), Usage Minimum/Maximum; Input flags Constant/Array/Relative. Long
/// items are skipped. Never throws for bad content and never reads out of bounds: a truncated or
/// malformed descriptor gives a result with complete == false and a problem message. Bounds that
/// end parsing: Report Size > 32, Report Count > 4096, Report ID 0, Push deeper than 16, Pop or
/// End Collection without a match, a report longer than 4096 bytes, more than 4096 fields.
HidReportDescriptor ParseHidReportDescriptor(std::span<const std::uint8_t> descriptor);

/// Reads `field` from `payload` (the bytes after the report id), sign-extending when the field's
/// logical minimum is negative. Returns 0 when the field lies beyond the payload.
std::int64_t HidFieldValue(const HidField& field, std::span<const std::uint8_t> payload) noexcept;

// ------------------------------------------------------------------------------------------------
// 2. Report parser
// ------------------------------------------------------------------------------------------------

/// Axis order used for deflections throughout: translations then rotations.
enum SpaceMouseAxis : int { kTx = 0, kTy, kTz, kRx, kRy, kRz };

/// From the HID axes (frame D, order X Y Z Rx Ry Rz) to frame M: m[i] = sign[i] * d[source[i]].
/// The default is the rotation by pi about x described at the top of this file.
struct SpaceMouseAxisMap {
  std::array<int, 6> source{0, 1, 2, 3, 4, 5};
  std::array<double, 6> sign{1.0, -1.0, -1.0, 1.0, -1.0, -1.0};
};

/// Counts of what the report parser did with the reports it was fed.
struct SpaceMouseReportCounts {
  std::uint64_t accepted = 0;           ///< Parsed (known id, right length).
  std::uint64_t unknown_report_id = 0;  ///< Dropped: no such input report in the descriptor.
  std::uint64_t wrong_length = 0;       ///< Dropped: empty, or not the descriptor's length.
};

/// The latest state of the cap and the buttons. Trivially copyable (crosses threads).
struct SpaceMouseSample {
  /// Cap deflection in frame M, order SpaceMouseAxis, each in [-1, 1] (full scale of the
  /// descriptor's logical range). Translation deflections push the handle along +x right,
  /// +y forward, +z up; rotation deflections are a rotation vector direction in M.
  std::array<double, 6> axes{};
  /// steady-clock time (ns) of the report that last set each axis; 0 = never set.
  std::array<std::int64_t, 6> axis_time_ns{};
  std::uint32_t buttons = 0;  ///< Bit k set = HID button usage k + 1 pressed (usages 1..32).
  SpaceMouseReportCounts counts;
};

/// Parses raw input reports with the layout a report descriptor gives. Handles both report styles
/// of the family: translation (id 1) and rotation (id 2) in separate reports, or all six axes in
/// one report (id 1, 12 bytes of payload), and any other layout the descriptor describes.
/// Axis values are normalized by the descriptor's logical range: (v - centre) / half-range,
/// clamped to [-1, 1]. The Relative flag is ignored: 3Dconnexion firmwares flag the axes Relative
/// but send absolute deflections (the reason for the Linux hid-lg rel→abs fixup).
class SpaceMouseReportParser {
 public:
  /// Throws std::invalid_argument when no input report carries one of the six axes
  /// (Generic Desktop X..Rz) as a variable field, naming the missing axis. With
  /// `accept_longer_reports`, reports longer than the descriptor says are parsed and their extra
  /// bytes ignored (used with the built-in descriptors, whose button reports may be shorter than
  /// the real device's); shorter ones are always dropped.
  explicit SpaceMouseReportParser(const HidReportDescriptor& descriptor,
                                  const SpaceMouseAxisMap& axis_map = {},
                                  bool accept_longer_reports = false);

  /// Feeds one raw input report: report-id byte first when the descriptor uses report ids, then
  /// the payload. `now_ns` (steady clock) stamps the axes it sets. Returns false and counts the
  /// report when it is dropped (unknown id, wrong length). No allocation.
  bool Feed(std::span<const std::uint8_t> report, std::int64_t now_ns) noexcept;

  /// The state after the reports fed so far.
  const SpaceMouseSample& sample() const noexcept { return sample_; }
  /// The last raw HID axis values in logical units, HID order X Y Z Rx Ry Rz (frame D).
  const std::array<std::int64_t, 6>& raw_axes() const noexcept { return raw_axes_; }

 private:
  struct AxisBinding {
    HidField field;
    int hid_axis = 0;  // 0..5 = X..Rz
  };
  struct ButtonBinding {
    HidField field;
  };
  struct Layout {
    std::uint8_t report_id = 0;
    std::size_t payload_bytes = 0;
    std::vector<AxisBinding> axes;
    std::vector<ButtonBinding> buttons;
    bool has_buttons = false;
    std::uint32_t button_mask = 0;  // buttons currently pressed according to this report
  };

  std::vector<Layout> layouts_;
  std::array<std::int16_t, 256> layout_of_id_{};  // -1 = unknown id
  bool uses_report_ids_ = false;
  bool accept_longer_reports_ = false;
  SpaceMouseAxisMap axis_map_;
  std::array<int, 6> m_axis_of_hid_axis_{};  // inverse of axis_map_.source
  SpaceMouseSample sample_;
  std::array<std::int64_t, 6> raw_axes_{};
};

// ------------------------------------------------------------------------------------------------
// 3. Device table
// ------------------------------------------------------------------------------------------------

/// How a model sends its axes.
enum class SpaceMouseReportStyle : std::uint8_t {
  kSplit,    ///< Report 1 = X Y Z, report 2 = Rx Ry Rz, report 3 = buttons (16-bit LE axes).
  kSixAxis,  ///< Report 1 = X Y Z Rx Ry Rz (12 bytes), report 3 = buttons.
  kNone,     ///< Not a 6-DoF device.
};

/// One USB/Bluetooth model of the 3Dconnexion family.
struct SpaceMouseModel {
  std::uint16_t vendor_id;
  std::uint16_t product_id;
  std::string_view name;
  bool six_dof;  ///< False for the devices spacenavd blacklists (CadMouse, keyboards...).
  SpaceMouseReportStyle style;
  /// True when PySpaceMouse's devices.toml lists the model's report layout; otherwise the style
  /// is inferred (Logitech-era 046d = split, 256f wireless = six-axis) and only used when the
  /// real descriptor cannot be read.
  bool style_listed;
};

/// VID/PID facts from spacenavd src/dev.c (usbdb[] and the blacklist, via
/// ../shared/data/spacemouse/spacenavd_usb_device_table.csv), plus 256f:c652 (Universal
/// Receiver), which only PySpaceMouse lists. Where the two disagree, spacenavd wins: 256f:c641
/// is "SpaceMouse USB" (6-DoF) in PySpaceMouse but blacklisted ("scout(?)") in spacenavd, so it is
/// not enumerated here.
inline constexpr std::array<SpaceMouseModel, 34> kSpaceMouseModels{{
    {0x046d, 0xc603, "SpaceMouse Plus XT", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc605, "CadMan", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc606, "SpaceMouse Classic", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc621, "SpaceBall 5000", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc623, "Space Traveller", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc625, "Space Pilot", true, SpaceMouseReportStyle::kSplit, true},
    {0x046d, 0xc626, "Space Navigator", true, SpaceMouseReportStyle::kSplit, true},
    {0x046d, 0xc627, "Space Explorer", true, SpaceMouseReportStyle::kSplit, true},
    {0x046d, 0xc628, "Space Navigator for Notebooks", true, SpaceMouseReportStyle::kSplit, false},
    {0x046d, 0xc629, "Space Pilot Pro", true, SpaceMouseReportStyle::kSplit, true},
    {0x046d, 0xc62b, "SpaceMouse Pro", true, SpaceMouseReportStyle::kSplit, true},
    {0x046d, 0xc640, "NuLOOQ", true, SpaceMouseReportStyle::kSplit, false},
    {0x256f, 0xc62e, "SpaceMouse Wireless (USB cable)", true, SpaceMouseReportStyle::kSixAxis,
     true},
    {0x256f, 0xc62f, "SpaceMouse Wireless receiver", true, SpaceMouseReportStyle::kSixAxis, false},
    {0x256f, 0xc631, "SpaceMouse Pro Wireless", true, SpaceMouseReportStyle::kSixAxis, false},
    {0x256f, 0xc632, "SpaceMouse Pro Wireless receiver", true, SpaceMouseReportStyle::kSixAxis,
     true},
    {0x256f, 0xc633, "SpaceMouse Enterprise", true, SpaceMouseReportStyle::kSixAxis, true},
    {0x256f, 0xc635, "SpaceMouse Compact", true, SpaceMouseReportStyle::kSplit, true},
    {0x256f, 0xc636, "SpaceMouse Module", true, SpaceMouseReportStyle::kSixAxis, false},
    {0x256f, 0xc638, "SpaceMouse Pro Wireless BT (USB)", true, SpaceMouseReportStyle::kSixAxis,
     true},
    {0x256f, 0xc63a, "SpaceMouse Wireless (Bluetooth)", true, SpaceMouseReportStyle::kSixAxis,
     true},
    {0x256f, 0xc652, "Universal Receiver", true, SpaceMouseReportStyle::kSixAxis, true},
    {0x256f, 0xc650, "CadMouse", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc651, "CadMouse Wireless", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc654, "CadMouse Pro Wireless", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc655, "CadMouse Compact", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc656, "CadMouse Pro", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc657, "CadMouse Pro Wireless Left", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc658, "CadMouse Compact Wireless", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc664, "Keyboard Pro", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc668, "Keyboard Pro (newer version)", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc665, "Numpad Pro", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc62c, "lipari(?)", false, SpaceMouseReportStyle::kNone, false},
    {0x256f, 0xc641, "scout(?)", false, SpaceMouseReportStyle::kNone, false},
}};

/// The table entry for a VID/PID, or nullptr.
const SpaceMouseModel* FindSpaceMouseModel(std::uint16_t vendor_id,
                                           std::uint16_t product_id) noexcept;

/// A minimal report descriptor for a report style, used when the device's own cannot be read
/// (hidapi < 0.14 has no hid_get_report_descriptor, and no sysfs): the axes as the real
/// descriptors give them (16-bit, -350..350) and the first 16 buttons in report 3. Empty span for
/// kNone. Not a copy of a device's descriptor: written from the layout facts.
std::span<const std::uint8_t> BuiltInSpaceMouseDescriptor(SpaceMouseReportStyle style) noexcept;

// ------------------------------------------------------------------------------------------------
// 4. Shaping and mapping
// ------------------------------------------------------------------------------------------------

/// How deflection moves the handle.
enum class SpaceMouseControlMode {
  kRate,      ///< Deflection → twist, integrated (the usual SpaceMouse use).
  kPosition,  ///< Deflection → offset from the workspace centre (springs back when released).
};

/// Settings of SpaceMouseDevice and SpaceMousePoseMapper. ValidateSpaceMouseConfig says which
/// value is wrong.
struct SpaceMouseConfig {
  /// hidapi path (e.g. /dev/hidraw3) to open; empty = the first 6-DoF model of the table found.
  std::string path;
  /// Dead zone as a fraction of full deflection, [0, 1): |d| below it reads 0, and the rest is
  /// rescaled so that the output still reaches 1 and is continuous at the edge.
  double dead_zone = 0.05;
  /// An axis not refreshed by a report for `hold_s` then ramps linearly to 0 over `decay_s`.
  /// 3Dconnexion firmwares send an all-zero report when the cap is released (observed:
  /// `01 00 00 00 00 00 00`) and keep reporting while it is deflected (the sensor noise changes
  /// the value), so the hold covers short quiet spells; the decay stops a runaway under rate
  /// control when reports stop for good (unplug, wireless drop-out, a firmware that goes quiet
  /// while deflected). Buttons are sent on change only and are kept.
  double hold_s = 0.5;
  double decay_s = 0.2;
  SpaceMouseControlMode mode = SpaceMouseControlMode::kRate;
  double v_max_m_per_s = 0.1;    ///< Rate control: linear speed at full deflection (m/s).
  double w_max_rad_per_s = 1.0;  ///< Rate control: angular speed at full deflection (rad/s).
  /// Largest rotation of H from the initial orientation (rad), (0, pi]: the clamp under rate
  /// control, the rotation at full deflection under position control.
  double max_rotation_rad = 0.5;
  /// Half sizes of the box the handle origin stays in, centred on M's origin (m). Under position
  /// control, full deflection reaches its faces.
  glm::dvec3 workspace_half_extents_m{0.1, 0.1, 0.1};
  /// Longest integration step (s): a longer gap between ReadState calls (a stall) integrates only
  /// this much, so that the handle does not jump.
  double max_step_s = 0.05;
  SpaceMouseAxisMap axis_map;
  int read_timeout_ms = 20;  ///< Reader thread's hid_read_timeout (ms), (0, 1000].
};

/// Throws std::invalid_argument naming the first bad value of `config`.
void ValidateSpaceMouseConfig(const SpaceMouseConfig& config);

/// Dead zone on one normalized value: 0 inside ±dead_zone, else sign(v)(|v| - dz)/(1 - dz).
double ApplySpaceMouseDeadZone(double v, double dead_zone) noexcept;

/// Factor on an axis whose last report is `age_s` old: 1 up to hold_s, then linear to 0 at
/// hold_s + decay_s (a step at hold_s when decay_s is 0).
double SpaceMouseStalenessGain(double age_s, double hold_s, double decay_s) noexcept;

/// The deflections to use at `now_ns`: staleness gain times dead-zoned axes (frame M, order
/// SpaceMouseAxis, each in [-1, 1]). Axes never set read 0.
std::array<double, 6> ShapeSpaceMouseAxes(const SpaceMouseSample& sample, std::int64_t now_ns,
                                          const SpaceMouseConfig& config) noexcept;

/// Turns shaped deflections into the handle pose X_MH and twist V_MH_M.
/// Rate control: v = v_max (d_tx, d_ty, d_tz) m/s and w = w_max (d_rx, d_ry, d_rz) rad/s in M,
/// integrated over the real time since the previous Step (at most max_step_s): p_MH += v dt, then
/// clamped per axis to ±workspace_half_extents_m; R_MH ← exp(w dt) R_MH, then its rotation
/// vector clamped to max_rotation_rad. Position control: p_MH = d_t ∘ half extents,
/// R_MH = exp(max_rotation_rad d_r) with |d_r| limited to 1. In both, V_MH_M is the pose change
/// over dt (after the clamps), 0 on the first Step.
class SpaceMousePoseMapper {
 public:
  /// Throws std::invalid_argument from ValidateSpaceMouseConfig.
  explicit SpaceMousePoseMapper(const SpaceMouseConfig& config);
  /// Back to X_MH = identity, time restarts at the next Step.
  void Reset() noexcept;
  /// Advances to `now_ns` (steady clock) with `sample`; writes X_MH, V_MH_M, buttons, timestamp.
  /// A time earlier than the previous Step counts as dt = 0.
  void Step(const SpaceMouseSample& sample, std::int64_t now_ns, DeviceState& state) noexcept;
  const RigidTransform& X_MH() const noexcept { return X_MH_; }

 private:
  SpaceMouseConfig config_;
  RigidTransform X_MH_;
  bool started_ = false;
  std::int64_t last_ns_ = 0;
};

// ------------------------------------------------------------------------------------------------
// 5. The device
// ------------------------------------------------------------------------------------------------

/// Where the report descriptor in use came from.
enum class SpaceMouseDescriptorSource {
  kNone,     ///< Not opened.
  kHidapi,   ///< hid_get_report_descriptor (hidapi >= 0.14).
  kSysfs,    ///< /sys/class/hidraw/<node>/device/report_descriptor (Linux hidraw).
  kBuiltIn,  ///< BuiltInSpaceMouseDescriptor of the model's style (neither of the above).
};

/// A 3Dconnexion 6-DoF mouse as a HapticDevice: input only (dof_out 0, max force 0).
/// Open enumerates the table's models with hid_enumerate (or opens config.path), reads the report
/// descriptor (hidapi ≥ 0.14: hid_get_report_descriptor; hidapi 0.13 as on Debian 12 lacks it,
/// so sysfs; else the built-in descriptor of the model's style), and starts a reader thread that
/// blocks in hid_read_timeout, parses each report and publishes the newest SpaceMouseSample
/// through a TripleBuffer. ReadState copies the newest sample and steps the SpaceMousePoseMapper:
/// it never blocks or allocates.
class SpaceMouseDevice final : public HapticDevice {
 public:
  /// Throws std::invalid_argument from ValidateSpaceMouseConfig.
  explicit SpaceMouseDevice(const SpaceMouseConfig& config = {});
  ~SpaceMouseDevice() override;
  SpaceMouseDevice(const SpaceMouseDevice&) = delete;
  SpaceMouseDevice& operator=(const SpaceMouseDevice&) = delete;

  /// Input only: dof_in 6, dof_out 0, no force, torque or stiffness; workspace from the config.
  DeviceCapabilities capabilities() const override;
  /// Throws std::runtime_error when no table device is found ("no 3Dconnexion device found
  /// (looked for VID:PID ...); ... see deploy/udev/70-haptic-spacemouse.rules"), when it cannot
  /// be opened (permissions), or when its descriptor has no six axes.
  void Open() override;
  /// Stops the reader thread and closes the device. No force output, so nothing to zero.
  void Close() noexcept override;
  /// Pose and twist of the handle at `now_ns` from the newest reports. False when not open or
  /// after the device was lost (read error; the pose then holds while the axes decay).
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  /// No force output: accepts any wrench and ignores it (returns true).
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  /// Model opened ("" before Open), its hidapi path, and where its descriptor came from.
  const std::string& model_name() const noexcept { return model_name_; }
  const std::string& device_path() const noexcept { return device_path_; }
  SpaceMouseDescriptorSource descriptor_source() const noexcept { return descriptor_source_; }
  /// The parsed descriptor's problem, if it was incomplete ("" otherwise).
  const std::string& descriptor_problem() const noexcept { return descriptor_problem_; }
  /// Report counts as of the last ReadState.
  const SpaceMouseReportCounts& report_counts() const noexcept { return latest_.counts; }
  /// hid_read errors seen by the reader thread (it stops at the first).
  std::uint64_t read_errors() const noexcept {
    return read_errors_.load(std::memory_order_relaxed);
  }

 private:
  void ReaderLoop(SpaceMouseReportParser parser) noexcept;

  SpaceMouseConfig config_;
  SpaceMousePoseMapper mapper_;
  hid_device_* handle_ = nullptr;
  std::thread reader_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> lost_{false};
  std::atomic<std::uint64_t> read_errors_{0};
  TripleBuffer<SpaceMouseSample> handoff_;
  SpaceMouseSample latest_;  // owned by the ReadState thread
  bool open_ = false;
  std::string model_name_;
  std::string device_path_;
  SpaceMouseDescriptorSource descriptor_source_ = SpaceMouseDescriptorSource::kNone;
  std::string descriptor_problem_;
};

}  // namespace ht
