// Which penetration-depth backend the remote node uses (gpu_penetration_depth.h): the CPU
// backend, or the GPU backend where a context starts, with the reason for the choice.
#include <algorithm>
#include <stdexcept>
#include <string>

#include "haptic_core/gpu_penetration_depth.h"

namespace ht {

PdBackendChoice ParsePdBackendChoice(const std::string& text) {
  if (text == "cpu") return PdBackendChoice::kCpu;
  if (text == "gpu") return PdBackendChoice::kGpu;
  if (text == "auto") return PdBackendChoice::kAuto;
  throw std::invalid_argument("penetration-depth backend must be cpu, gpu or auto, got '" + text +
                              "'");
}

const char* ToString(PdBackendChoice choice) noexcept {
  switch (choice) {
    case PdBackendChoice::kCpu:
      return "cpu";
    case PdBackendChoice::kGpu:
      return "gpu";
    case PdBackendChoice::kAuto:
      return "auto";
  }
  return "?";
}

std::unique_ptr<PenetrationDepthBackend> MakePenetrationDepthBackend(
    PdBackendChoice choice, const GpuPenetrationDepthOptions& gpu_options, int grid_resolution,
    std::string& message, int cpu_threads) {
  const int cpu_resolution = std::max(grid_resolution, 2);
  if (choice == PdBackendChoice::kCpu) {
    auto cpu = std::make_unique<CpuPenetrationDepthBackend>(cpu_resolution, TextureStagePath::kFast,
                                                            cpu_threads);
    message = "penetration depth on the CPU (requested): " + cpu->description();
    return cpu;
  }
  try {
    GpuPenetrationDepthOptions options = gpu_options;
    options.max_resolution = std::max(options.max_resolution, grid_resolution);
    // A software rasterizer (llvmpipe) is slower than the CPU backend on this stage (see the
    // benchmark): auto takes hardware only; gpu takes whatever starts.
    if (choice == PdBackendChoice::kAuto) options.egl.allow_software = false;
    auto gpu = GpuPenetrationDepthBackend::Create(options);
    message = std::string("penetration depth on the GPU (") + ToString(choice) +
              "): " + gpu->description() + ", vendor " + gpu->info().vendor;
    return gpu;
  } catch (const std::exception& e) {
    message = choice == PdBackendChoice::kGpu
                  ? std::string("GPU penetration depth was requested but cannot start: ") +
                        e.what() + "; falling back to the CPU backend"
                  : std::string("no hardware GPU (") + e.what() +
                        "); penetration depth on the CPU backend (--pd-backend gpu forces a "
                        "software renderer such as llvmpipe)";
    return std::make_unique<CpuPenetrationDepthBackend>(cpu_resolution, TextureStagePath::kFast,
                                                        cpu_threads);
  }
}

}  // namespace ht
