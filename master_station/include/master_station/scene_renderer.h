#pragma once
// What the operator sees: the remote scene as the operator station received it (meshes at their
// poses, the tool, contact forces as arrows), drawn off-screen with OpenGL ES through the
// project's headless EGL context (Mesa llvmpipe where there is no GPU) and read back as RGBA8.
//
// Frames: W remote world (metres, right-handed), N a mesh's own node frame, C the camera (OpenGL
// convention: x right, y up, looking along −z).

#include <cstdint>
#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <memory>
#include <span>
#include <vector>

#include "haptic_core/egl_context.h"

namespace ht {

/// A triangle mesh in its node frame N, as uploaded once and drawn at any pose.
struct RenderMesh {
  /// Vertex positions p_NoV_N (m), #V entries, all finite.
  std::vector<glm::vec3> positions_N;
  /// Triangles as three indices into positions_N, #T entries, counter-clockwise seen from the
  /// outside by convention (lighting is two-sided: winding changes nothing drawn).
  std::vector<glm::uvec3> triangles;
  /// Texture coordinates, empty or #V entries (uv[i] belongs to positions_N[i]), finite, in
  /// glTF's convention: (0, 0) the texture image's top-left corner, u to the right, v down
  /// (GltfMesh::uv_N as loaded, no flip). Values outside [0, 1] repeat. Without them the mesh is
  /// drawn in its items' flat colour whatever their texture.
  std::vector<glm::vec2> uv;
};

/// One mesh drawn at one pose.
struct RenderItem {
  /// Index returned by SceneRenderer::AddMesh.
  int mesh = -1;
  /// Pose of the node frame N in W (m); any invertible affine map (scale allowed).
  glm::dmat4 X_WN{1.0};
  /// Linear RGBA in [0, 1] (values outside are clamped). Alpha below 1 draws translucently.
  /// With a texture, the base colour's RGB is colour_rgba.rgb × the texel's linear RGB (glTF's
  /// baseColorFactor × baseColorTexture); alpha stays colour_rgba.a.
  glm::vec4 colour_rgba{0.7f, 0.7f, 0.7f, 1.f};
  /// Drawn translucent (alpha 0.3 × colour_rgba.a) after the opaque items and arrows: e.g. the
  /// tool where the operator's hand is, beside the tool where the remote side holds it. Only its
  /// nearest surface is blended (one layer per pixel), and it hides nothing drawn before it.
  bool ghost = false;
  /// Index returned by SceneRenderer::AddTexture, or -1 for none. Used only when the item's mesh
  /// has uv; the texture's alpha is ignored (glTF's default alphaMode OPAQUE). Declared last, so
  /// that {mesh, X_WN, colour_rgba, ghost} initializers keep their meaning.
  int texture = -1;
};

/// A force shown as an arrow from its point of application.
struct RenderArrow {
  /// Point of application p_WoP_W (m), e.g. a contact point.
  glm::dvec3 point_W{0.0};
  /// Force f_W (N); the arrow points along it, length |f|·RenderFrame::arrow_m_per_n.
  glm::dvec3 force_W{0.0};
};

/// A pinhole camera in W.
struct RenderCamera {
  glm::dvec3 eye_W{0, 0, 1};  ///< Eye position p_WoE_W (m).
  glm::dvec3 target_W{0};     ///< Point looked at (m); must differ from eye_W.
  glm::dvec3 up_W{0, 1, 0};   ///< Up direction (any length, not parallel to target − eye).
  double yfov_rad = 0.8;      ///< Vertical field of view (rad), in (0, π).
  double near_m = 0.001;      ///< Near clip distance (m), > 0.
  double far_m = 10.0;        ///< Far clip distance (m), > near_m.
};

/// Everything one frame shows.
struct RenderFrame {
  std::vector<RenderItem> items;
  std::vector<RenderArrow> arrows;
  RenderCamera camera;
  /// Arrow length per newton of force (m/N), finite and >= 0.
  double arrow_m_per_n = 0.01;
  /// Clear colour, linear RGBA in [0, 1].
  glm::vec4 background_rgba{0.1f, 0.1f, 0.12f, 1.f};
};

/// The colour force arrows and contact markers are drawn in (linear RGBA): a saturated
/// red-orange that no default item colour resembles. Arrows are lit lightly, so their pixels are
/// this colour scaled by a shade in [0.7, 1] (alpha 1).
inline constexpr glm::vec4 kForceArrowColour{1.0f, 0.35f, 0.05f, 1.0f};

/// How the bytes SceneRenderer::Render() returns encode the linear colours it computes.
enum class ColourEncoding {
  /// byte = round(255 · linear value), no transfer function (what the renderer always did: an
  /// item of colour_rgba c, fully lit, reads back as 255·c). Shown on a screen, which takes
  /// bytes as sRGB, colours look darker than their linear values; a texture's texels (decoded
  /// from sRGB to linear) come back as 255·linear, darker than the image file's bytes.
  kLinear,
  /// byte = sRGB encoding (IEC 61966-2-1) of the linear value, through a GL_SRGB8_ALPHA8
  /// framebuffer, with blending done in linear: what a screen or PNG viewer expects. A fully lit
  /// texel comes back as the image file's byte (within rounding); a flat colour c as
  /// sRGB(c) (0.5 → 188).
  kSrgb,
};

/// Draws RenderFrames into an off-screen RGBA8 + 24-bit depth framebuffer and reads them back.
///
/// Shading: flat per-face normals (meshes are un-indexed on upload), a headlight at the eye and
/// an ambient term (shade = 0.3 + 0.7·|n·l|, two-sided), times the item's base colour:
/// colour_rgba, times the texel at the fragment's uv for an item with a texture on a mesh with
/// uv (textures are GL_SRGB8_ALPHA8: sampling decodes sRGB to linear before filtering, so the
/// product is linear; mipmapped, trilinear filtering, REPEAT wrap). Draw order:
/// opaque items; then translucent items (ghosts, alpha < 1) from back to front by their
/// bounding-box centres, each with a depth-only pass then a blended colour pass (so each item
/// blends once per pixel, with its nearest surface; its depth hides only translucent items drawn
/// later, i.e. nearer ones, where they interpenetrate); then, over all of that (the depth buffer
/// cleared), the arrows (shaft + cone) and a contact marker at each arrow's point (a small
/// octahedron of about 3 px radius, so zero forces still show where contact is): a contact
/// inside or under the tool stays visible. No anti-aliasing.
///
/// Threading: the renderer owns its own EglContext. It must be created and used on one thread
/// (the display thread); every call makes its context current on the calling thread, which fails
/// with GpuError on a thread other than the one it is current on. Not for the 1 kHz loop.
class SceneRenderer {
 public:
  /// Creates a headless EglContext, current on the calling thread, and a width x height
  /// framebuffer whose bytes are `encoding` (see ColourEncoding; kLinear by default, as before).
  /// Throws std::invalid_argument when width or height is outside [1, 4096], and GpuError when
  /// no context can be made or the framebuffer is refused (message says why).
  static std::unique_ptr<SceneRenderer> Create(int width, int height,
                                               ColourEncoding encoding = ColourEncoding::kLinear);
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  /// Uploads `mesh` (un-indexed, with face normals and its uv; zero-area triangles are dropped)
  /// and returns its index for RenderItem::mesh (0, 1, 2, ... in call order). Throws
  /// std::invalid_argument naming the bad value for a triangle index >= #V, a non-finite
  /// position or uv, a uv count other than 0 or #V, or more than 2^24 triangles; GpuError when
  /// GL refuses the upload.
  int AddMesh(const RenderMesh& mesh);

  /// Uploads a width x height RGBA8 image (rgba_top_down: width·height·4 bytes, row 0 the top,
  /// sRGB-encoded colour as image files hold it, e.g. DecodeImage()'s output) as a texture and
  /// returns its index for RenderItem::texture (0, 1, 2, ... in call order). Stored as
  /// GL_SRGB8_ALPHA8 with a full mipmap chain; sampled with trilinear filtering
  /// (LINEAR_MIPMAP_LINEAR / LINEAR) and REPEAT wrap in u and v; row 0 is v = 0. Textures live
  /// as long as the renderer. Throws std::invalid_argument for width or height outside
  /// [1, kMaxDecodedImageSide = 8192] or a buffer of another size; GpuError when GL refuses it
  /// (e.g. larger than GL_MAX_TEXTURE_SIZE, out of memory).
  int AddTexture(std::span<const std::uint8_t> rgba_top_down, int width, int height);

  /// Replaces mesh `index` with a new version (e.g. a newer version of a scene object); items
  /// that name `index` draw the new one from the next Render on. Throws std::invalid_argument for
  /// an index not returned by AddMesh or a bad mesh (as AddMesh); the old mesh stays then.
  void ReplaceMesh(int index, const RenderMesh& mesh);

  /// Draws `frame` and reads it back into *rgba_top_down: width·height·4 bytes, RGBA8, row 0 the
  /// top of the image, pixel (i, j) covering x ∈ [i, i+1), y ∈ [j, j+1) of ProjectToPixel's
  /// coordinates. The vector is resized (no allocation once it has the size). Throws
  /// std::invalid_argument, before drawing anything, for a null output, an item whose mesh index
  /// was not returned by AddMesh or whose texture is neither -1 nor an index returned by
  /// AddTexture, a non-finite pose, colour, arrow or background, a negative or
  /// non-finite arrow_m_per_n, or a degenerate camera (see RenderCamera); GpuError on a GL error.
  void Render(const RenderFrame& frame, std::vector<std::uint8_t>* rgba_top_down);

  int width() const noexcept { return width_; }    ///< Image width (pixels).
  int height() const noexcept { return height_; }  ///< Image height (pixels).
  /// What the context runs on (llvmpipe or a GPU).
  const GpuInfo& gpu() const noexcept;

 private:
  struct Impl;
  SceneRenderer(int width, int height);
  int width_ = 0;
  int height_ = 0;
  std::unique_ptr<Impl> impl_;
};

/// A camera that looks at target_W from distance_m away, from above and behind: the eye is at
/// target + distance·(cos 35°·b + sin 35°·u), u = up_W normalized and b the horizontal "behind"
/// direction, W's +z made perpendicular to u (glTF's viewer side), or W's −y where up_W is within
/// about 9° of ±z. Field of view 0.8 rad, near 0.01·distance, far 100·distance. Throws
/// std::invalid_argument for a non-finite target, a zero or non-finite up_W, or a distance that
/// is not finite and > 0.
RenderCamera FollowCamera(const glm::dvec3& target_W, const glm::dvec3& up_W, double distance_m);

/// Projects p_W with camera `c` onto a width x height image: *pixel = (x right, y down) in
/// pixels, origin the image's top-left corner, pixel (i, j) centred at (i + 0.5, j + 0.5). The
/// same matrices as SceneRenderer::Render (OpenGL: x = (ndc.x + 1)/2·width, y = (1 − ndc.y)/2·
/// height). Returns false (pixel untouched) when p_W is at or behind the eye's plane; points off
/// the image still return true with coordinates outside it. Throws std::invalid_argument for a
/// degenerate camera or width/height < 1.
bool ProjectToPixel(const RenderCamera& c, int width, int height, const glm::dvec3& p_W,
                    glm::dvec2* pixel);

}  // namespace ht
