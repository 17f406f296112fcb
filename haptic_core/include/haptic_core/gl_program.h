// Small OpenGL ES helpers of the EGL context's users (haptic_egl): shader compilation, program
// linking and the GL error queue, for the GPU penetration depth and the operator's display. They
// need a current context (EglContext); their errors are GpuError (egl_context.h). Not installed.
#pragma once

#include <GLES3/gl31.h>

#include <initializer_list>
#include <string>

#include "haptic_core/egl_context.h"

namespace ht::gl {

/// "" when no GL error is pending, else the names of the pending errors (at most 16; "GL error
/// <number>" for one without a name here), which this call clears.
std::string DrainGlErrors();

/// Compiles `source` for `stage`. Throws GpuError "<who>: the <what> failed to compile: <the
/// compiler's log>".
GLuint CompileShader(GLenum stage, const std::string& source, const char* who, const char* what);

/// Links `shaders` into a program and deletes them. Throws GpuError "<who>: the <what> failed to
/// link: <the linker's log>".
GLuint LinkProgram(std::initializer_list<GLuint> shaders, const char* who, const char* what);

}  // namespace ht::gl
