#pragma once
// Perceptual deadband on both streams of a session (docs/DESIGN.md §6, docs/deadband.md).
//
// The idea is the kinesthetic codecs' (Hinterseer, Hirche, Chaudhuri, Steinbach, Buss,
// "Perception-based data reduction and transmission of haptic data in telepresence and
// teleaction systems", IEEE Trans. Signal Processing 56(2), 2008; IEEE 1918.1.1): a sample is sent
// only when it differs from what the receiver already predicts by more than a Weber fraction k of
// the value (a just-noticeable difference), with an absolute floor so that values near zero do
// not send on noise, and a keep-alive so that the receiver can tell a quiet stream from a lost one.
//
// Here the prediction on each side is the one the receiver really makes:
// - tool states (operator → remote node): the remote node extrapolates the last tool state at
//   its own twist (ExtrapolatePose); the operator sends when its tool has left that prediction;
// - contact models (remote node → operator): the operator renders every tick from the model it
//   holds, so a new model is sent when the held one, evaluated at the new model's pose q0,
//   renders a wrench or a stiffness that differs beyond the deadband, or when the number of
//   contacts changed (model-mediated teleoperation's model update rule: Xu, Cizmeci, Schuwerk,
//   Steinbach, "Model-mediated teleoperation: toward stable and transparent teleoperation
//   systems", IEEE Access 4, 2016).
// Both deciders are noexcept and allocation-free.

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>

#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"

namespace ht {

/// The tool pose a receiver predicts `dt_s` seconds after a tool state X_WT with twist V_WT_W
/// (linear velocity of T's origin and angular velocity, both along W): constant twist, the
/// rotation about T's origin, R(t) = exp([ω]ₓ dt)·R. dt ≤ 0 returns X_WT.
RigidTransform ExtrapolatePose(const RigidTransform& X_WT, const Twist& V_WT_W,
                               double dt_s) noexcept;

/// Why a deadband sent (or did not send) a sample. Counted per reason in the summaries.
enum class DeadbandReason : std::uint8_t {
  kNotSent = 0,      ///< inside the deadband: not sent
  kOff,              ///< the deadband is off (k = 0): every sample is sent
  kFirst,            ///< nothing sent yet
  kKeepAlive,        ///< nothing sent for the keep-alive period
  kPosition,         ///< tool position left the prediction
  kRotation,         ///< tool rotation left the prediction
  kVelocity,         ///< tool linear velocity changed (with the velocity criterion)
  kAngularVelocity,  ///< tool angular velocity changed (with the velocity criterion)
  kContactCount,     ///< the number of contacts changed
  kForce,            ///< the rendered force changed
  kTorque,           ///< the rendered torque changed
  kStiffness,        ///< the rendered stiffness (translational or rotational block) changed
  kDepth,            ///< a contact's depth at the tool left its depth at the prediction
  kDepthField,       ///< a contact names a depth field the held model does not
};
inline constexpr int kDeadbandReasonCount = static_cast<int>(DeadbandReason::kDepthField) + 1;
/// Decisions per reason, indexed by DeadbandReason.
using DeadbandCounts = std::array<std::uint64_t, kDeadbandReasonCount>;
/// {"reason": count} for the reasons with a non-zero count, for summaries.
nlohmann::json ToJson(const DeadbandCounts& counts);
namespace wire {
struct DeadbandTerms;  // messages.h
}  // namespace wire
/// A session's agreed terms for both sides' summaries: {"tool_state_deadband", "model_deadband"
/// (Weber fractions), "tool_state_keepalive_ms", "model_keepalive_ms"}; each side adds its own
/// counts to the object.
nlohmann::json ToJson(const wire::DeadbandTerms& terms);
/// "not_sent", "off", "first", "keep_alive", "position", ... for summaries.
const char* ToString(DeadbandReason reason) noexcept;

/// Tool-state deadband. k = weber_fraction; every threshold is max(k·|reference value|, k·floor
/// scale), i.e. the absolute floors scale with k too, so one number sets the deadband.
struct ToolStateDeadbandConfig {
  double weber_fraction = 0.0;  ///< k ∈ [0, 1); 0 = off (every tool state is sent)
  /// Floor scales: the floor of each threshold is k times these (position m, rotation rad,
  /// linear velocity m/s, angular velocity rad/s).
  double position_floor_scale_m = 2e-3;
  double rotation_floor_scale_rad = 0.02;
  double linear_velocity_floor_scale_m_per_s = 0.02;
  double angular_velocity_floor_scale_rad_per_s = 0.2;
  /// Floor scales while the tool is near contact (the held contact model has contacts: Decide's
  /// near_contact), in place of position_floor_scale_m and rotation_floor_scale_rad (m, rad).
  /// In contact the remote node linearizes its model at the pose it predicts, and the contact
  /// appears and vanishes within the penetration depth (about 0.1 mm on the fig75 block): with
  /// the free-space position floor (0.2 mm at k = 0.1) a tool bobbing by less than that was
  /// modelled where it was not, and the models so made kept a resting block bouncing at 45–50 Hz
  /// (docs/deadband.md). At k = 0.1 the position floor is 20 µm in contact.
  /// The rotation floor stays the free-space one by default: shrinking it to 0.2 mrad also kept
  /// the block calm, at twice the tool states of the position floor alone (docs/deadband.md).
  double contact_position_floor_scale_m = 2e-4;
  double contact_rotation_floor_scale_rad = 0.02;
  /// The contact floors stay for this long after the last tool state decided near contact (s,
  /// ≥ 0). A block that bounces off the surface gets a model with no contacts at the top of its
  /// bounce; with the free-space floor at once, it then fell 0.2 mm into the gear before the next
  /// tool state went out, and the next model pushed 1.7 N (1 in 17 fig75 loopback runs landed in
  /// 3–4 such bounces). Half a second covers a bounce and a lift-off.
  double contact_floor_hold_s = 0.5;
  /// Depth criterion near contact, 0 = off: with the held contact
  /// model given to Decide, a tool state is also sent when, for a contact of that model, the
  /// depth it gives at the tool's pose and at the remote node's prediction differ by more than
  /// max(k·δ, k·this) (m; δ the contact's depth at the tool, ContactDepthAt). The remote node
  /// linearizes each model at the pose it predicts, so this bounds the depth error of that
  /// linearization point where the held model says the depth changes fast (a ridge's flank, a
  /// rotation about a long lever), and nowhere else. Contacts whose depth is below −this at both
  /// poses are not looked at. The velocity-adaptive factor does not widen it (a depth error is felt
  /// as such at any speed).
  double contact_depth_floor_scale_m = 0.0;
  double keepalive_s = 0.1;  ///< longest time between two tool states sent (s, > 0)
  /// Also send when the twist itself changed beyond the deadband (Weber fraction of the last
  /// twist sent). Off by default: a changed twist already shows as pose error against the
  /// receiver's extrapolation within a few ticks, and on the fig75 and kinesthetic runs the
  /// twist criterion sent 3–4× more tool states for no gain in force error (docs/deadband.md).

  bool velocity_criterion = false;
  /// Velocity-adaptive deadband: the position and rotation floors widen by (1 + |v|/v_ref) while
  /// the tool moves fast (humans notice position errors less during fast motion).
  bool velocity_adaptive = false;
  double adaptive_speed_ref_m_per_s = 0.05;  ///< v_ref of the velocity-adaptive floors (m/s)
  /// Throws std::invalid_argument naming the field when a value is out of range or not finite.
  void Validate() const;
};

/// Decides which tool states to send (operator side). Thresholds, with (p_s, R_s, v_s, ω_s) the
/// last state sent at t_s and (p̂, R̂) = ExtrapolatePose(last sent, t − t_s):
///   position  |p − p̂| > max(k·|p − p_s|, k·floor_p·a)
///   rotation  ∠(R R̂ᵀ) > max(k·∠(R R_sᵀ), k·floor_θ·a)
/// (floor_p, floor_θ the contact floor scales while near contact or within contact_floor_hold_s
/// of the last decision near contact, else the free-space ones)
///   depth     |δ_i(q) − δ_i(q̂)| > max(k·max(δ_i(q), 0), k·floor_δ) for a contact i of the held
///             model (near contact, with contact_depth_floor_scale_m = floor_δ > 0 and a model),
///   velocity  |v − v_s| > max(k·|v_s|, k·floor_v), the same for ω (with velocity_criterion),
/// a = 1 + |v|/v_ref with velocity_adaptive, else 1; plus the keep-alive.
class ToolStateDeadband {
 public:
  explicit ToolStateDeadband(const ToolStateDeadbandConfig& config) : config_(config) {}
  /// The decision for the tool state (X_WT, V_WT_W) at time t_ns (ns, the sender's steady
  /// clock). When it returns anything but kNotSent, the state counts as sent (the caller sends
  /// it). `near_contact`: the operator's held contact model has contacts (the contact floors
  /// apply, and go on applying for contact_floor_hold_s after the last such call).
  /// `held_model` (optional): the newest contact model the operator received (what it renders
  /// from, or blends towards), for the depth criterion (contact_depth_floor_scale_m).
  DeadbandReason Decide(const RigidTransform& X_WT, const Twist& V_WT_W, std::int64_t t_ns,
                        bool near_contact = false,
                        const ContactModel* held_model = nullptr) noexcept;
  /// Records a state the caller sent without asking (e.g. a keep-alive while the loop is idle),
  /// so that the next decision predicts from it.
  void NoteSent(const RigidTransform& X_WT, const Twist& V_WT_W, std::int64_t t_ns) noexcept;
  /// A new session's terms: the new configuration, and the last state sent forgotten (the next
  /// one is sent). The counts go on across sessions.
  void Configure(const ToolStateDeadbandConfig& config) noexcept {
    config_ = config;
    have_sent_ = false;
  }
  const ToolStateDeadbandConfig& config() const noexcept { return config_; }
  /// Decisions so far, over every session.
  const DeadbandCounts& counts() const noexcept { return counts_; }

 private:
  ToolStateDeadbandConfig config_;
  bool have_sent_ = false;
  RigidTransform X_sent_;
  Twist V_sent_;
  std::int64_t t_sent_ns_ = 0;
  bool have_near_contact_ = false;
  std::int64_t t_near_contact_ns_ = 0;  ///< the last decision with near_contact
  DeadbandCounts counts_{};
};

/// Contact-model deadband. Thresholds are max(k·|value|, k·floor scale).
struct ContactModelDeadbandConfig {
  double weber_fraction = 0.0;                   ///< k ∈ [0, 1); 0 = off (every model is sent)
  double force_floor_scale_n = 1.0;              ///< floor of the force threshold, ÷ k (N)
  double torque_floor_scale_nm = 0.05;           ///< floor of the torque threshold, ÷ k (N·m)
  double stiffness_floor_scale_n_per_m = 200.0;  ///< translational block of K (N/m)
  double rotational_stiffness_floor_scale_nm_per_rad = 0.2;  ///< rotational block (N·m/rad)
  double keepalive_s = 0.1;  ///< longest time between two models sent (s, > 0)
  /// Throws std::invalid_argument naming the field when a value is out of range or not finite.
  void Validate() const;
};

/// Decides which contact models to send (remote node side). The held model H (the last one sent)
/// is evaluated at the new model M's pose q0 (EvaluateContactModel), which is what the operator
/// renders there; M is sent when
///   the number of contacts differs, or
///   a contact of M names a depth field (ContactLinearization::depth_field_id) that no contact of
///   H names (the operator evaluates a field only while a model it holds names it), or
///   |F_H − F_M| > max(k·|F_M|, k·floor_F) (force; likewise torque), or
///   ‖K_H − K_M‖_F > max(k·‖K_M‖_F, k·floor_K) for K's translational 3×3 block and, separately,
///   its rotational 3×3 block (Frobenius norms; the coupling blocks follow from these two),
/// or the keep-alive has passed. F_M and K_M are M evaluated at its own q0.
class ContactModelDeadband {
 public:
  explicit ContactModelDeadband(const ContactModelDeadbandConfig& config) : config_(config) {}
  /// The decision for `model` at time t_ns (ns, the remote node's steady clock). When it returns
  /// anything but kNotSent, `model` becomes the held model (the caller sends it).
  /// With `fields` (the sender's kept depth fields, looked up by id), both models are evaluated
  /// with the fields their contacts name (EvaluateContactModel's field overload), as the
  /// operator renders them, so that a model whose contacts name the held model's fields and
  /// whose linearizations are those fields' tangents is not sent again.
  DeadbandReason Decide(const ContactModel& model, std::int64_t t_ns,
                        std::span<const DepthField* const> fields = {}) noexcept;
  /// Records that the held model was sent again at t_ns (a keep-alive): the keep-alive period
  /// starts over.
  void NoteResent(std::int64_t t_ns) noexcept { t_sent_ns_ = t_ns; }
  /// A new session's terms: the new configuration, and the held model forgotten. The counts go
  /// on across sessions.
  void Configure(const ContactModelDeadbandConfig& config) noexcept {
    config_ = config;
    ForgetHeld();
  }
  /// Forgets the held model: the next Decide sends (kFirst), for a change of the model that
  /// Decide does not compare (a new configuration).
  void ForgetHeld() noexcept { have_sent_ = false; }
  const ContactModelDeadbandConfig& config() const noexcept { return config_; }
  /// The last model sent (valid after the first Decide that sent).
  const ContactModel& held() const noexcept { return held_; }
  /// Decisions so far, over every session.
  const DeadbandCounts& counts() const noexcept { return counts_; }

 private:
  ContactModelDeadbandConfig config_;
  bool have_sent_ = false;
  ContactModel held_;
  std::int64_t t_sent_ns_ = 0;
  DeadbandCounts counts_{};
};

}  // namespace ht
