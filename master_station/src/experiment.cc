#include "master_station/experiment.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace ht {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

class Fig75Experiment final : public Experiment {
 public:
  explicit Fig75Experiment(const Fig75Params& p) : p_(p) {
    if (!(p.duration_s > 0.0) || !std::isfinite(p.duration_s)) {
      throw std::invalid_argument("fig75: duration must be positive");
    }
    t_approach_ = 0.1 * p.duration_s;
    t_phase_ = 0.3 * p.duration_s;
  }
  const std::string& name() const noexcept override { return name_; }
  double duration_s() const noexcept override { return p_.duration_s; }
  const std::vector<std::string>& phase_names() const noexcept override { return phases_; }

  HandTarget Target(double t) const noexcept override {
    HandTarget out;
    t = std::clamp(t, 0.0, p_.duration_s);
    glm::dvec3& p = out.X_MH.translation;
    glm::dvec3& v = out.V_MH_M.linear;
    if (t < t_approach_) {  // ease down from start height to the pressing depth
      const double s = t / t_approach_;
      const double span = -p_.press_depth_m - p_.start_height_m;
      p.z = p_.start_height_m + span * 0.5 * (1.0 - std::cos(std::numbers::pi * s));
      v.z = span * 0.5 * std::numbers::pi * std::sin(std::numbers::pi * s) / t_approach_;
      out.phase = 0;
      return out;
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
  std::string name_ = "fig75";
  std::vector<std::string> phases_ = {"approach", "x", "y", "z"};
};

}  // namespace

std::unique_ptr<Experiment> MakeFig75Experiment(const Fig75Params& params) {
  return std::make_unique<Fig75Experiment>(params);
}

std::unique_ptr<Experiment> MakeExperiment(const std::string& name, double duration_s) {
  if (name == "fig75") {
    Fig75Params p;
    p.duration_s = duration_s;
    return MakeFig75Experiment(p);
  }
  throw std::invalid_argument("unknown experiment '" + name + "' (known: fig75)");
}

}  // namespace ht
