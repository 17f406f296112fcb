// libFuzzer target for the scene loader (issue 16, hostile input): each input is written to a
// file and loaded as a glTF 2.0 scene (.gltf JSON, or .glb when it starts with the GLB magic;
// KHR_draco_mesh_compression primitives included). Any input must give a scene or a
// std::exception, never a crash, a hang or an unbounded allocation. Built and run by
// tests/fuzz/run-fuzz --target scene.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>

#include "codecs/gltf_scene.h"
#include "codecs/json_nesting.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = [] {
    const char* dir = std::getenv("TMPDIR");
    return std::string(dir ? dir : "/tmp") + "/ht_scene_fuzz_" + std::to_string(getpid()) + ".gltf";
  }();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return 0;
  if (size > 0) std::fwrite(data, 1, size, f);
  std::fclose(f);
  (void)ht::JsonNestingDepth({reinterpret_cast<const char*>(data), size});
  try {
    const ht::GltfScene scene = ht::LoadGltfScene(path);
    (void)scene;
  } catch (const std::exception&) {
    // refused with a message: fine
  }
  return 0;
}
