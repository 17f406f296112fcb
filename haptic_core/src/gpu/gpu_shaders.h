// The GPU penetration depth's shaders (OpenGL ES 3.1) and the encodings they share with the C++
// side: the height-to-depth map and a corner's vertex layout. Internal to src/gpu/.
#pragma once

namespace ht::gpu {

// Heights h (m, along n, relative to the window centre) are stored as depth z = 0.5 + h/(2R'),
// R' = R·(1 + 1/1024) with R the window's depth range, so that every stored sample lies strictly
// inside (0, 1): the clear values 0 (environment) and 1 (tool) mark empty cells.
constexpr double kRangeSlack = 1.0 + 1.0 / 1024.0;
constexpr int kFloatsPerCorner = 12;  // position 3, normal 3, face normal 3, uv 2, texel size 1

// Vertex stages. Both take a corner from object frame O to the window frame (u, v, n) with
// rows (xyz: the axis in O; w: axis·(p_WO − c_W)) and pass the fragment stage its height,
// texture coordinates, mip level, interpolated normal and n; triangles that do not face the other
// side are moved outside the clip volume (all three corners share the face normal). This part,
// after "#version 310 es" and any extension line, is shared.
constexpr const char* kVertexCommon = R"(
precision highp float;
precision highp int;
layout(location = 0) in vec3 a_position_O;
layout(location = 1) in vec3 a_normal_O;
layout(location = 2) in vec3 a_face_normal_O;
layout(location = 3) in vec2 a_uv;
layout(location = 4) in float a_texel_size;  // < 0: smooth face (no texture)
uniform float u_half_extent;  // W/2 (m)
uniform float u_cell_size;    // W/N (m)
uniform float u_facing_sign;  // +1 environment B, −1 tool A
uniform int u_num_levels;
out vec2 v_uv;
out float v_height;
out vec3 v_normal_O;  // interpolated corner normal (renormalized per fragment)
flat out int v_level;
flat out vec3 v_row_n;  // n in O, for the fragment's N·n
// The corner's window coordinates over W/2 (the window spans [−1, 1]²) in xy; false where its
// triangle does not face the other side.
bool ProjectCorner(vec4 row_u, vec4 row_v, vec4 row_n, out vec2 xy) {
  v_row_n = row_n.xyz;
  float facing = u_facing_sign * dot(a_face_normal_O, row_n.xyz);
  float s = dot(row_u.xyz, a_position_O) + row_u.w;
  float t = dot(row_v.xyz, a_position_O) + row_v.w;
  v_height = dot(row_n.xyz, a_position_O) + row_n.w;
  v_normal_O = a_normal_O;
  v_uv = a_uv;
  int level = -1;
  if (a_texel_size >= 0.0) {
    level = 0;
    if (a_texel_size > 0.0 && u_cell_size > a_texel_size) {
      level = clamp(int(floor(log2(u_cell_size / a_texel_size))), 0, u_num_levels - 1);
    }
  }
  v_level = level;
  xy = vec2(s / u_half_extent, t / u_half_extent);
  return facing > 0.05;
}
)";

// One draw per render: per-draw rows; the viewport is the render's tile.
constexpr const char* kRenderVertexMain = R"(
uniform vec4 u_row_u;
uniform vec4 u_row_v;
uniform vec4 u_row_n;
void main() {
  vec2 xy;
  bool faces = ProjectCorner(u_row_u, u_row_v, u_row_n, xy);
  gl_Position = faces ? vec4(xy, 0.0, 1.0) : vec4(2.0, 2.0, 2.0, 1.0);
}
)";

// The instanced draws (GL_EXT_clip_cull_distance): one draw per side (per environment model) for
// a whole batch, an instance per render (a contact's environment, or one of its tool poses), with
// its rows and atlas tile from the Instances block; the viewport is the whole atlas. Each
// instance draws the union of the batch's patch triangles (of that side and model); the window's
// edges are clip planes, so a triangle is cut where a per-render draw's viewport and scissor cut
// it, and the pixel mapping is the viewport transform's, origin + (x + 1)·N/2.
constexpr const char* kInstancedVertexMain = R"(
// Instance i: its u, v and n rows at 4i, 4i + 1, 4i + 2 and its atlas tile at 4i + 3 (x).
layout(std140) uniform Instances { vec4 u_instances[4 * 256]; };
uniform int u_columns;        // tiles per atlas row
uniform float u_tile_stride;  // texels between tile origins
uniform float u_cells;        // N
uniform vec2 u_atlas_size;    // texels
out float gl_ClipDistance[4];
void main() {
  int i = 4 * gl_InstanceID;
  vec2 xy;
  bool faces = ProjectCorner(u_instances[i], u_instances[i + 1], u_instances[i + 2], xy);
  gl_ClipDistance[0] = 1.0 + xy.x;
  gl_ClipDistance[1] = 1.0 - xy.x;
  gl_ClipDistance[2] = 1.0 + xy.y;
  gl_ClipDistance[3] = 1.0 - xy.y;
  int tile = int(u_instances[i + 3].x);
  vec2 origin = u_tile_stride * vec2(float(tile % u_columns), float(tile / u_columns));
  vec2 pixel = origin + (xy + 1.0) * (0.5 * u_cells);
  gl_Position = faces ? vec4(pixel / u_atlas_size * 2.0 - 1.0, 0.0, 1.0)
                      : vec4(2.0, 2.0, 2.0, 1.0);
}
)";

// Fragment stage: coarse height plus texture height times N·n, bilinear at the chosen mip level
// exactly as HeightField::Sample does (texelFetch, so no fixed-point filter weights).
constexpr const char* kRenderFragmentShader = R"(#version 310 es
precision highp float;
precision highp int;
uniform highp sampler2D u_texture;
uniform ivec2 u_wrap;
uniform float u_depth_range;  // R (m)
uniform float u_depth_scale;  // 1 / (2 R')
in vec2 v_uv;
in float v_height;
in vec3 v_normal_O;
flat in vec3 v_row_n;
flat in int v_level;
int Address(int i, int n, int wrap) {
  if (wrap != 0) {
    if (i < 0) i += n * ((-i) / n + 1);
    return i % n;
  }
  return clamp(i, 0, n - 1);
}
float SampleHeight(int level, vec2 uv) {
  ivec2 size = textureSize(u_texture, level);
  float fx = clamp(uv.x * float(size.x) - 0.5, -1e6, 1e6);
  float fy = clamp(uv.y * float(size.y) - 0.5, -1e6, 1e6);
  float x0f = floor(fx), y0f = floor(fy);
  float tx = fx - x0f, ty = fy - y0f;
  int x0 = int(x0f), y0 = int(y0f);
  int xa = Address(x0, size.x, u_wrap.x), xb = Address(x0 + 1, size.x, u_wrap.x);
  int ya = Address(y0, size.y, u_wrap.y), yb = Address(y0 + 1, size.y, u_wrap.y);
  float aa = texelFetch(u_texture, ivec2(xa, ya), level).r;
  float ba = texelFetch(u_texture, ivec2(xb, ya), level).r;
  float ab = texelFetch(u_texture, ivec2(xa, yb), level).r;
  float bb = texelFetch(u_texture, ivec2(xb, yb), level).r;
  float top = aa + tx * (ba - aa);
  float bottom = ab + tx * (bb - ab);
  return top + ty * (bottom - top);
}
void main() {
  float h = v_height;
  if (v_level >= 0) {
    // Height along the unit interpolated normal N (HapticModel: p = p_coarse + h·N), projected on n.
    float len = length(v_normal_O);
    float ndotn = len > 1e-6 ? dot(v_normal_O, v_row_n) / len : 0.0;
    h += SampleHeight(v_level, v_uv) * ndotn;
  }
  if (!(abs(h) <= u_depth_range)) discard;
  gl_FragDepth = 0.5 + h * u_depth_scale;
}
)";

// Reduction: one work group per tool tile; per cell covered by both patches b − a, then the
// maximum and its lowest cell index (ties as in DirectionalPenetrationDepth).
constexpr const char* kReduceComputeShader = R"(#version 310 es
precision highp float;
precision highp int;
layout(local_size_x = 256) in;
uniform highp sampler2D u_env_depth;
uniform highp sampler2D u_tool_depth;
uniform int u_resolution;
uniform int u_tile_stride;
uniform int u_env_columns;
uniform int u_tool_columns;
uniform int u_samples_per_contact;
uniform float u_height_scale;  // 2 R' (m)
struct Result { float depth; int cell; };
layout(std430, binding = 0) writeonly buffer Results { Result results[]; };
shared float s_depth[256];
shared int s_cell[256];
void main() {
  int tile = int(gl_WorkGroupID.x);
  int contact = tile / u_samples_per_contact;
  ivec2 env_origin = u_tile_stride * ivec2(contact % u_env_columns, contact / u_env_columns);
  ivec2 tool_origin = u_tile_stride * ivec2(tile % u_tool_columns, tile / u_tool_columns);
  int lid = int(gl_LocalInvocationID.x);
  float best = 0.0;
  int cell = -1;
  int cells = u_resolution * u_resolution;
  for (int k = lid; k < cells; k += 256) {
    ivec2 ij = ivec2(k % u_resolution, k / u_resolution);
    float b = texelFetch(u_env_depth, env_origin + ij, 0).r;
    float a = texelFetch(u_tool_depth, tool_origin + ij, 0).r;
    if (b > 0.0 && a < 1.0) {
      float d = (b - a) * u_height_scale;
      if (cell < 0 || d > best) { best = d; cell = k; }
    }
  }
  s_depth[lid] = best;
  s_cell[lid] = cell;
  barrier();
  for (int stride = 128; stride > 0; stride >>= 1) {
    if (lid < stride) {
      float od = s_depth[lid + stride];
      int oc = s_cell[lid + stride];
      int mc = s_cell[lid];
      if (oc >= 0 && (mc < 0 || od > s_depth[lid] || (od == s_depth[lid] && oc < mc))) {
        s_depth[lid] = od;
        s_cell[lid] = oc;
      }
    }
    barrier();
  }
  if (lid == 0) results[tile] = Result(s_depth[0], s_cell[0]);
}
)";

}  // namespace ht::gpu
