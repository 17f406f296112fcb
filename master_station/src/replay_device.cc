#include "master_station/replay_device.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace ht {
namespace {

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::string cell;
  std::stringstream ss(line);
  while (std::getline(ss, cell, ',')) {
    while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
    out.push_back(cell);
  }
  return out;
}

}  // namespace

std::vector<ReplaySample> LoadReplayTrace(const std::string& path, const glm::dvec3& origin_W) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot read replay trace " + path);
  std::string line;
  if (!std::getline(f, line)) throw std::runtime_error("replay trace " + path + " is empty");
  const std::vector<std::string> header = SplitCsv(line);
  const auto column = [&](std::initializer_list<const char*> names) -> int {
    for (const char* n : names) {
      for (std::size_t i = 0; i < header.size(); ++i) {
        if (header[i] == n) return static_cast<int>(i);
      }
    }
    return -1;
  };
  const int ct = column({"t_s", "t"});
  int cx = column({"x"}), cy = column({"y"}), cz = column({"z"});
  bool world = false;
  if (cx < 0 && cy < 0 && cz < 0) {
    cx = column({"hand_x"});
    cy = column({"hand_y"});
    cz = column({"hand_z"});
    world = true;
  }
  const int crx = column({"rx"}), cry = column({"ry"}), crz = column({"rz"});
  if (ct < 0 || cx < 0 || cy < 0 || cz < 0) {
    throw std::runtime_error("replay trace " + path +
                             ": the header must name t_s and x,y,z (or hand_x,hand_y,hand_z); "
                             "found: " +
                             line);
  }
  std::vector<ReplaySample> samples;
  int line_no = 1;
  while (std::getline(f, line)) {
    ++line_no;
    if (line.empty() || line == "\r") continue;
    const std::vector<std::string> cells = SplitCsv(line);
    const auto number = [&](int c, const char* what) {
      if (c < 0) return 0.0;
      if (static_cast<std::size_t>(c) >= cells.size()) {
        throw std::runtime_error("replay trace " + path + " line " + std::to_string(line_no) +
                                 ": no " + what + " column");
      }
      char* end = nullptr;
      const double v = std::strtod(cells[static_cast<std::size_t>(c)].c_str(), &end);
      if (end == cells[static_cast<std::size_t>(c)].c_str() || *end != '\0' || !std::isfinite(v)) {
        throw std::runtime_error("replay trace " + path + " line " + std::to_string(line_no) +
                                 ": " + what + " is not a finite number: '" +
                                 cells[static_cast<std::size_t>(c)] + "'");
      }
      return v;
    };
    ReplaySample s;
    s.t_s = number(ct, "t_s");
    s.X_MH.translation = {number(cx, "x"), number(cy, "y"), number(cz, "z")};
    if (world) s.X_MH.translation -= origin_W;
    if (crx >= 0 && cry >= 0 && crz >= 0) {
      s.X_MH.rotation =
          QuaternionFromRotationVector({number(crx, "rx"), number(cry, "ry"), number(crz, "rz")});
    }
    if (!samples.empty() && !(s.t_s > samples.back().t_s)) {
      throw std::runtime_error("replay trace " + path + " line " + std::to_string(line_no) +
                               ": time does not increase");
    }
    samples.push_back(s);
  }
  if (samples.size() < 2) {
    throw std::runtime_error("replay trace " + path + " has fewer than 2 samples");
  }
  return samples;
}

ReplayDevice::ReplayDevice(std::vector<ReplaySample> samples, std::string source)
    : samples_(std::move(samples)), source_(std::move(source)) {
  if (samples_.size() < 2) throw std::invalid_argument("replay device: need at least 2 samples");
}

DeviceCapabilities ReplayDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "replay (" + source_ + ")";
  c.max_force_n = 10.0;  // what the station may command; nothing is rendered
  c.max_torque_nm = 1.0;
  c.max_stiffness_n_per_m = 3000.0;
  c.max_rotational_stiffness_nm_per_rad = 5.0;
  c.max_damping_ns_per_m = 40.0;
  c.workspace_half_extents_m = {0.1, 0.1, 0.1};
  c.dof_in = 6;
  c.dof_out = 0;
  return c;
}

void ReplayDevice::Open() {
  open_ = true;
  started_ = false;
  cursor_ = 0;
}

void ReplayDevice::Close() noexcept { open_ = false; }

bool ReplayDevice::ReadState(std::int64_t now_ns, DeviceState& out) noexcept {
  if (!open_) return false;
  if (!started_) {
    started_ = true;
    t0_ns_ = now_ns;
  }
  const double t = samples_.front().t_s + (now_ns - t0_ns_) * 1e-9;
  while (cursor_ + 2 < samples_.size() && samples_[cursor_ + 1].t_s <= t) ++cursor_;
  const ReplaySample& a = samples_[cursor_];
  const ReplaySample& b = samples_[cursor_ + 1];
  const double span = b.t_s - a.t_s;
  out.timestamp_ns = now_ns;
  out.buttons = 0;
  if (t >= samples_.back().t_s) {  // the end: hold still
    out.X_MH = samples_.back().X_MH;
    out.V_MH_M = {};
    return true;
  }
  const double u = std::clamp((t - a.t_s) / span, 0.0, 1.0);
  out.X_MH.translation = glm::mix(a.X_MH.translation, b.X_MH.translation, u);
  out.X_MH.rotation = glm::slerp(a.X_MH.rotation, b.X_MH.rotation, u);
  out.V_MH_M.linear = (b.X_MH.translation - a.X_MH.translation) / span;
  out.V_MH_M.angular = PoseDifference(b.X_MH, a.X_MH).angular / span;
  return true;
}

bool ReplayDevice::WriteWrench(const Wrench&, std::int64_t) noexcept {
  ++wrenches_;
  return open_;
}

}  // namespace ht
