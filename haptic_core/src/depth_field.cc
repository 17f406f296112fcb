// The contact model's depth field (depth_field.h): its preparation, its evaluation at a tool
// pose, and the operator's cache of fields.

#include "haptic_core/depth_field.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <stdexcept>

namespace ht {
namespace {

/// Catmull–Rom weights w[0..3] of nodes −1, 0, 1, 2 at t ∈ [0, 1), and their derivatives d/dt.
inline void CatmullRom(double t, double w[4], double d[4]) noexcept {
  const double t2 = t * t, t3 = t2 * t;
  w[0] = 0.5 * (-t3 + 2.0 * t2 - t);
  w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0);
  w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t);
  w[3] = 0.5 * (t3 - t2);
  d[0] = 0.5 * (-3.0 * t2 + 4.0 * t - 1.0);
  d[1] = 0.5 * (9.0 * t2 - 10.0 * t);
  d[2] = 0.5 * (-9.0 * t2 + 8.0 * t + 1.0);
  d[3] = 0.5 * (3.0 * t2 - 2.0 * t);
}

/// Over a 4×4 stencil the Catmull–Rom weights' positive part sums to at most
/// (1 + 1/8)² + (1/8)² (each 1D weight set has negative lobes of at most 1/8 in all), so the
/// interpolant is at most lo + kOvershoot·(hi − lo), lo and hi the stencil's extremes.
constexpr double kOvershoot = 1.125 * 1.125 + 0.125 * 0.125;

/// Depths more than this many ε below the maximum weigh less than e^−30 ≈ 1e−13: skipped.
constexpr double kCutoffWidths = 30.0;

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

}  // namespace

void DepthField::Reserve() {
  const std::size_t n = static_cast<std::size_t>(kMaxDepthFieldSide) * kMaxDepthFieldSide;
  env_height_m.reserve(n);
  tool_height_m.reserve(n);
  env_bound_m.reserve(n);
}

bool DepthField::Prepare() {
  prepared = false;
  const std::size_t n = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  if (id == 0 || !IsFiniteRigidTransform(X_WF) || !IsFiniteRigidTransform(X_WT0) ||
      !(cell_m > 0.0) || !std::isfinite(cell_m) || nx < 4 || ny < 4 || nx > kMaxDepthFieldSide ||
      ny > kMaxDepthFieldSide || env_height_m.size() != n || tool_height_m.size() != n ||
      !(travel_margin_m >= 0.0) || !std::isfinite(travel_margin_m) || !(smooth_max_m > 0.0) ||
      !std::isfinite(smooth_max_m) || !std::isfinite(depth_offset_m)) {
    return false;
  }
  env_bound_m.assign(n, -std::numeric_limits<float>::infinity());
  for (int j = 1; j + 2 < ny; ++j) {
    for (int i = 1; i + 2 < nx; ++i) {
      float lo = std::numeric_limits<float>::infinity(), hi = -lo;
      bool complete = true;
      for (int b = -1; b <= 2 && complete; ++b) {
        const float* row = env_height_m.data() + static_cast<std::size_t>(j + b) * nx;
        for (int a = -1; a <= 2; ++a) {
          const float v = row[i + a];
          if (!std::isfinite(v)) {
            complete = false;
            break;
          }
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
      }
      if (complete) {
        // Rounded up by a relative 1e−6 (the float store) so that the bound holds.
        const double bound = lo + kOvershoot * (static_cast<double>(hi) - lo);
        env_bound_m[static_cast<std::size_t>(j) * nx + i] =
            static_cast<float>(bound + 1e-6 * std::abs(bound) + 1e-12);
      }
    }
  }
  double r2 = 0.0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const float a = tool_height_m[static_cast<std::size_t>(j) * nx + i];
      if (!std::isfinite(a)) continue;
      const glm::dvec3 p_W = X_WF * glm::dvec3(i * cell_m, j * cell_m, a);
      const glm::dvec3 r = p_W - X_WT0.translation;
      r2 = std::max(r2, glm::dot(r, r));
    }
  }
  tool_radius_m = std::sqrt(r2);
  prepared = true;
  return true;
}

void DepthField::CopyFrom(const DepthField& other) noexcept {
  const std::size_t cap = static_cast<std::size_t>(kMaxDepthFieldSide) * kMaxDepthFieldSide;
  if (other.env_height_m.size() > std::min(cap, env_height_m.capacity()) ||
      other.tool_height_m.size() > std::min(cap, tool_height_m.capacity()) ||
      other.env_bound_m.size() > std::min(cap, env_bound_m.capacity())) {
    id = 0;
    prepared = false;
    env_height_m.clear();
    tool_height_m.clear();
    env_bound_m.clear();
    return;
  }
  id = other.id;
  X_WF = other.X_WF;
  cell_m = other.cell_m;
  nx = other.nx;
  ny = other.ny;
  env_height_m.assign(other.env_height_m.begin(), other.env_height_m.end());
  tool_height_m.assign(other.tool_height_m.begin(), other.tool_height_m.end());
  X_WT0 = other.X_WT0;
  travel_margin_m = other.travel_margin_m;
  depth_offset_m = other.depth_offset_m;
  smooth_max_m = other.smooth_max_m;
  env_bound_m.assign(other.env_bound_m.begin(), other.env_bound_m.end());
  tool_radius_m = other.tool_radius_m;
  prepared = other.prepared;
}

DepthFieldEvaluation DepthFieldDepthAt(const DepthField& f, const RigidTransform& X_WT) noexcept {
  DepthFieldEvaluation out;
  if (!f.prepared || !IsFiniteRigidTransform(X_WT)) return out;
  const Twist dq = PoseDifference(X_WT, f.X_WT0);
  if (glm::length(dq.linear) + glm::length(dq.angular) * f.tool_radius_m > f.travel_margin_m) {
    return out;
  }
  out.valid = true;
  // The tool's motion since X_WT0 in F: s = D·p for a tool node p (F at X_WT0).
  const RigidTransform X_FW = f.X_WF.Inverse();
  const RigidTransform D = X_FW * X_WT * f.X_WT0.Inverse() * f.X_WF;
  const glm::dmat3 R = glm::mat3_cast(D.rotation);
  const glm::dvec3 c_F = X_FW * X_WT.translation;  // the centre of mass in F
  const double h = f.cell_m, inv_h = 1.0 / h, eps = f.smooth_max_m;
  const int nx = f.nx, ny = f.ny;
  const float* env = f.env_height_m.data();
  const float* tool = f.tool_height_m.data();
  const float* bound = f.env_bound_m.data();
  const glm::dvec3 step_i = h * R[0], step_j = h * R[1], along_a = R[2];

  // The node's moved position and its cell's bound (−∞: no interpolant under it).
  const auto locate = [&](const glm::dvec3& s, int& cell, double& tu, double& tv) noexcept {
    const double u = s.x * inv_h, v = s.y * inv_h;
    if (!(u >= 1.0) || !(v >= 1.0) || !(u < nx - 2) || !(v < ny - 2)) return false;
    const int i0 = static_cast<int>(u), j0 = static_cast<int>(v);
    tu = u - i0;
    tv = v - j0;
    cell = j0 * nx + i0;
    return true;
  };
  // Pass 1: the node with the highest bound.
  double best_ub = -std::numeric_limits<double>::infinity();
  int best_node = -1;
  for (int j = 0; j < ny; ++j) {
    const glm::dvec3 row = D.translation + static_cast<double>(j) * step_j;
    for (int i = 0; i < nx; ++i) {
      const float a = tool[j * nx + i];
      if (!std::isfinite(a)) continue;
      const glm::dvec3 s = row + static_cast<double>(i) * step_i + static_cast<double>(a) * along_a;
      int cell;
      double tu, tv;
      if (!locate(s, cell, tu, tv)) continue;
      const double ub = bound[cell] - s.z;
      if (ub > best_ub) {
        best_ub = ub;
        best_node = j * nx + i;
      }
    }
  }
  if (best_node < 0) return out;  // no tool node over the environment: no overlap, valid

  // The exact depth of node (i, j): δ = b(s) − s.z and the node's gradient in F.
  const auto exact = [&](int i, int j, const glm::dvec3& s, int cell, double tu, double tv,
                         Vec6* J) noexcept {
    double wu[4], du[4], wv[4], dv[4];
    CatmullRom(tu, wu, du);
    CatmullRom(tv, wv, dv);
    const int i0 = cell % nx, j0 = cell / nx;
    double b = 0.0, bu = 0.0, bv = 0.0;
    for (int r = 0; r < 4; ++r) {
      const float* row = env + (j0 - 1 + r) * nx + (i0 - 1);
      const double x = wu[0] * row[0] + wu[1] * row[1] + wu[2] * row[2] + wu[3] * row[3];
      const double dx = du[0] * row[0] + du[1] * row[1] + du[2] * row[2] + du[3] * row[3];
      b += wv[r] * x;
      bu += wv[r] * dx;
      bv += dv[r] * x;
    }
    (void)i;
    (void)j;
    if (J != nullptr) {
      const glm::dvec3 g(bu * inv_h, bv * inv_h, -1.0);
      const glm::dvec3 lever = glm::cross(s - c_F, g);
      *J << g.x, g.y, g.z, lever.x, lever.y, lever.z;
    }
    return b - s.z;
  };
  double m_ref;
  {
    const int i = best_node % nx, j = best_node / nx;
    const glm::dvec3 s = D.translation + static_cast<double>(j) * step_j +
                         static_cast<double>(i) * step_i +
                         static_cast<double>(tool[best_node]) * along_a;
    int cell;
    double tu, tv;
    locate(s, cell, tu, tv);
    m_ref = exact(i, j, s, cell, tu, tv, nullptr);
  }
  // Pass 2: the nodes whose bound reaches within the cutoff of the running maximum, summed as
  // an online log-sum-exp (the sums rescaled whenever the maximum rises).
  const double cutoff = kCutoffWidths * eps;
  double S0 = 0.0;
  Vec6 S1 = Vec6::Zero();
  Mat6 S2 = Mat6::Zero();
  Vec6 J;
  for (int j = 0; j < ny; ++j) {
    const glm::dvec3 row = D.translation + static_cast<double>(j) * step_j;
    for (int i = 0; i < nx; ++i) {
      const float a = tool[j * nx + i];
      if (!std::isfinite(a)) continue;
      const glm::dvec3 s = row + static_cast<double>(i) * step_i + static_cast<double>(a) * along_a;
      int cell;
      double tu, tv;
      if (!locate(s, cell, tu, tv)) continue;
      if (bound[cell] - s.z < m_ref - cutoff) continue;
      const double d = exact(i, j, s, cell, tu, tv, &J);
      ++out.nodes_evaluated;
      if (d > m_ref) {
        const double scale = std::exp((m_ref - d) / eps);
        S0 *= scale;
        S1 *= scale;
        S2 *= scale;
        m_ref = d;
      }
      const double e = std::exp((d - m_ref) / eps);
      if (e < 1e-13) continue;
      S0 += e;
      S1.noalias() += e * J;
      S2.noalias() += e * (J * J.transpose());
    }
  }
  if (!(S0 > 0.0)) return out;
  out.depth_m = m_ref + eps * std::log(S0) + f.depth_offset_m;
  out.max_node_depth_m = m_ref + f.depth_offset_m;
  const Vec6 mean = S1 / S0;
  const Mat6 cov = S2 / S0 - mean * mean.transpose();
  // To world axes: both halves turn with R_WF.
  const glm::dmat3 R_WF = glm::mat3_cast(f.X_WF.rotation);
  const glm::dvec3 g_F(mean[0], mean[1], mean[2]), r_F(mean[3], mean[4], mean[5]);
  out.gradient.d_translation_W = R_WF * g_F;
  out.gradient.d_rotation_W = R_WF * r_F;
  Mat6 B = Mat6::Zero();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      B(r, c) = R_WF[c][r];
      B(r + 3, c + 3) = R_WF[c][r];
    }
  }
  out.curvature.noalias() = B * (cov / eps) * B.transpose();
  out.curvature = 0.5 * (out.curvature + out.curvature.transpose()).eval();
  return out;
}

DepthFieldCache::DepthFieldCache(int slots) {
  if (slots < 1) {
    throw std::invalid_argument("a depth-field cache needs at least 1 slot, got " +
                                std::to_string(slots));
  }
  slots_.resize(static_cast<std::size_t>(slots));
  for (DepthField& f : slots_) f.Reserve();
  stamp_.assign(static_cast<std::size_t>(slots), 0);
}

const DepthField* DepthFieldCache::Find(std::uint32_t id) const noexcept {
  if (id == 0) return nullptr;
  for (std::size_t k = 0; k < slots_.size(); ++k) {
    if (stamp_[k] != 0 && slots_[k].id == id) return &slots_[k];
  }
  return nullptr;
}

bool DepthFieldCache::Take(DepthField& field, std::span<const std::uint32_t> keep) noexcept {
  if (!field.prepared || field.id == 0) {
    ++refused_;
    return false;
  }
  std::size_t slot = slots_.size();
  for (std::size_t k = 0; k < slots_.size() && slot == slots_.size(); ++k) {
    if (stamp_[k] != 0 && slots_[k].id == field.id) slot = k;
  }
  for (std::size_t k = 0; k < slots_.size() && slot == slots_.size(); ++k) {
    if (stamp_[k] == 0) slot = k;
  }
  if (slot == slots_.size()) {
    std::uint64_t oldest = ~std::uint64_t{0};
    for (std::size_t k = 0; k < slots_.size(); ++k) {
      if (std::find(keep.begin(), keep.end(), slots_[k].id) != keep.end()) continue;
      if (stamp_[k] < oldest) {
        oldest = stamp_[k];
        slot = k;
      }
    }
  }
  if (slot == slots_.size()) {
    ++refused_;
    return false;
  }
  std::swap(slots_[slot], field);
  stamp_[slot] = ++clock_;
  ++taken_;
  return true;
}

}  // namespace ht
