// Small OpenGL ES helpers of the GPU penetration depth: shader compilation, program linking and
// the GL error queue. They need a current context. Internal to src/gpu/.
#pragma once

#include <GLES3/gl31.h>

#include <initializer_list>
#include <string>

namespace ht::gpu {

/// "" when no GL error is pending, else the names of the pending errors (at most 16), which
/// this call clears.
std::string DrainGlErrors();

/// Compiles `source` for `stage`; throws GpuError naming `what` with the compiler's log.
GLuint CompileShader(GLenum stage, const std::string& source, const char* what);

/// Links `shaders` into a program and deletes them; throws GpuError naming `what` with the
/// linker's log.
GLuint LinkProgram(std::initializer_list<GLuint> shaders, const char* what);

}  // namespace ht::gpu
