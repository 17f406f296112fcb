#include "master_station/experiment.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "master_station/operator_hand.h"

namespace ht {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// The approach of the press experiments (fig75, fig76, fig77): the hand eases down along M's z
// from `start_height_m` above the contact to `press_depth_m` below it over [0, t_approach_s),
// with zero speed at both ends. Phase 0.
HandTarget ApproachTarget(double t, double t_approach_s, double start_height_m,
                          double press_depth_m) noexcept {
  HandTarget out;
  const double s = t / t_approach_s;
  const double span = -press_depth_m - start_height_m;
  out.X_MH.translation.z = start_height_m + span * 0.5 * (1.0 - std::cos(std::numbers::pi * s));
  out.V_MH_M.linear.z =
      span * 0.5 * std::numbers::pi * std::sin(std::numbers::pi * s) / t_approach_s;
  out.phase = 0;
  return out;
}

// What every fixed script (fig75, fig76, fig77) shares: its name, duration and phase names.
class FixedScript : public Experiment {
 public:
  FixedScript(std::string name, double duration_s, std::vector<std::string> phases)
      : name_(std::move(name)), duration_s_(duration_s), phases_(std::move(phases)) {}
  const std::string& name() const noexcept override { return name_; }
  double duration_s() const noexcept override { return duration_s_; }
  const std::vector<std::string>& phase_names() const noexcept override { return phases_; }

 private:
  std::string name_;
  double duration_s_;
  std::vector<std::string> phases_;
};

class Fig75Experiment final : public FixedScript {
 public:
  explicit Fig75Experiment(const Fig75Params& p)
      : FixedScript("fig75", p.duration_s, {"approach", "x", "y", "z"}), p_(p) {
    if (!(p.duration_s > 0.0) || !std::isfinite(p.duration_s)) {
      throw std::invalid_argument("fig75: duration must be positive");
    }
    t_approach_ = 0.1 * p.duration_s;
    t_phase_ = 0.3 * p.duration_s;
  }

  HandTarget Target(double t) const noexcept override {
    HandTarget out;
    t = std::clamp(t, 0.0, p_.duration_s);
    glm::dvec3& p = out.X_MH.translation;
    glm::dvec3& v = out.V_MH_M.linear;
    if (t < t_approach_) {
      return ApproachTarget(t, t_approach_, p_.start_height_m, p_.press_depth_m);
    }
    p.z = -p_.press_depth_m;
    double tau = (t - t_approach_) / t_phase_;
    if (tau < 1.0) {  // along x, parallel to the ridges
      p.x = p_.x_amplitude_m * std::sin(kTwoPi * tau);
      v.x = p_.x_amplitude_m * kTwoPi / t_phase_ * std::cos(kTwoPi * tau);
      out.phase = 1;
      return out;
    }
    tau -= 1.0;
    if (tau < 1.0) {  // along y, across the ridges
      p.y = p_.y_amplitude_m * std::sin(kTwoPi * tau);
      v.y = p_.y_amplitude_m * kTwoPi / t_phase_ * std::cos(kTwoPi * tau);
      out.phase = 2;
      return out;
    }
    tau = std::min(tau - 1.0, 1.0);  // along z: lift off and press again, twice
    const double span = p_.press_depth_m + p_.lift_height_m;
    p.z = -p_.press_depth_m + span * 0.5 * (1.0 - std::cos(2.0 * kTwoPi * tau));
    v.z = span * 0.5 * 2.0 * kTwoPi / t_phase_ * std::sin(2.0 * kTwoPi * tau);
    out.phase = 3;
    return out;
  }

 private:
  Fig75Params p_;
  double t_approach_ = 0.0;
  double t_phase_ = 0.0;
};

// The explore script: a list of segments, each a time interval with a hand behaviour.
class ExploreExperiment final : public Experiment {
  // Each object's phases in order: the k-th object's (from 0) are kStepsPerObject * k + step,
  // named kStepNames[step] + "@" + (k + 1).
  enum Step : int { kTransfer, kPress, kSlideX, kSlideY, kRelease, kStepsPerObject };
  static constexpr std::array<const char*, kStepsPerObject> kStepNames = {
      "transfer", "press", "slide_x", "slide_y", "release"};

 public:
  explicit ExploreExperiment(const ExploreParams& p) : p_(p) {
    const auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
    if (!positive(p.duration_s) || !positive(p.press_force_n) || !positive(p.transfer_speed_m_s) ||
        !positive(p.press_s) || !positive(p.slide_s) || !positive(p.release_s) ||
        !positive(p.stroke_m) || !positive(p.release_lift_m) || !(p.travel_height_m >= 0.0)) {
      throw std::invalid_argument(
          "explore: duration, press force, transfer speed, stroke, lift and phase times must be "
          "positive");
    }
    SetScene(ExperimentScene{});
  }
  const std::string& name() const noexcept override { return name_; }
  double duration_s() const noexcept override { return p_.duration_s; }
  const std::vector<std::string>& phase_names() const noexcept override { return phases_; }
  // Each object's transfer and release end with the hand off the object.
  bool EndsFree(int phase) const noexcept override {
    const int step = phase % kStepsPerObject;
    return step == kTransfer || step == kRelease;
  }

  void SetScene(const ExperimentScene& scene) override {
    std::vector<ExperimentTarget> targets = scene.targets;
    const double below = scene.tool_extent_down_m;
    if (targets.empty()) {  // nothing described: explore below the workspace centre
      ExperimentTarget t;
      t.box_min_M = {-0.02, -0.02, -0.04 - below};
      t.box_max_M = {0.02, 0.02, -below};
      t.top_M = {0.0, 0.0, -below};
      t.approach_z_M = 0.0;
      targets.push_back(t);
    }
    phases_.clear();
    for (std::size_t k = 0; k < targets.size(); ++k) {
      for (const char* ph : kStepNames) {
        phases_.push_back(std::string(ph) + "@" + std::to_string(k + 1));
      }
    }
    segments_.clear();
    // Moves between spots at the travel height: above the home pose and every object's bounds.
    double travel_z = 0.0;
    for (const ExperimentTarget& t : targets) travel_z = std::max(travel_z, t.box_max_M.z + below);
    travel_z += p_.travel_height_m;
    // The simulated hand's approach speeds (its defaults), for how long phases last.
    const OperatorHandParams hand;
    const double fast = hand.press_fast_speed_m_per_s, slow = hand.press_slow_speed_m_per_s;
    glm::dvec3 here(0.0);   // the workspace centre: the home pose
    glm::dvec3 shift(0.0);  // the workspace's jumps so far
    double ceiling = 0.0;   // where the last press started
    double t = 0.0;
    const auto add = [&](Segment s, double duration) {
      s.t0 = t;
      s.t1 = t + duration;
      t = s.t1;
      segments_.push_back(s);
    };
    for (int visit = 0; t < p_.duration_s && visit < 10000; ++visit) {
      const auto k = static_cast<int>(visit % targets.size());
      const int round = static_cast<int>(visit / targets.size());
      const ExperimentTarget& target = targets[static_cast<std::size_t>(k)];
      const glm::dvec3 half = 0.5 * (target.box_max_M - target.box_min_M);
      // Round 0 presses at the object's top, later rounds around it (a quarter of the object's
      // width away, at most 4 cm: the texture near the top rather than the far sides).
      static constexpr double kSpots[5][2] = {{0, 0}, {1, 0}, {0, 1}, {-1, 0}, {0, -1}};
      const double* d = kSpots[round % 5];
      glm::dvec3 spot = target.top_M;
      spot.x = std::clamp(spot.x + std::min(0.25 * half.x, 0.04) * d[0], target.box_min_M.x,
                          target.box_max_M.x);
      spot.y = std::clamp(spot.y + std::min(0.25 * half.y, 0.04) * d[1], target.box_min_M.y,
                          target.box_max_M.y);
      // The hand's height when the tool touches this object's (coarse) top, and the lowest it
      // may go: the tool at the bottom of the object's bounds.
      const double hover_z = target.top_M.z + below;
      const double floor_z = target.box_min_M.z + below - 0.005;
      const int base = kStepsPerObject * k;

      // Just above the object's top where the tool touches nothing (the remote node checked).
      const double approach_z = std::min(travel_z, std::max(target.approach_z_M, hover_z));
      const double distance = glm::length(glm::dvec2(spot.x - here.x, spot.y - here.y));
      const bool jump = distance > p_.jump_beyond_m || travel_z - approach_z > 0.1;
      Segment lift;  // straight up: to where the last press started, or to the travel height
      lift.kind = Segment::kMove;
      lift.phase = base + kTransfer;
      lift.from = here;
      lift.to = {here.x, here.y, jump ? ceiling : travel_z};
      lift.shift = shift;
      add(lift, std::max(0.1, (lift.to.z - here.z) / (0.8 * fast)));
      Segment move = lift;
      move.from = lift.to;
      if (jump) {
        // "Go to": from just above the last spot (free space) to just above this one, the
        // workspace and the tool jump together; the handle stays where it is in the device.
        move.to = {spot.x, spot.y, approach_z};
        shift += move.to - lift.to;
        move.from = move.to;
        move.shift = shift;
        add(move, 0.1);
      } else {  // across, at the travel height (above the whole scene)
        move.to = {spot.x, spot.y, travel_z};
        add(move, std::max(0.15, distance / p_.transfer_speed_m_s));
      }
      ceiling = move.to.z;

      Segment press;  // down under force control, fast to near the top, then slowly
      press.kind = Segment::kPress;
      press.phase = base + kPress;
      press.from = press.to = move.to;
      press.shift = shift;
      press.floor_z = floor_z;
      press.slow_below_z = hover_z + 0.01;
      add(press, p_.press_s + std::max(0.0, press.to.z - press.slow_below_z) / fast + 0.01 / slow);
      const double stroke_x = std::min(p_.stroke_m, 0.4 * half.x);
      const double stroke_y = std::min(p_.stroke_m, 0.4 * half.y);
      Segment slide = press;
      slide.phase = base + kSlideX;
      slide.axis = 0;
      slide.amplitude = stroke_x;
      add(slide, p_.slide_s);
      slide.phase = base + kSlideY;
      slide.axis = 1;
      slide.amplitude = stroke_y;
      add(slide, p_.slide_s);
      Segment release = press;
      release.kind = Segment::kLift;
      release.phase = base + kRelease;
      release.amplitude = 0.0;
      add(release, p_.release_s);
      press.phase = base + kPress;
      add(press, p_.press_s);
      here = {spot.x, spot.y, hover_z};
    }
  }

  HandTarget Target(double t) const noexcept override {
    HandTarget out;
    if (segments_.empty()) return out;
    t = std::clamp(t, 0.0, segments_.back().t1);
    // The segment holding t (segments are contiguous and sorted).
    auto it = std::upper_bound(segments_.begin(), segments_.end(), t,
                               [](double v, const Segment& s) { return v < s.t1; });
    if (it == segments_.end()) --it;
    const Segment& s = *it;
    const double span = s.t1 - s.t0;
    const double u = span > 0.0 ? std::clamp((t - s.t0) / span, 0.0, 1.0) : 1.0;
    out.phase = s.phase;
    out.workspace_shift_M = s.shift;
    glm::dvec3& p = out.X_MH.translation;
    glm::dvec3& v = out.V_MH_M.linear;
    switch (s.kind) {
      case Segment::kMove: {  // cosine-eased straight line
        const double e = 0.5 * (1.0 - std::cos(std::numbers::pi * u));
        p = s.from + e * (s.to - s.from);
        if (span > 0.0) {
          v = (s.to - s.from) * (0.5 * std::numbers::pi * std::sin(std::numbers::pi * u) / span);
        }
        break;
      }
      case Segment::kPress:
      case Segment::kLift: {
        p = s.to;
        if (s.amplitude > 0.0 && span > 0.0) {  // one period of a sine along x or y
          p[s.axis] += s.amplitude * std::sin(kTwoPi * u);
          v[s.axis] = s.amplitude * kTwoPi / span * std::cos(kTwoPi * u);
        }
        if (s.kind == Segment::kPress) {
          out.z_control = HandZControl::kPress;
          out.press_force_n = p_.press_force_n;
          out.floor_z_m = s.floor_z;
          out.slow_below_z_m = s.slow_below_z;
        } else {
          out.z_control = HandZControl::kLift;
          out.lift_m = p_.release_lift_m;
        }
        break;
      }
    }
    return out;
  }

 private:
  struct Segment {
    enum Kind { kMove, kPress, kLift } kind = kMove;
    double t0 = 0.0, t1 = 0.0;
    int phase = 0;
    glm::dvec3 from{0.0}, to{0.0};
    int axis = 0;            // slide axis (0 = x, 1 = y)
    double amplitude = 0.0;  // slide amplitude (m); 0 = no slide
    double floor_z = 0.0, slow_below_z = 0.0;
    glm::dvec3 shift{0.0};  // HandTarget::workspace_shift_M
  };
  ExploreParams p_;
  std::vector<Segment> segments_;
  std::string name_ = "explore";
  std::vector<std::string> phases_;
};

// Seed Fig. 76: press the upper striped block into the lower one, then rotate it back and forth
// about n (the device's z, the scene's up) while the hand keeps pressing.
class Fig76Experiment final : public FixedScript {
 public:
  explicit Fig76Experiment(const Fig76Params& p)
      : FixedScript("fig76", p.duration_s, {"approach", "rotate"}), p_(p) {
    if (!(p.duration_s > 0.0) || !std::isfinite(p.duration_s) || !(p.period_s > 0.0) ||
        !(p.amplitude_rad > 0.0)) {
      throw std::invalid_argument("fig76: duration, period and amplitude must be positive");
    }
    t_approach_ = std::min(1.0, 0.1 * p.duration_s);
  }

  HandTarget Target(double t) const noexcept override {
    HandTarget out;
    t = std::clamp(t, 0.0, p_.duration_s);
    glm::dvec3& p = out.X_MH.translation;
    if (t < t_approach_) {
      return ApproachTarget(t, t_approach_, p_.start_height_m, p_.press_depth_m);
    }
    p.z = -p_.press_depth_m;
    const double w = kTwoPi / p_.period_s;
    const double theta = p_.amplitude_rad * std::sin(w * (t - t_approach_));
    out.X_MH.rotation = glm::angleAxis(theta, glm::dvec3(0.0, 0.0, 1.0));
    out.V_MH_M.angular.z = p_.amplitude_rad * w * std::cos(w * (t - t_approach_));
    out.phase = 1;
    return out;
  }

 private:
  Fig76Params p_;
  double t_approach_ = 0.0;
};

// Seed Fig. 77: press the tool onto the part, then scrape along +x with a sway in y and a yaw.
class Fig77Experiment final : public FixedScript {
 public:
  explicit Fig77Experiment(const Fig77Params& p)
      : FixedScript("fig77", p.duration_s, {"approach", "scrape"}), p_(p) {
    if (!(p.duration_s > 0.0) || !std::isfinite(p.duration_s) || !(p.stroke_m > 0.0)) {
      throw std::invalid_argument("fig77: duration and stroke must be positive");
    }
    t_approach_ = std::min(1.0, 0.1 * p.duration_s);
  }

  HandTarget Target(double t) const noexcept override {
    HandTarget out;
    t = std::clamp(t, 0.0, p_.duration_s);
    glm::dvec3& p = out.X_MH.translation;
    glm::dvec3& v = out.V_MH_M.linear;
    if (t < t_approach_) {
      return ApproachTarget(t, t_approach_, p_.start_height_m, p_.press_depth_m);
    }
    const double T = p_.duration_s - t_approach_;
    const double tau = (t - t_approach_) / T;  // 0 → 1 over the scrape
    p.z = -p_.press_depth_m;
    // x: eased from 0 to the stroke; y: two sways; yaw: three swings.
    p.x = p_.stroke_m * 0.5 * (1.0 - std::cos(std::numbers::pi * tau));
    v.x = p_.stroke_m * 0.5 * std::numbers::pi * std::sin(std::numbers::pi * tau) / T;
    p.y = p_.sway_m * std::sin(kTwoPi * 2.0 * tau);
    v.y = p_.sway_m * kTwoPi * 2.0 / T * std::cos(kTwoPi * 2.0 * tau);
    const double yaw = p_.yaw_rad * std::sin(kTwoPi * 3.0 * tau);
    out.X_MH.rotation = glm::angleAxis(yaw, glm::dvec3(0.0, 0.0, 1.0));
    out.V_MH_M.angular.z = p_.yaw_rad * kTwoPi * 3.0 / T * std::cos(kTwoPi * 3.0 * tau);
    out.phase = 1;
    return out;
  }

 private:
  Fig77Params p_;
  double t_approach_ = 0.0;
};

}  // namespace

std::unique_ptr<Experiment> MakeFig76Experiment(const Fig76Params& params) {
  return std::make_unique<Fig76Experiment>(params);
}

std::unique_ptr<Experiment> MakeFig77Experiment(const Fig77Params& params) {
  return std::make_unique<Fig77Experiment>(params);
}

std::unique_ptr<Experiment> MakeExploreExperiment(const ExploreParams& params) {
  return std::make_unique<ExploreExperiment>(params);
}

std::unique_ptr<Experiment> MakeFig75Experiment(const Fig75Params& params) {
  return std::make_unique<Fig75Experiment>(params);
}

std::unique_ptr<Experiment> MakeExperiment(const std::string& name, double duration_s) {
  if (name == "fig75") {
    Fig75Params p;
    p.duration_s = duration_s;
    return MakeFig75Experiment(p);
  }
  if (name == "explore") {
    ExploreParams p;
    p.duration_s = duration_s;
    return MakeExploreExperiment(p);
  }
  if (name == "fig76") {
    Fig76Params p;
    p.duration_s = duration_s;
    return MakeFig76Experiment(p);
  }
  if (name == "fig77") {
    Fig77Params p;
    p.duration_s = duration_s;
    return MakeFig77Experiment(p);
  }
  throw std::invalid_argument("unknown experiment '" + name +
                              "' (known: fig75, fig76, fig77, explore)");
}

}  // namespace ht
