#include "haptic_core/demo/seed_models.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>
#include <stdexcept>
#include <string>

#include "haptic_core/demo/procedural_models.h"

namespace ht {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

void RequirePositive(double v, const char* what) {
  if (!(v > 0.0)) {
    throw std::invalid_argument(std::string(what) + " must be positive, got " + std::to_string(v));
  }
}

void RequireFinite(double v, const char* what) {
  if (!std::isfinite(v)) throw std::invalid_argument(std::string(what) + " must be finite");
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

double Smoothstep(double e0, double e1, double x) noexcept {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

double Fract(double x) noexcept { return x - std::floor(x); }

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

GridAxis MakeGridAxis(std::vector<double> breaks, double cell) {
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

QuadMesh BuildPolycube(const std::vector<AxisBox>& boxes, const glm::dvec3& cell_size) {
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

double Angle(const glm::dvec3& at, const glm::dvec3& a, const glm::dvec3& b) noexcept {
  const glm::dvec3 u = a - at, v = b - at;
  return std::atan2(glm::length(glm::cross(u, v)), glm::dot(u, v));
}

// Projects every polycube vertex onto the blurred solid, applies `warp(p, n)` (which may map the
// base point and its outward normal in place), splits each quad along the diagonal that makes the
// pair of triangles Delaunay on the base surface (the corner cells of a square mapped onto a
// circle would otherwise give slivers), and finally displaces every vertex along the base normal
// by `detail(p, n)·detail_scale`. The connectivity does not depend on the detail.
template <typename Warp, typename Detail>
TriangleMesh ShapeFromPolycube(const BlurredSolid& solid, const glm::dvec3& cell,
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
double SawTooth(double s) noexcept {
  const double t = Fract(s);
  constexpr double kRise = 0.75;
  return t < kRise ? t / kRise : (1.0 - t) / (1.0 - kRise);
}

void ValidateDetail(double detail_scale) {
  RequireFinite(detail_scale, "detail_scale");
  Require(detail_scale >= 0.0, "detail_scale must be >= 0");
}

}  // namespace

// ---------------------------------------------------------------------------------------------

TriangleMesh MakeTexturedHammerFullResolution(const TexturedHammerParams& p) {
  RequirePositive(p.head_half_extents_m.x, "hammer head half extent x");
  RequirePositive(p.head_half_extents_m.y, "hammer head half extent y");
  RequirePositive(p.head_half_extents_m.z, "hammer head half extent z");
  RequirePositive(p.length_m, "hammer length");
  RequirePositive(p.handle_radius_m, "hammer handle radius");
  RequirePositive(p.edge_blur_m, "hammer edge blur");
  RequirePositive(p.knurl_period_m, "hammer knurl period");
  RequirePositive(p.peen_min_period_m, "hammer peen min period");
  RequirePositive(p.peen_max_period_m, "hammer peen max period");
  RequirePositive(p.cell_size_m.x, "hammer cell size x");
  RequirePositive(p.cell_size_m.y, "hammer cell size y");
  RequirePositive(p.cell_size_m.z, "hammer cell size z");
  RequireFinite(p.knurl_amplitude_m, "hammer knurl amplitude");
  RequireFinite(p.peen_amplitude_m, "hammer peen amplitude");
  ValidateDetail(p.detail_scale);
  const glm::dvec3 hh = p.head_half_extents_m;
  const double R = p.handle_radius_m;
  const double outer_blend = 3.0e-3;
  Require(R + outer_blend + 2.0 * p.edge_blur_m <= std::min(hh.x, hh.y),
          "hammer handle radius must leave a ledge under the head (radius + 3 mm + 2σ <= head "
          "half extents x and y)");
  const double z_top = 0.5 * p.length_m, z_bottom = -0.5 * p.length_m;
  const double z_head = z_top - 2.0 * hh.z;
  Require(z_head - z_bottom > 4.0 * R, "hammer handle must be longer than 4 radii");

  BlurredSolid solid(p.edge_blur_m);
  solid.AddBox({-hh.x, -hh.y, z_head}, {hh.x, hh.y, z_top});
  solid.AddCylinder({2, {0.0, 0.0}, R, z_bottom, z_head, 0.0, outer_blend});

  const int starts = std::max(1, static_cast<int>(std::lround(kTwoPi * R / p.knurl_period_m)));
  const double grip0 = z_bottom + p.grip_start_m, grip1 = grip0 + p.grip_length_m;
  const double fade = 3.0e-3;
  const PlaneWaveNoise peen(8, p.peen_min_period_m, p.peen_max_period_m, 1.0);
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double radial = std::sqrt(n.x * n.x + n.y * n.y);
    const double w_knurl = Smoothstep(grip0, grip0 + fade, q.z) *
                           (1.0 - Smoothstep(grip1 - fade, grip1, q.z)) *
                           Smoothstep(0.85, 0.97, radial);
    double h = 0.0;
    if (w_knurl > 0.0) {
      const double theta = std::atan2(q.y, q.x);
      h += w_knurl * p.knurl_amplitude_m * std::cos(starts * theta) *
           std::cos(kTwoPi * q.z / p.knurl_period_m);
    }
    const double w_head = Smoothstep(z_head - 4.0e-3, z_head, q.z);
    if (w_head > 0.0) h += w_head * p.peen_amplitude_m * std::tanh(0.5 * peen(q));
    return h;
  };
  return ShapeFromPolycube(
      solid, p.cell_size_m, p.detail_scale, [](glm::dvec3&, glm::dvec3&) {}, detail);
}

TriangleMesh MakeRoughCadPartFullResolution(const RoughCadPartParams& p) {
  RequirePositive(p.plate_half_extents_m.x, "CAD part plate half extent x");
  RequirePositive(p.plate_half_extents_m.y, "CAD part plate half extent y");
  RequirePositive(p.boss_radius_m, "CAD part boss radius");
  RequirePositive(p.pin_radius_m, "CAD part pin radius");
  RequirePositive(p.edge_blur_m, "CAD part edge blur");
  RequirePositive(p.mill_period_m, "CAD part mill period");
  RequirePositive(p.wall_period_m, "CAD part wall period");
  RequirePositive(p.rough_min_period_m, "CAD part roughness min period");
  RequirePositive(p.rough_max_period_m, "CAD part roughness max period");
  RequirePositive(p.cell_size_m.x, "CAD part cell size x");
  RequirePositive(p.cell_size_m.y, "CAD part cell size y");
  RequirePositive(p.cell_size_m.z, "CAD part cell size z");
  RequireFinite(p.mill_amplitude_m, "CAD part mill amplitude");
  RequireFinite(p.wall_amplitude_m, "CAD part wall amplitude");
  RequireFinite(p.rough_amplitude_m, "CAD part roughness amplitude");
  ValidateDetail(p.detail_scale);
  const double hx = p.plate_half_extents_m.x, hy = p.plate_half_extents_m.y;
  const double boss_blend = 5.0e-3, pin_blend = 3.0e-3;
  Require(p.bottom_z_m < p.plate_top_z_m && p.plate_top_z_m < p.slot_floor_z_m &&
              p.slot_floor_z_m < p.step_top_z_m && p.step_top_z_m < p.pin_top_z_m &&
              p.plate_top_z_m < p.boss_top_z_m,
          "CAD part heights must increase: bottom < plate top < slot floor < step top < pin top, "
          "plate top < boss top");
  Require(
      -hx < p.step_start_x_m && p.step_start_x_m < p.slot_start_x_m && p.slot_start_x_m < hx &&
          0.0 < p.slot_half_width_m && p.slot_half_width_m < hy,
      "CAD part layout along x/y: -hx < step start < slot start < hx, 0 < slot half width < hy");
  Require(p.boss_centre_m.x + p.boss_radius_m + boss_blend < p.step_start_x_m &&
              p.boss_centre_m.x - p.boss_radius_m - boss_blend > -hx &&
              p.boss_centre_m.y - p.boss_radius_m - boss_blend > 0.0 &&
              p.boss_centre_m.y + p.boss_radius_m + boss_blend < hy,
          "CAD part bosses must stand on the low plate, 5 mm clear of its edges and the x axis");
  Require(p.pin_centre_m.x - p.pin_radius_m - pin_blend > p.step_start_x_m &&
              p.pin_centre_m.x + p.pin_radius_m + pin_blend < hx &&
              p.pin_centre_m.y - p.pin_radius_m - pin_blend > p.slot_half_width_m &&
              p.pin_centre_m.y + p.pin_radius_m + pin_blend < hy,
          "CAD part pins must stand on the step, 3 mm clear of its edges and the slot");

  BlurredSolid solid(p.edge_blur_m);
  const double sw = p.slot_half_width_m;
  solid.AddBox({-hx, -hy, p.bottom_z_m}, {hx, hy, p.plate_top_z_m});
  solid.AddBox({p.step_start_x_m, -hy, p.plate_top_z_m}, {hx, -sw, p.step_top_z_m});
  solid.AddBox({p.step_start_x_m, sw, p.plate_top_z_m}, {hx, hy, p.step_top_z_m});
  solid.AddBox({p.step_start_x_m, -sw, p.plate_top_z_m}, {p.slot_start_x_m, sw, p.step_top_z_m});
  solid.AddBox({p.slot_start_x_m, -sw, p.plate_top_z_m}, {hx, sw, p.slot_floor_z_m});
  for (double sy : {-1.0, 1.0}) {
    solid.AddCylinder({2,
                       {p.boss_centre_m.x, sy * p.boss_centre_m.y},
                       p.boss_radius_m,
                       p.plate_top_z_m,
                       p.boss_top_z_m,
                       0.0,
                       boss_blend});
    solid.AddCylinder({2,
                       {p.pin_centre_m.x, sy * p.pin_centre_m.y},
                       p.pin_radius_m,
                       p.step_top_z_m,
                       p.pin_top_z_m,
                       0.0,
                       pin_blend});
  }

  const glm::dvec2 cutter_centre(-3.0 * hx, 0.4 * hy);
  const PlaneWaveNoise rough(8, p.rough_min_period_m, p.rough_max_period_m, 2.0);
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double w_flat = Smoothstep(0.5, 0.9, std::abs(n.z));
    const double mill =
        p.mill_amplitude_m *
        std::cos(kTwoPi * glm::length(glm::dvec2(q.x, q.y) - cutter_centre) / p.mill_period_m);
    const double wall = p.wall_amplitude_m * std::cos(kTwoPi * q.z / p.wall_period_m);
    return w_flat * mill + (1.0 - w_flat) * wall + p.rough_amplitude_m * std::tanh(0.5 * rough(q));
  };
  return ShapeFromPolycube(
      solid, p.cell_size_m, p.detail_scale, [](glm::dvec3&, glm::dvec3&) {}, detail);
}

TriangleMesh MakeToothedFileFullResolution(const ToothedFileParams& p) {
  RequirePositive(p.handle_length_m, "file handle length");
  RequirePositive(p.handle_radius_m, "file handle radius");
  RequirePositive(p.neck_length_m, "file neck length");
  RequirePositive(p.neck_half_width_m, "file neck half width");
  RequirePositive(p.neck_half_thickness_m, "file neck half thickness");
  RequirePositive(p.blade_length_m, "file blade length");
  RequirePositive(p.blade_half_width_m, "file blade half width");
  RequirePositive(p.blade_half_thickness_m, "file blade half thickness");
  RequirePositive(p.taper_length_m, "file taper length");
  RequirePositive(p.tip_width_scale, "file tip width scale");
  RequirePositive(p.tip_thickness_scale, "file tip thickness scale");
  RequirePositive(p.edge_blur_m, "file edge blur");
  RequirePositive(p.overcut_period_m, "file overcut period");
  RequirePositive(p.upcut_period_m, "file upcut period");
  RequirePositive(p.edge_tooth_period_m, "file edge tooth period");
  RequirePositive(p.grip_period_m, "file grip period");
  RequirePositive(p.cell_size_m.x, "file cell size x");
  RequirePositive(p.cell_size_m.y, "file cell size y");
  RequirePositive(p.cell_size_m.z, "file cell size z");
  RequireFinite(p.tooth_amplitude_m, "file tooth amplitude");
  RequireFinite(p.edge_tooth_amplitude_m, "file edge tooth amplitude");
  RequireFinite(p.grip_amplitude_m, "file grip amplitude");
  ValidateDetail(p.detail_scale);
  const double neck_extent = std::max(p.neck_half_width_m, p.neck_half_thickness_m);
  Require(p.taper_length_m <= p.blade_length_m, "file taper must not be longer than the blade");
  Require(p.tip_width_scale <= 1.0 && p.tip_thickness_scale <= 1.0,
          "file tip scales must be in (0, 1]");
  // The handle's radial map is blended in from neck_extent + 0.5 mm; it stays monotone along
  // each ray (no folds on the end faces) while that is at most half the radius.
  Require(neck_extent + 0.5e-3 <= 0.5 * p.handle_radius_m,
          "file neck must fit well inside the handle (max neck half size + 0.5 mm <= handle "
          "radius / 2)");
  Require(p.neck_half_width_m < p.blade_half_width_m &&
              p.neck_half_thickness_m < p.blade_half_thickness_m,
          "file neck must be narrower and thinner than the blade");
  const double x_handle = -0.5 * p.TotalLength();
  const double x_neck = x_handle + p.handle_length_m;
  const double x_blade = x_neck + p.neck_length_m;
  const double x_tip = x_blade + p.blade_length_m;
  const double x_taper = x_tip - p.taper_length_m;

  BlurredSolid solid(p.edge_blur_m);
  solid.AddCylinder(
      {0, {0.0, 0.0}, p.handle_radius_m, x_handle, x_neck, neck_extent + 0.5e-3, 0.0});
  solid.AddBox({x_neck, -p.neck_half_width_m, -p.neck_half_thickness_m},
               {x_blade, p.neck_half_width_m, p.neck_half_thickness_m});
  solid.AddBox({x_blade, -p.blade_half_width_m, -p.blade_half_thickness_m},
               {x_tip, p.blade_half_width_m, p.blade_half_thickness_m});

  // Taper D(x, y, z) = (x, y·a(x), z·b(x)); normals map by the inverse transpose of its Jacobian.
  const auto taper = [&](glm::dvec3& q, glm::dvec3& n) {
    if (q.x <= x_taper) return;
    const double t = std::min(1.0, (q.x - x_taper) / p.taper_length_m);
    const double a = 1.0 - (1.0 - p.tip_width_scale) * t * t;
    const double b = 1.0 - (1.0 - p.tip_thickness_scale) * t * t;
    const double da = t < 1.0 ? -(1.0 - p.tip_width_scale) * 2.0 * t / p.taper_length_m : 0.0;
    const double db = t < 1.0 ? -(1.0 - p.tip_thickness_scale) * 2.0 * t / p.taper_length_m : 0.0;
    n = glm::normalize(glm::dvec3(n.x - q.y * da / a * n.y - q.z * db / b * n.z, n.y / a, n.z / b));
    q.y *= a;
    q.z *= b;
  };
  const double c1 = std::cos(65.0 * std::numbers::pi / 180.0),
               s1 = std::sin(65.0 * std::numbers::pi / 180.0);
  const double c2 = std::cos(-45.0 * std::numbers::pi / 180.0),
               s2 = std::sin(-45.0 * std::numbers::pi / 180.0);
  const double fade = 2.0e-3;
  const auto detail = [&](const glm::dvec3& q, const glm::dvec3& n) {
    const double w_blade = Smoothstep(x_blade + 4.0e-3, x_blade + 4.0e-3 + fade, q.x) *
                           (1.0 - Smoothstep(x_tip - 3.0e-3 - fade, x_tip - 3.0e-3, q.x));
    double h = 0.0;
    if (w_blade > 0.0) {
      const double w_face = Smoothstep(0.85, 0.97, std::abs(n.z));
      const double w_edge = Smoothstep(0.85, 0.97, n.y);
      // Coordinates across the cuts (crest lines at +65° and −45° to the axis).
      const double u1 = -q.x * s1 + q.y * c1, u2 = -q.x * s2 + q.y * c2;
      const double teeth = p.tooth_amplitude_m * std::min(SawTooth(u1 / p.overcut_period_m),
                                                          SawTooth(u2 / p.upcut_period_m));
      const double edge = p.edge_tooth_amplitude_m * SawTooth(q.x / p.edge_tooth_period_m);
      h += w_blade * (w_face * teeth + w_edge * edge);
    }
    const double w_grip = Smoothstep(x_handle + 5.0e-3, x_handle + 5.0e-3 + fade, q.x) *
                          (1.0 - Smoothstep(x_neck - 5.0e-3 - fade, x_neck - 5.0e-3, q.x)) *
                          Smoothstep(0.85, 0.97, std::sqrt(n.y * n.y + n.z * n.z));
    h += w_grip * p.grip_amplitude_m * std::cos(kTwoPi * q.x / p.grip_period_m);
    return h;
  };
  return ShapeFromPolycube(solid, p.cell_size_m, p.detail_scale, taper, detail);
}

TriangleMesh MakeWrinkledTorusFullResolution(const WrinkledTorusParams& p) {
  RequirePositive(p.major_radius_m, "torus major radius");
  RequirePositive(p.minor_radius_m, "torus minor radius");
  RequireFinite(p.wrinkle_amplitude_m, "torus wrinkle amplitude");
  ValidateDetail(p.detail_scale);
  Require(p.minor_radius_m + std::abs(p.wrinkle_amplitude_m) < p.major_radius_m,
          "torus minor radius plus wrinkle amplitude must be below the major radius");
  Require(std::abs(p.wrinkle_amplitude_m) < 0.5 * p.minor_radius_m,
          "torus wrinkle amplitude must be below half the minor radius");
  Require(p.major_segments >= 3 && p.tube_segments >= 3,
          "torus needs at least 3 major and 3 tube segments");
  const int nu = p.major_segments, nv = p.tube_segments;
  const double R = p.major_radius_m, r = p.minor_radius_m;
  const double A = p.detail_scale * p.wrinkle_amplitude_m;
  TriangleMesh mesh;
  mesh.vertices.reserve(static_cast<size_t>(nu) * nv);
  for (int i = 0; i < nu; ++i) {
    const double theta = kTwoPi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double phi = kTwoPi * j / nv;
      const glm::dvec3 n(std::cos(phi) * std::cos(theta), std::cos(phi) * std::sin(theta),
                         std::sin(phi));
      const double rho = r + A * std::sin(p.major_waves * theta + p.tube_waves * phi);
      mesh.vertices.push_back(R * glm::dvec3(std::cos(theta), std::sin(theta), 0.0) + rho * n);
    }
  }
  // (i along θ, j along φ): ∂p/∂θ × ∂p/∂φ points out of the tube.
  const auto idx = [nu, nv](int i, int j) { return (i % nu) * nv + (j % nv); };
  mesh.triangles.reserve(2 * static_cast<size_t>(nu) * nv);
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      mesh.triangles.push_back({idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)});
      mesh.triangles.push_back({idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)});
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------

const std::vector<SeedModelSpec>& SeedModelSpecs() {
  static const std::vector<SeedModelSpec> kSpecs = {
      {SeedModel::kBlock, "block", 65536, 16, 1},
      {SeedModel::kGear, "gear", 25600, 1600, 1},
      {SeedModel::kHammer, "hammer", 433152, 518, 210},
      {SeedModel::kCadPart, "cad_part", 658432, 720, 390},
      {SeedModel::kFile, "file", 285824, 632, 113},
      {SeedModel::kTorus, "torus", 128000, 532, 114},
  };
  return kSpecs;
}

const SeedModelSpec& SeedModelSpecOf(SeedModel model) {
  for (const SeedModelSpec& s : SeedModelSpecs()) {
    if (s.model == model) return s;
  }
  throw std::invalid_argument("unknown SeedModel value " + std::to_string(static_cast<int>(model)));
}

const char* SeedModelName(SeedModel model) { return SeedModelSpecOf(model).name; }

SeedModel ParseSeedModelName(const std::string& name) {
  std::string valid;
  for (const SeedModelSpec& s : SeedModelSpecs()) {
    if (name == s.name) return s.model;
    valid += valid.empty() ? "" : ", ";
    valid += s.name;
  }
  throw std::invalid_argument("unknown seed model '" + name + "'; valid names: " + valid);
}

TriangleMesh MakeSeedModelFullResolution(SeedModel model) {
  switch (model) {
    case SeedModel::kBlock:
      return MakeRidgedBlockFullResolution();
    case SeedModel::kGear:
      return MakeRidgedGearFullResolution();
    case SeedModel::kHammer:
      return MakeTexturedHammerFullResolution();
    case SeedModel::kCadPart:
      return MakeRoughCadPartFullResolution();
    case SeedModel::kFile:
      return MakeToothedFileFullResolution();
    case SeedModel::kTorus:
      return MakeWrinkledTorusFullResolution();
  }
  throw std::invalid_argument("unknown SeedModel value " + std::to_string(static_cast<int>(model)));
}

}  // namespace ht
