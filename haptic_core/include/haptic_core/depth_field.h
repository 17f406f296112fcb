#pragma once
// The contact model's depth field (DESIGN.md §5): the two surfaces of one contact window, the
// environment's heights b and the tool's heights a along the window's normal on its grid, over
// the window grown by a travel margin. The operator's loop evaluates the seed's directional
// penetration depth δ = max over cells of (b − a) on them at the tool's current pose, every tick,
// instead of a linearization taken at the pose q0 the remote node answered.

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/contact_windows.h"
#include "haptic_core/spatial.h"

namespace ht {

/// Width ε (m) of a depth field's smooth maximum (DepthFieldDepthAt): δ = ε·ln Σ exp(δ_j/ε) over
/// the tool's nodes j, which lies within [max δ_j, max δ_j + ε·ln M] (M the nodes within a few ε
/// of the maximum), so that ∇δ is continuous where the deepest node changes (a face tilting over
/// the edge it rests on, a slide over a ridge's crest) and the implicit step can be given the
/// maximum's curvature.
inline constexpr double kDepthFieldSmoothMaxM = 2e-6;

/// The force law a depth field is evaluated with (DepthFieldDepthAt; the remote node's choice for
/// its session, stamped on every field it renders):
///  - kSeed: the seed's directional penetration depth δ, the smooth maximum of the tool nodes'
///    overlaps, and its penalty F = −k δ ∇δ [S][L]: one point, the deepest, bears.
///  - kPressure: a pressure p_j = k_p d_j on every tool node's overlap d_j = max(0, b − a_q), the
///    potential U = ½ k_p Σ_j A d_j² (A the tool's area a node stands for, m²) and the wrench
///    −∇U (the discrete form of a hydroelastic pressure field, Elandt et al. 2019 [R]): every
///    overlapping node bears, so that the torque of a face resting on many ridges is the
///    pressures' moment. k_p = k / A_ref (N/m³; DepthField::pressure_area_m2).
enum class ForceLaw : std::uint8_t { kSeed = 0, kPressure = 1 };

/// Side (nodes) of the blocks a depth field's evaluation prunes by (DepthField::env_block_bound_m),
/// of the sub-blocks it prunes a block's nodes by in turn (env_sub_bound_m), and of the
/// super-blocks it prunes blocks by first (env_super_bound_m).
inline constexpr int kDepthFieldBlock = 8;
inline constexpr int kDepthFieldSubBlock = 4;
inline constexpr int kDepthFieldSuperBlock = 32;

/// Most tool nodes one evaluation of a field computes in the operator's loop (DepthFieldCache):
/// beyond, the evaluation stops (DepthFieldEvaluation::over_budget) and the cache renders that
/// field's contact from its linearization for the field's lifetime, so that the 1 kHz tick
/// stays bounded. A face resting on the gear's ridges computes up to ~4,600 nodes; two blocks'
/// interlocked stripes (seed Fig. 76) up to ~38,000, which would take ~1 ms a field.
inline constexpr int kDepthFieldMaxNodes = 8192;

/// Most tool nodes a prepared field's evaluation at its own pose X_WT0 computes: where more of
/// them lie within the smooth maximum's cutoff of the deepest (surfaces that bear over a wide
/// area, as the striped blocks' interlocked stripes of seed Fig. 76), DepthField::Prepare keeps
/// only every s-th tool node of the tool's lattice along each axis (s = 2, 4, …,
/// kMaxDepthFieldNodeStride, the smallest that brings it within this), so that the loop
/// evaluates such a field in bounded time instead of falling back to its linearization. The
/// nodes kept are fixed on the tool's lattice, so that successive fields keep the same ones.
inline constexpr int kDepthFieldDenseNodes = 2048;
/// kDepthFieldDenseNodes under ForceLaw::kPressure, whose evaluation computes every node that
/// overlaps, and more of them as the tool presses deeper than the pose the field was rendered
/// at: the node spacing is the law's quadrature step. On the gear (seed Fig. 75) at 25 ms one
/// way (`deadband_lockstep --scene block-on-gear --arm …,pressure=1`), 2,048 left fields that
/// passed kDepthFieldMaxNodes at the operator's pose in 19 % of ticks (their contacts rendered
/// from the linearization) and an operator tick p99 of 413 µs; 512, none and 149 µs. A field
/// with a stride hint (DepthField::stride_hint) keeps the hinted stride while its evaluation at
/// X_WT0 computes between an eighth of this and this many nodes.
inline constexpr int kDepthFieldDensePressureNodes = 512;
/// The same for the tool nodes whose own cell's bound the evaluation at X_WT0 tests (most of them
/// rejected): surfaces interlocked over a wide area (seed Fig. 76's stripes) pass the blocks'
/// bounds with most of their nodes and cost the loop ~25 ns a node tested. On Fig. 76 at 25 ms
/// (`deadband_lockstep --scene striped-blocks`) the operator tick's p99 is 444 µs with this bound
/// and 685 µs without; the gear's fields (seed Fig. 75) stay whole.
inline constexpr int kDepthFieldDenseTestedNodes = 8192;
/// Largest DepthField::node_stride.
inline constexpr int kMaxDepthFieldNodeStride = 8;

/// The range of the pressure law's reference area A_ref (m², DepthField::pressure_area_m2) a
/// field may carry: from a 10 µm square to a 10 m one, so that Σ A d² / A_ref stays finite.
inline constexpr double kMinPressureAreaM2 = 1e-10;
inline constexpr double kMaxPressureAreaM2 = 1e2;

/// Largest number of nodes per side of a depth field's grid (the window's N plus twice the travel
/// margin, in cells): bounds the memory the operator's loop preallocates per field.
inline constexpr int kMaxDepthFieldSide = 256;

/// The least cosine between an environment triangle's face normal and a field's normal n for
/// the triangle to be rendered into the field (cos 75°; the texture stage's own renders take
/// every triangle above kPatchFacingThreshold, 87°). Nearly edge-on, a triangle's heights along n
/// span millimetres within a cell: the rim of a thin fin seen along the fin's normal reads
/// millimetres above the fin's face at single nodes, spikes whose bicubic slopes turn the
/// contact's force sideways, one way or the other as the tool moves by a cell.
inline constexpr double kDepthFieldFacingThreshold = 0.26;

/// The steepest an environment's surface falls away in a rendered field (tan 75°, the slope at
/// kDepthFieldFacingThreshold; LimitDepthMapDescent). Where two surfaces that both face n lie
/// one behind the other (beyond a thin fin's rim, seen along the fin's normal, the next fin's
/// face millimetres further back), b steps between two nodes: the bicubic across the step
/// overshoots the upper surface by up to 7 % of the step with slopes of the step over a cell
/// (tens), so that the deepest node sits on a bump whose sides push the tool sideways, one way
/// and the other from tick to tick, at the contact force's bound. Textures no steeper than this
/// are left as they are.
inline constexpr double kDepthFieldMaxDescentSlope = 3.73;

/// Limits how steeply `heights_m` (#nx·ny, row-major, m, NaN: no surface) falls away from any
/// node: each node is raised to the highest of b_j − max_slope·d_ij over the other nodes j (d_ij
/// their distance, m, on the grid of spacing `cell_m`, along the axes and diagonals), so that a
/// step becomes a chamfer of slope max_slope below its upper edge and a node without a surface
/// takes that chamfer's height (it stays NaN only in a map without any surface). Surfaces no
/// steeper than max_slope are unchanged. noexcept; allocation-free; does nothing for bad sizes.
void LimitDepthMapDescent(int nx, int ny, double cell_m, double max_slope,
                          std::vector<float>& heights_m) noexcept;

/// One contact window's two surfaces (our construction [R] on the seed's directional penetration
/// depth [S][L]). Frame F: origin at grid node (0, 0), x along the lattice's u, y along v, z
/// along its normal n (from the environment towards the tool); environment node (i, j) lies at
/// (i·h, j·h, 0) in F and tool node (i, j) at (i·h + tool_offset_u_m, j·h + tool_offset_v_m)
/// at X_WT0, h = cell_m (DepthFieldRenderer puts both on lattices fixed in their objects' frames).
///  - env_height_m[j·nx + i] = b: the height along z_F of the environment's surface facing +n
///    at the node (m; sampled at the node, the topmost where several surfaces lie over it, with
///    the texture's mip level at the cell, as the texture stage renders it), NaN where the
///    environment has no surface there. b is fixed in the environment's frame. Triangles
///    nearly edge-on to n are not rendered (kDepthFieldFacingThreshold), and b nowhere falls
///    away more steeply than kDepthFieldMaxDescentSlope (LimitDepthMapDescent): beyond the
///    surface's edges it falls away at that slope, and NaN remains only in a field without
///    surface.
///  - tool_height_m[j·nx + i] = a: the height along z_F of the tool's surface facing −n under
///    tool node (i, j) at the pose X_WT0 (m; the lowest where several lie over it), NaN where
///    none. The tool's nodes are
///    points of the tool p_F(i, j) = (i·h + tool_offset_u_m, j·h + tool_offset_v_m, a) at
///    X_WT0, which move rigidly with the tool.
/// At a tool pose X_WT each tool node j moves to s_j = X_FW·X_WT·X_WT0⁻¹·X_WF·p_F(j) and reads the
/// environment there: δ_j = b(s_j.x, s_j.y) − s_j.z, b interpolated between nodes by a
/// Catmull–Rom bicubic (its gradient continuous across cell edges). The field holds the whole
/// overlap while every tool node moved at most travel_margin_m in F's plane from where it was at
/// X_WT0 (DepthFieldEvaluation::within_margin).
struct DepthField {
  /// The remote node's id of this field within its session (0: no field).
  std::uint32_t id = 0;
  RigidTransform X_WF;               ///< Frame F in W (m).
  double cell_m = 0.0;               ///< Node spacing h (m), > 0.
  int nx = 0, ny = 0;                ///< Nodes along x_F and y_F (4..kMaxDepthFieldSide).
  std::vector<float> env_height_m;   ///< b, #nx·ny, row-major j·nx + i (m).
  std::vector<float> tool_height_m;  ///< a at X_WT0, #nx·ny, row-major j·nx + i (m).
  /// The tool nodes' offset from the environment's along x_F and y_F (m, |offset| ≤ h).
  double tool_offset_u_m = 0.0, tool_offset_v_m = 0.0;
  /// Where the maps lie on their lattices (DepthFieldLattice; what a receiver caches surface
  /// by): the lattice's id (0: none), and node (0, 0)'s whole-cell coordinates along u and v on
  /// the environment's lattice and on the tool's.
  std::uint32_t lattice_id = 0;
  std::int32_t lattice_i0 = 0, lattice_j0 = 0, tool_lattice_i0 = 0, tool_lattice_j0 = 0;
  RigidTransform X_WT0;  ///< The tool pose a was rendered at (T at the tool's CoM).
  /// How far (m) the tool's surface may move in F's plane from where it was at X_WT0 before the
  /// field may miss part of the overlap: the margin by which the grid exceeds the window on each
  /// side.
  double travel_margin_m = 0.0;
  /// Smooth-maximum width ε (m, > 0; the seed law's).
  double smooth_max_m = kDepthFieldSmoothMaxM;
  /// The law the field is evaluated with, and for kPressure the reference area A_ref (m², > 0)
  /// that sets the pressure stiffness k_p = k / A_ref from the contact's k: a flat face of area
  /// A_ref pressed d into a flat plate is pushed back with k·d under either law.
  ForceLaw force_law = ForceLaw::kSeed;
  double pressure_area_m2 = 0.0;
  /// Under kPressure, the node stride the sender's last field on this lattice kept (1, 2, 4 or
  /// kMaxDepthFieldNodeStride; 0: none), which Prepare keeps while the field's own node count
  /// allows (kDepthFieldDensePressureNodes): successive fields then take the same quadrature,
  /// and the force does not step where one would keep every 2nd node and the next every 4th.
  std::uint8_t stride_hint = 0;

  // Derived by Prepare (the receiver's work, off the loop).
  /// Per grid cell (i, j) (between nodes i, i+1 and j, j+1; #nx·ny, row-major, the last row and
  /// column unused): an upper bound on the bicubic b over that cell (m), −∞ where its 4×4 stencil
  /// is incomplete (no interpolant there).
  std::vector<float> env_bound_m;
  /// The tool nodes the evaluation takes (kDepthFieldDenseNodes): those whose lattice
  /// coordinates (tool_lattice_i0 + i, tool_lattice_j0 + j) are both multiples of node_stride
  /// (1: all), as a grid of tool_nx × tool_ny (row-major) whose node (p, q) is tool node
  /// (tool_i0 + p·node_stride, tool_j0 + q·node_stride).
  int node_stride = 1;
  int tool_i0 = 0, tool_j0 = 0, tool_nx = 0, tool_ny = 0;
  std::vector<float> tool_grid_m;
  /// Per block of kDepthFieldBlock² grid cells (#ceil(nx/B)·ceil(ny/B), row-major): the largest
  /// env_bound_m in it (m). Per block of as many kept tool nodes (on tool_grid_m,
  /// #ceil(tool_nx/B)·ceil(tool_ny/B)): their smallest and largest a (m; +∞ and −∞ where the
  /// block has none). The evaluation skips a tool block
  /// whose moved box cannot reach within the cutoff of the deepest node found.
  std::vector<float> env_block_bound_m, tool_block_min_m, tool_block_max_m;
  /// The same per sub-block of kDepthFieldSubBlock² cells or nodes, and per super-block of
  /// kDepthFieldSuperBlock².
  std::vector<float> env_sub_bound_m, tool_sub_min_m, tool_sub_max_m;
  std::vector<float> env_super_bound_m, tool_super_min_m, tool_super_max_m;
  /// Prepare's scratch: the rows' Bézier coefficients (#4·nx·ny).
  std::vector<float> row_coefficients_m;
  /// An upper bound (m) on the distance of a kept tool node from the tool's centre of mass at X_WT0
  /// (the farthest corner of the blocks' boxes of nodes).
  double tool_radius_m = 0.0;
  bool prepared = false;

  /// Checks the field (id ≠ 0, finite frames, h > 0 and finite, nx and ny in
  /// [4, kMaxDepthFieldSide], both maps #nx·ny, the tool's offsets within ±h, margin ≥ 0, ε > 0,
  /// a known law, A_ref in [kMinPressureAreaM2, kMaxPressureAreaM2] under kPressure, a stride
  /// hint of 0 or a power of two up to kMaxDepthFieldNodeStride)
  /// and derives env_bound_m, the kept tool nodes, the blocks' bounds and tool_radius_m: all
  /// tool nodes, or, where the evaluation at X_WT0 computes more than kDepthFieldDenseNodes of
  /// them (kDepthFieldDensePressureNodes under kPressure, whose stride_hint is kept while that
  /// evaluation computes more than an eighth of them and at most them, or no overlap at all)
  /// or tests more than kDepthFieldDenseTestedNodes, every node_stride-th. Allocates only when
  /// the buffers' capacity is short. Returns false, leaving prepared false, on a bad field.
  bool Prepare();
  /// Reserves the maps, the bounds and the blocks for kMaxDepthFieldSide² nodes (not Prepare's
  /// scratch), so that a field swapped into a cache slot keeps buffers of that size. Allocates.
  void Reserve();

 private:
  /// Keeps every `stride`-th tool node of the tool's lattice (node_stride, tool_grid_m and the
  /// tool's bounds). Prepare's.
  void KeepToolNodes(int stride);  // stride ≥ 1
};

/// What DepthFieldDepthAt found. Under ForceLaw::kPressure the law is given as the seed's penalty
/// on an equivalent depth, so that a contact's k turns either into its wrench, energy and
/// stiffness through the same formulas (F = −k δ ∇δ, U = ½ k δ², K = −k(∇δ∇δᵀ + δ·curvature)):
/// with the overlapping nodes' d_j > 0, their ∇d_j and A (DepthField), depth_m is
/// δ_eq = √(Σ A d_j² / A_ref), gradient Σ A d_j ∇d_j / (A_ref δ_eq) and curvature
/// (Σ A ∇d_j∇d_jᵀ / A_ref − ∇δ_eq∇δ_eqᵀ) / δ_eq, so that k δ_eq ∇δ_eq = k_p Σ A d_j ∇d_j (−∇U),
/// ½ k δ_eq² = U and the stiffness is k_p Σ A ∇d_j∇d_jᵀ (its Gauss–Newton part: the d_j ∇²d_j
/// terms are left out). Where no node overlaps, depth_m and gradient are the seed's δ (at most 0)
/// and ∇δ, so that a linearization taken there still says how far apart the surfaces are.
struct DepthFieldEvaluation {
  /// δ (m): the smooth maximum over the tool nodes that read an environment; −∞ when none does
  /// (kPressure: δ_eq, above).
  double depth_m = -std::numeric_limits<double>::infinity();
  /// The deepest node's own δ_j (m; the plain maximum, which depth_m exceeds by the smooth
  /// maximum's lift, at most ε·ln(nodes_evaluated)); −∞ when none.
  double max_node_depth_m = -std::numeric_limits<double>::infinity();
  /// ∇δ with respect to the tool's pose (x of its centre of mass, θ about it; world axes).
  PenetrationGradient gradient;
  /// ∇²δ's part from the smooth maximum (6×6, world axes, rows/cols as Stiffness6: translation
  /// then rotation): the weights' covariance of the nodes' gradients over ε, positive
  /// semi-definite (the curvature of δ's kinks, which the implicit step needs in K; kPressure:
  /// above, positive semi-definite by Cauchy–Schwarz).
  Eigen::Matrix<double, 6, 6> curvature = Eigen::Matrix<double, 6, 6>::Zero();
  /// The field's law (DepthField::force_law).
  ForceLaw force_law = ForceLaw::kSeed;
  /// kPressure only (zero otherwise): the overlapping nodes (count), their volume Σ A d_j along
  /// n (m³), and Σ A d_j ∇d_j∇d_jᵀ / A_ref (6×6, world axes, m): the depth-weighted stiffness per
  /// unit k that a Hunt–Crossley damping scales (ContactModelEvaluation::G).
  int overlapping_nodes = 0;
  double pressure_volume_m3 = 0.0;
  Eigen::Matrix<double, 6, 6> pressure_damping = Eigen::Matrix<double, 6, 6>::Zero();
  /// False when the field is not prepared or the pose is not finite (nothing is computed).
  bool valid = false;
  /// Whether the tool is within the field's travel margin of X_WT0. Beyond it the field is still
  /// evaluated, but tool surface that lay outside the grid at X_WT0 is missing from it, and the
  /// tool's nodes that left the environment's grid drop out.
  bool within_margin = false;
  /// Tool nodes whose exact depth was computed (the others were pruned by the bound), and those
  /// whose cell's bound was tested (the rest were pruned with their block).
  int nodes_evaluated = 0;
  int nodes_tested = 0;
  /// The evaluation stopped at its node budget (DepthFieldDepthAt's max_nodes): valid is false.
  bool over_budget = false;
};

/// Evaluates `field` at tool pose X_WT (T at the tool's centre of mass, W): each kept tool node's
/// depth δ_j = b(s_j) − s_j.z (DepthField), δ = smooth_max_m·ln Σ_j exp(δ_j / smooth_max_m)
/// over the nodes whose bicubic stencil is complete, with ∇δ = Σ w_j ∇δ_j (w the
/// softmax weights) and ∇δ_j = (g_j, r_j × g_j), g_j = R_WF·(∂b/∂x, ∂b/∂y, −1), r_j the node less
/// the centre of mass (W). Nodes whose depth is more than 10 ε below the running maximum
/// (weight below 4.5e-5 of the deepest's) are skipped by bounds per block and per cell. Under
/// ForceLaw::kPressure: the sums over the nodes with δ_j > 0 (the others skipped by the same
/// bounds), each of area A = (node_stride·h)² (carried rigidly with the tool: its projection's
/// change with tilt, 1 − cos θ, is left out), as DepthFieldEvaluation says.
/// The tool is within the field's margin (within_margin) while |Δx_∥| + |Δθ|·tool_radius_m ≤
/// travel_margin_m, Δq = X_WT ⊖ X_WT0 and Δx_∥ the part of Δx in F's plane (along n the field
/// holds however far). noexcept, allocation-free: callable from the 1 kHz loop.
DepthFieldEvaluation DepthFieldDepthAt(const DepthField& field,
                                       const RigidTransform& X_WT) noexcept;

/// How DepthFieldDepthAt evaluates the nodes whose cell's bound passed: one at a time in double
/// (kScalar), or four at a time in double AVX2 lanes (kAvx2: the same sums, in another order).
/// DepthFieldDepthAt(field, X_WT) takes kAvx2 where the CPU has AVX2 and FMA.
enum class DepthFieldKernel : std::uint8_t { kScalar, kAvx2 };
/// Whether `kernel` runs on this CPU (kAvx2 asked where it does not falls back to kScalar).
bool DepthFieldKernelAvailable(DepthFieldKernel kernel) noexcept;
/// DepthFieldDepthAt with the kernel chosen by the caller (tests, benchmarks), stopping once
/// `max_nodes` nodes were computed (over_budget true, valid false).
DepthFieldEvaluation DepthFieldDepthAt(const DepthField& field, const RigidTransform& X_WT,
                                       DepthFieldKernel kernel,
                                       int max_nodes = std::numeric_limits<int>::max()) noexcept;

/// The lattice a depth field is sampled on (W; unit u, v, n with u × v = n, n from the
/// environment towards the tool; cell h in m). The environment's nodes are its origin plus whole
/// cells along u and v, the tool's its centre of mass plus whole cells: while the caller keeps
/// the axes fixed in the environment's frame, successive fields sample the same points of both
/// surfaces (for the tool, up to its turn about n between them), so that a new field changes
/// the force only as far as the surfaces it adds.
struct DepthFieldLattice {
  glm::dvec3 axis_u_W{1.0, 0.0, 0.0}, axis_v_W{0.0, 1.0, 0.0}, normal_W{0.0, 0.0, 1.0};
  double cell_m = 0.0;
  std::uint32_t id = 0;  ///< the caller's name for it (DepthField::lattice_id)
};

/// Renders a contact's depth field on the remote node (the texture stage's CPU raster,
/// RenderPatchHeightsFast): the query's window, on `lattice`, grown by the travel margin on each
/// side, the environment at query.X_WO and the tool at X_WT (T at its centre of mass), each
/// restricted to the query's triangle subsets, both with the textures' mip level at the cell;
/// the environment without its triangles nearly edge-on to n (kDepthFieldFacingThreshold) and
/// falling away nowhere more steeply than kDepthFieldMaxDescentSlope (DepthField::env_height_m).
/// Keeps its triangle lists between calls (allocates only while they grow).
class DepthFieldRenderer {
 public:
  /// Writes the field into `out` (id `id`, X_WT0 = X_WT, ε `smooth_max_m`, travel margin
  /// `margin_m` rounded up to whole cells) and prepares it: ceil(W/h) + 2·ceil(margin/h) nodes a
  /// side, centred on the window to the nearest lattice node. Returns false (out.prepared false)
  /// when that exceeds kMaxDepthFieldSide, the cell is not positive, a pose is not finite, or
  /// the field does not prepare.
  /// The field is evaluated with `law` (DepthField::force_law; kPressure with A_ref
  /// `pressure_area_m2` and `stride_hint`).
  bool Render(const HapticModel& tool, const RigidTransform& X_WT, const ContactQuery& query,
              const DepthFieldLattice& lattice, double margin_m, std::uint32_t id,
              double smooth_max_m, DepthField& out, ForceLaw law = ForceLaw::kSeed,
              double pressure_area_m2 = 0.0, std::uint8_t stride_hint = 0);

 private:
  std::vector<int> env_triangles_, tool_triangles_;
};

/// The tool's contact area for the pressure law's default stiffness (PipelineOptions): the
/// largest face of the axis-aligned box around `tool`'s vertices in its own frame (m²; 0 for a
/// tool without vertices). For the seed's block, its broad face.
double ToolContactArea(const HapticModel& tool) noexcept;

/// A fixed set of prepared fields, by id, for the operator's loop: preallocated at construction,
/// so that taking a field in and looking one up never allocate.
class DepthFieldCache {
 public:
  /// `slots` fields of up to kMaxDepthFieldSide² nodes each (allocates; throws
  /// std::invalid_argument unless slots ≥ 1).
  explicit DepthFieldCache(int slots);
  /// The field with `id`, or null (id 0: null).
  const DepthField* Find(std::uint32_t id) const noexcept;
  /// DepthFieldDepthAt of the field with `id` at X_WT (valid false where there is none),
  /// remembered per slot: the same field at the same pose (bit for bit) is not evaluated again,
  /// as a tick evaluates its models several times at one pose. A field whose evaluation passed
  /// kDepthFieldMaxNodes is not evaluated again (valid false, over_budget true) until its slot
  /// takes another field. Not thread-safe (the loop's).
  DepthFieldEvaluation Evaluate(std::uint32_t id, const RigidTransform& X_WT) const noexcept;
  /// Takes the prepared `field` in (DepthField::Prepare, the sender's or the receiver's work off
  /// the loop), replacing a field of the same id, else a free slot, else the oldest slot not in
  /// `keep` (ids the models in use refer to). Swaps buffers with `field` (no copy, no
  /// allocation): `field` leaves holding the evicted field's buffers. Returns false, taking
  /// nothing, when the field is not prepared or every slot is kept.
  bool Take(DepthField& field, std::span<const std::uint32_t> keep) noexcept;
  /// Forgets every field (a new session: its ids name other fields). noexcept, no allocation.
  void Clear() noexcept;
  int size() const noexcept { return static_cast<int>(slots_.size()); }
  /// Fields taken in since construction, and those refused (bad, or no slot).
  std::int64_t taken() const noexcept { return taken_; }
  std::int64_t refused() const noexcept { return refused_; }
  /// Fields whose evaluation passed kDepthFieldMaxNodes (rendered from their linearization).
  std::int64_t over_budget() const noexcept { return over_budget_; }

 private:
  std::vector<DepthField> slots_;
  std::vector<std::uint64_t> stamp_;  // when each slot was filled (0: free)
  struct Memo {
    std::uint64_t stamp = 0;  // the slot's stamp it was computed for (0: none)
    RigidTransform X_WT;
    DepthFieldEvaluation result;
  };
  mutable std::vector<Memo> memo_;
  mutable std::vector<std::uint8_t> dense_;  // per slot: its field passed the node budget
  mutable std::int64_t over_budget_ = 0;
  std::uint64_t clock_ = 0;
  std::int64_t taken_ = 0, refused_ = 0;
};

}  // namespace ht
