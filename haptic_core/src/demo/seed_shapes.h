// The seed analogues' modelling kit (seed_models.cc): argument checks, blurred solids (a union
// of boxes and cylinders smoothed as the level set of its blurred indicator), polycube meshing of
// such a solid, plane-wave noise and saw teeth. Internal to src/demo/.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/mesh.h"

namespace ht::seed_shapes {

inline constexpr double kTwoPi = 2.0 * std::numbers::pi;

inline void RequirePositive(double v, const char* what) {
  if (!(v > 0.0)) {
    throw std::invalid_argument(std::string(what) + " must be positive, got " + std::to_string(v));
  }
}

inline void RequireFinite(double v, const char* what) {
  if (!std::isfinite(v)) throw std::invalid_argument(std::string(what) + " must be finite");
}

inline void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

inline double Smoothstep(double e0, double e1, double x) noexcept {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

inline double Fract(double x) noexcept { return x - std::floor(x); }

// ---------------------------------------------------------------------------------------------
// Base shapes: a union of disjoint axis-aligned boxes and cylinders (the sharp solid), smoothed as
// the 0.5 level set of its indicator blurred by a Gaussian of standard deviation σ. The blur of a
// box is separable (a product of 1-D blurred intervals), so a partition into boxes merges flush
// faces exactly; convex edges round (radius ≈ 1.9σ) and concave edges fill (fillets) alike. The
// blur of a cylinder is approximated by Φ((R − r)/σ) times its blurred axial interval.

struct Interval {
  double value;
  double derivative;  // per metre
};

// Gaussian CDF Φ(t) and density φ(t) of t = x/σ, cut off beyond 8σ.
inline double Cdf(double t) noexcept {
  if (t > 8.0) return 1.0;
  if (t < -8.0) return 0.0;
  return 0.5 * std::erfc(-t * std::numbers::sqrt2 * 0.5);
}
inline double Pdf(double t) noexcept {
  if (t > 8.0 || t < -8.0) return 0.0;
  return std::exp(-0.5 * t * t) * (0.5 * std::numbers::inv_sqrtpi * std::numbers::sqrt2);
}

// The indicator of [lo, hi] blurred by σ, at x.
inline Interval BlurredInterval(double x, double lo, double hi, double inv_sigma) noexcept {
  const double a = (x - lo) * inv_sigma, b = (x - hi) * inv_sigma;
  return {Cdf(a) - Cdf(b), (Pdf(a) - Pdf(b)) * inv_sigma};
}

struct AxisBox {
  glm::dvec3 lo, hi;
};

// A cylinder along `axis` (0 x, 1 y, 2 z) about the point `centre` of the plane of the other two
// axes (in cyclic order axis+1, axis+2), over [a0, a1] along the axis. Its polycube is the
// circumscribed square prism, mapped onto the cylinder before projection by the radial map
// d → d·‖d‖∞/‖d‖₂ (squares about the axis onto circles), which is blended out over
// ‖d‖∞ ∈ [R, R + outer_blend] on the attachment planes (so the grid of the face it stands on
// follows smoothly) and, where inner_blend > 0, blended in over ‖d‖∞ ∈ [inner_blend, R] (so an
// end face can carry a narrower part unmoved).
struct Cylinder {
  int axis;
  glm::dvec2 centre;
  double radius;
  double a0, a1;
  double inner_blend;
  double outer_blend;

  AxisBox Box() const {
    glm::dvec3 lo(0.0), hi(0.0);
    lo[axis] = a0;
    hi[axis] = a1;
    const int b = (axis + 1) % 3, c = (axis + 2) % 3;
    lo[b] = centre.x - radius;
    hi[b] = centre.x + radius;
    lo[c] = centre.y - radius;
    hi[c] = centre.y + radius;
    return {lo, hi};
  }
};

class BlurredSolid {
 public:
  explicit BlurredSolid(double sigma) : sigma_(sigma), inv_sigma_(1.0 / sigma) {}

  void AddBox(const glm::dvec3& lo, const glm::dvec3& hi) {
    for (int a = 0; a < 3; ++a) {
      if (!(hi[a] > lo[a])) throw std::invalid_argument("seed model: empty box in the layout");
    }
    boxes_.push_back({lo, hi});
  }
  void AddCylinder(const Cylinder& c) {
    if (!(c.radius > 0.0) || !(c.a1 > c.a0)) {
      throw std::invalid_argument("seed model: empty cylinder in the layout");
    }
    cylinders_.push_back(c);
  }

  // The sharp solid as boxes (cylinders as their square prisms), for the polycube grid.
  std::vector<AxisBox> PolycubeBoxes() const {
    std::vector<AxisBox> out = boxes_;
    for (const Cylinder& c : cylinders_) out.push_back(c.Box());
    return out;
  }

  // Moves a polycube vertex of a cylinder's prism (and of the attachment planes nearby) onto
  // the cylinder's circle.
  glm::dvec3 RadialMap(glm::dvec3 p) const noexcept {
    constexpr double kEps = 1e-9;
    for (const Cylinder& c : cylinders_) {
      const double s = p[c.axis];
      if (s < c.a0 - kEps || s > c.a1 + kEps) continue;
      const int b = (c.axis + 1) % 3, cc = (c.axis + 2) % 3;
      const glm::dvec2 d(p[b] - c.centre.x, p[cc] - c.centre.y);
      const double rho_inf = std::max(std::abs(d.x), std::abs(d.y));
      const double rho_2 = glm::length(d);
      if (rho_inf > c.radius + c.outer_blend + kEps || rho_2 < 1e-15) continue;
      double w;  // 1: full map, 0: identity
      if (rho_inf <= c.radius + kEps) {
        w = c.inner_blend > 0.0 ? Smoothstep(c.inner_blend, c.radius, rho_inf) : 1.0;
      } else {
        w = c.outer_blend > 0.0 ? 1.0 - Smoothstep(c.radius, c.radius + c.outer_blend, rho_inf)
                                : 0.0;
      }
      const double factor = 1.0 + (rho_inf / rho_2 - 1.0) * w;
      p[b] = c.centre.x + d.x * factor;
      p[cc] = c.centre.y + d.y * factor;
      return p;
    }
    return p;
  }

  // Blurred indicator F(p) ∈ [0, 1] (1 deep inside) and its gradient (1/m).
  double Eval(const glm::dvec3& p, glm::dvec3& grad) const noexcept {
    const double reach = 8.0 * sigma_;
    double f = 0.0;
    grad = glm::dvec3(0.0);
    for (const AxisBox& bx : boxes_) {
      if (p.x < bx.lo.x - reach || p.x > bx.hi.x + reach || p.y < bx.lo.y - reach ||
          p.y > bx.hi.y + reach || p.z < bx.lo.z - reach || p.z > bx.hi.z + reach) {
        continue;
      }
      const Interval ix = BlurredInterval(p.x, bx.lo.x, bx.hi.x, inv_sigma_);
      const Interval iy = BlurredInterval(p.y, bx.lo.y, bx.hi.y, inv_sigma_);
      const Interval iz = BlurredInterval(p.z, bx.lo.z, bx.hi.z, inv_sigma_);
      f += ix.value * iy.value * iz.value;
      grad += glm::dvec3(ix.derivative * iy.value * iz.value, ix.value * iy.derivative * iz.value,
                         ix.value * iy.value * iz.derivative);
    }
    for (const Cylinder& c : cylinders_) {
      const double s = p[c.axis];
      if (s < c.a0 - reach || s > c.a1 + reach) continue;
      const int b = (c.axis + 1) % 3, cc = (c.axis + 2) % 3;
      const glm::dvec2 d(p[b] - c.centre.x, p[cc] - c.centre.y);
      const double r = glm::length(d);
      if (r > c.radius + reach) continue;
      const double t = (c.radius - r) * inv_sigma_;
      const double radial = Cdf(t);
      const double radial_derivative = -Pdf(t) * inv_sigma_;  // d/dr
      const Interval ia = BlurredInterval(s, c.a0, c.a1, inv_sigma_);
      f += radial * ia.value;
      glm::dvec3 g(0.0);
      g[c.axis] = radial * ia.derivative;
      if (r > 1e-15) {
        g[b] = radial_derivative * ia.value * d.x / r;
        g[cc] = radial_derivative * ia.value * d.y / r;
      }
      grad += g;
    }
    return f;
  }

  // Newton steps along the gradient onto F = 0.5; throws std::logic_error when a point does not
  // converge (a layout whose polycube lies too far from its smoothed surface).
  glm::dvec3 Project(glm::dvec3 p) const {
    for (int it = 0; it < 60; ++it) {
      glm::dvec3 g;
      const double f = Eval(p, g) - 0.5;
      if (std::abs(f) < 1e-11) return p;
      const double g2 = glm::dot(g, g);
      if (!(g2 > 1e-6 * inv_sigma_ * inv_sigma_)) break;
      glm::dvec3 step = -f * g / g2;
      const double len = glm::length(step);
      if (len > sigma_) step *= sigma_ / len;
      p += step;
    }
    throw std::logic_error("seed model: projection onto the blurred solid did not converge");
  }

  // Unit outward normal of the level set through p.
  glm::dvec3 OutwardNormal(const glm::dvec3& p) const noexcept {
    glm::dvec3 g;
    Eval(p, g);
    return -glm::normalize(g);
  }

 private:
  double sigma_, inv_sigma_;
  std::vector<AxisBox> boxes_;
  std::vector<Cylinder> cylinders_;
};

// ---------------------------------------------------------------------------------------------
// Polycube surface: the boundary of a union of axis-aligned boxes, on the rectilinear grid made
// of every box face plane with each gap split into round(gap / cell) equal cells. Each boundary
// cell face becomes two triangles, counter-clockwise seen from outside; grid vertices are shared,
// so the surface is closed and 2-manifold as long as no two boxes touch only along an edge or at a
// corner.

struct GridAxis {
  std::vector<double> lines;  // sorted grid coordinates

  int IndexOf(double x) const {
    const auto it = std::lower_bound(lines.begin(), lines.end(), x - 1e-9);
    if (it == lines.end() || std::abs(*it - x) > 1e-9) {
      throw std::logic_error("seed model: box face not on the grid");
    }
    return static_cast<int>(it - lines.begin());
  }
};

inline GridAxis MakeGridAxis(std::vector<double> breaks, double cell) {
  std::sort(breaks.begin(), breaks.end());
  std::vector<double> merged;
  for (double b : breaks) {
    if (merged.empty() || b - merged.back() > 1e-9) merged.push_back(b);
  }
  GridAxis axis;
  for (size_t i = 0; i + 1 < merged.size(); ++i) {
    const double gap = merged[i + 1] - merged[i];
    const int n = std::max(1, static_cast<int>(std::lround(gap / cell)));
    for (int k = 0; k < n; ++k) axis.lines.push_back(merged[i] + gap * k / n);
  }
  axis.lines.push_back(merged.back());
  return axis;
}

struct QuadMesh {
  std::vector<glm::dvec3> vertices;
  std::vector<std::array<int, 4>> quads;  // counter-clockwise seen from outside
};

inline QuadMesh BuildPolycube(const std::vector<AxisBox>& boxes, const glm::dvec3& cell_size) {
  std::array<GridAxis, 3> axes;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> breaks;
    for (const AxisBox& b : boxes) {
      breaks.push_back(b.lo[a]);
      breaks.push_back(b.hi[a]);
    }
    axes[a] = MakeGridAxis(std::move(breaks), cell_size[a]);
  }
  const std::array<std::int64_t, 3> n = {static_cast<std::int64_t>(axes[0].lines.size()) - 1,
                                         static_cast<std::int64_t>(axes[1].lines.size()) - 1,
                                         static_cast<std::int64_t>(axes[2].lines.size()) - 1};
  std::vector<std::uint8_t> occupied(static_cast<size_t>(n[0] * n[1] * n[2]), 0);
  const auto cell_index = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return static_cast<size_t>(i + n[0] * (j + n[1] * k));
  };
  for (const AxisBox& b : boxes) {
    std::array<int, 3> lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = axes[a].IndexOf(b.lo[a]);
      hi[a] = axes[a].IndexOf(b.hi[a]);
    }
    for (int k = lo[2]; k < hi[2]; ++k) {
      for (int j = lo[1]; j < hi[1]; ++j) {
        for (int i = lo[0]; i < hi[0]; ++i) occupied[cell_index(i, j, k)] = 1;
      }
    }
  }

  // Scan the cells plane by plane along z; each boundary face becomes a quad of grid vertices,
  // counter-clockwise seen from outside. Grid vertices get their index on first use, through two
  // layers of per-(x, y) indices (the cell's lower and upper z planes).
  QuadMesh mesh;
  const std::int64_t layer_size = (n[0] + 1) * (n[1] + 1);
  std::array<std::vector<int>, 2> layers = {std::vector<int>(static_cast<size_t>(layer_size), -1),
                                            std::vector<int>(static_cast<size_t>(layer_size), -1)};
  const std::array<std::int64_t, 3> stride = {1, n[0], n[0] * n[1]};
  std::array<std::int64_t, 3> cell{};
  const auto vertex_of = [&](const std::array<std::int64_t, 3>& g) {
    int& id =
        layers[static_cast<size_t>(g[2] - cell[2])][static_cast<size_t>(g[0] + (n[0] + 1) * g[1])];
    if (id < 0) {
      id = static_cast<int>(mesh.vertices.size());
      mesh.vertices.push_back({axes[0].lines[static_cast<size_t>(g[0])],
                               axes[1].lines[static_cast<size_t>(g[1])],
                               axes[2].lines[static_cast<size_t>(g[2])]});
    }
    return id;
  };
  for (cell[2] = 0; cell[2] < n[2]; ++cell[2]) {
    for (cell[1] = 0; cell[1] < n[1]; ++cell[1]) {
      const size_t row = cell_index(0, cell[1], cell[2]);
      for (cell[0] = 0; cell[0] < n[0]; ++cell[0]) {
        const size_t here = row + static_cast<size_t>(cell[0]);
        if (occupied[here] == 0) continue;
        for (int a = 0; a < 3; ++a) {
          for (int dir = -1; dir <= 1; dir += 2) {
            const std::int64_t next = cell[a] + dir;
            if (next >= 0 && next < n[a] &&
                occupied[static_cast<std::int64_t>(here) + dir * stride[a]] != 0) {
              continue;
            }
            // Face on grid plane g[a] of axis a; corners counter-clockwise seen from +a (b, c
            // cyclic after a), reversed for an outward normal along −a.
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            std::array<std::int64_t, 3> g{};
            g[a] = dir > 0 ? cell[a] + 1 : cell[a];
            std::array<int, 4> q;
            const std::int64_t du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
            for (int k = 0; k < 4; ++k) {
              g[b] = cell[b] + du[k];
              g[c] = cell[c] + dv[k];
              q[k] = vertex_of(g);
            }
            if (dir < 0) std::swap(q[1], q[3]);
            mesh.quads.push_back(q);
          }
        }
      }
    }
    std::swap(layers[0], layers[1]);
    std::fill(layers[1].begin(), layers[1].end(), -1);
  }
  return mesh;
}

inline double Angle(const glm::dvec3& at, const glm::dvec3& a, const glm::dvec3& b) noexcept {
  const glm::dvec3 u = a - at, v = b - at;
  return std::atan2(glm::length(glm::cross(u, v)), glm::dot(u, v));
}

// Projects every polycube vertex onto the blurred solid, applies `warp(p, n)` (which may map the
// base point and its outward normal in place), splits each quad along the diagonal that makes the
// pair of triangles Delaunay on the base surface (the corner cells of a square mapped onto a
// circle would otherwise give slivers), and finally displaces every vertex along the base normal
// by `detail(p, n)·detail_scale`. The connectivity does not depend on the detail.
template <typename Warp, typename Detail>
inline TriangleMesh ShapeFromPolycube(const BlurredSolid& solid, const glm::dvec3& cell,
                                      double detail_scale, const Warp& warp, const Detail& detail) {
  QuadMesh quads = BuildPolycube(solid.PolycubeBoxes(), cell);
  std::vector<glm::dvec3> normals(quads.vertices.size());
  for (size_t i = 0; i < quads.vertices.size(); ++i) {
    glm::dvec3 p = solid.Project(solid.RadialMap(quads.vertices[i]));
    glm::dvec3 n = solid.OutwardNormal(p);
    warp(p, n);
    quads.vertices[i] = p;
    normals[i] = n;
  }
  TriangleMesh mesh;
  mesh.triangles.reserve(2 * quads.quads.size());
  for (const std::array<int, 4>& q : quads.quads) {
    const glm::dvec3& p0 = quads.vertices[q[0]];
    const glm::dvec3& p1 = quads.vertices[q[1]];
    const glm::dvec3& p2 = quads.vertices[q[2]];
    const glm::dvec3& p3 = quads.vertices[q[3]];
    if (Angle(p1, p0, p2) + Angle(p3, p2, p0) <= std::numbers::pi) {  // diagonal 0-2 is Delaunay
      mesh.triangles.push_back({q[0], q[1], q[2]});
      mesh.triangles.push_back({q[0], q[2], q[3]});
    } else {
      mesh.triangles.push_back({q[0], q[1], q[3]});
      mesh.triangles.push_back({q[1], q[2], q[3]});
    }
  }
  mesh.vertices = std::move(quads.vertices);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    mesh.vertices[i] += detail_scale * detail(mesh.vertices[i], normals[i]) * normals[i];
  }
  return mesh;
}

// Plane-wave noise: the sum of `count` cosines with quasi-random directions, phases and periods
// in [min_period, max_period] (log-uniform), scaled to unit RMS. Deterministic.
class PlaneWaveNoise {
 public:
  PlaneWaveNoise(int count, double min_period, double max_period, double seed) {
    for (int i = 0; i < count; ++i) {
      const double u = Fract((i + 0.5) * 0.6180339887498949 + seed * 0.3710);
      const double v = Fract((i + 0.5) * 0.7548776662466927 + seed * 0.5698);
      const double w = Fract((i + 0.5) * 0.5698402909980532 + seed * 0.1234);
      const double z = 2.0 * u - 1.0, s = std::sqrt(std::max(0.0, 1.0 - z * z));
      const double phi = kTwoPi * v;
      const double period = min_period * std::pow(max_period / min_period, w);
      waves_.push_back({glm::dvec3(s * std::cos(phi), s * std::sin(phi), z) * (kTwoPi / period),
                        kTwoPi * Fract(i * 0.3819660112501051 + seed * 0.77)});
    }
    scale_ = std::sqrt(2.0 / count);
  }
  double operator()(const glm::dvec3& p) const noexcept {
    double sum = 0.0;
    for (const Wave& w : waves_) sum += std::cos(glm::dot(w.k, p) + w.phase);
    return sum * scale_;
  }

 private:
  struct Wave {
    glm::dvec3 k;
    double phase;
  };
  std::vector<Wave> waves_;
  double scale_ = 1.0;
};

// Asymmetric saw tooth of period 1 in [0, 1]: rises over the first 75 %, falls over the rest.
inline double SawTooth(double s) noexcept {
  const double t = Fract(s);
  constexpr double kRise = 0.75;
  return t < kRise ? t / kRise : (1.0 - t) / (1.0 - kRise);
}

inline void ValidateDetail(double detail_scale) {
  RequireFinite(detail_scale, "detail_scale");
  Require(detail_scale >= 0.0, "detail_scale must be >= 0");
}

}  // namespace ht::seed_shapes
