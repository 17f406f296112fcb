#pragma once
// 3Dconnexion SpaceMouse family as an input-only 6-DoF device, through hidapi (hidraw backend).
//
// The pipeline, one stage per declaration group, with the header that holds it:
//   1. ParseHidReportDescriptor (hid_descriptor.h): HID 1.11 §6.2.2 item parser → per input
//      report, the fields with bit offset, size, logical range, usage and the Relative flag.
//   2. SpaceMouseReportParser (spacemouse_report.h): raw input reports (first byte = report id) →
//      the latest six axes, normalized to [-1, 1] by the descriptor's logical range, and the
//      buttons. The same code parses bytes from hid_read_timeout and bytes from the tests.
//   3. kSpaceMouseModels (this file): VID/PID facts from spacenavd's device table (6-DoF or not,
//      report style).
//   4. ShapeSpaceMouseAxes + SpaceMousePoseMapper (spacemouse_pose.h): dead zone, hold-then-decay
//      of stale axes, and the mapping of cap deflection to the handle pose X_MH (rate control or
//      position control).
//   5. SpaceMouseDevice (this file): the HapticDevice (enumerate, open, reader thread, lock-free
//      handoff).
// This header includes the others, so that including it gives the whole backend.
//
// Frames: the HID axes are in the device's own frame D, mapped to M by SpaceMouseAxisMap; see
// spacemouse_report.h.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <thread>

#include "master_station/haptic_device.h"
#include "master_station/hid_descriptor.h"
#include "master_station/lock_free.h"
#include "master_station/spacemouse_pose.h"
#include "master_station/spacemouse_report.h"

struct hid_device_;  // hidapi's opaque device (hidapi.h: typedef struct hid_device_ hid_device).

namespace ht {

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
