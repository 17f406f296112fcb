// The depth field's cost on both sides (depth_field.h): the remote node's render and preparation
// of a field, and the operator's evaluation of it at poses displaced from q0 as a hand moves in
// the time a model takes to come back. The seed's Fig. 75 scene (the block resting on the gear),
// the CPU backend, one thread. Prints µs per render and per evaluation (p50, p99) and the nodes
// the evaluation computed.
//
// Usage: depth_field_benchmark [--subdivision S] [--margin-mm M] [--poses K] [--travel-mm T]

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "haptic_core/demo/demo_scenes.h"
#include "haptic_core/depth_field.h"
#include "haptic_core/penetration_depth_backend.h"
#include "haptic_core/remote_step.h"

namespace {

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "The depth field's render (remote node) and evaluation (operator) on the seed's\n"
      "Fig. 75 scene, the block resting on the gear."};
  int subdivision = 2, poses = 2000;
  double margin_mm = 2.5, travel_mm = 1.5, tilt_mrad = 10.0;
  app.add_option("--subdivision", subdivision, "nodes per window cell (1..4)")
      ->capture_default_str();
  app.add_option("--margin-mm", margin_mm, "the fields' travel margin (mm)")->capture_default_str();
  app.add_option("--poses", poses, "poses evaluated")->capture_default_str();
  app.add_option("--travel-mm", travel_mm, "largest in-plane travel from q0 (mm)")
      ->capture_default_str();
  app.add_option("--tilt-mrad", tilt_mrad, "largest turn from q0 (mrad)")->capture_default_str();
  std::string kernel_name = "auto";
  app.add_option("--kernel", kernel_name,
                 "how the operator evaluates the nodes: auto (avx2 where the CPU has it), scalar "
                 "or avx2")
      ->check(CLI::IsMember({"auto", "scalar", "avx2"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  using namespace ht;
  const DepthFieldKernel kernel =
      kernel_name == "scalar" ? DepthFieldKernel::kScalar
      : kernel_name == "avx2" || DepthFieldKernelAvailable(DepthFieldKernel::kAvx2)
          ? DepthFieldKernel::kAvx2
          : DepthFieldKernel::kScalar;
  if (!DepthFieldKernelAvailable(kernel)) {
    std::fprintf(stderr, "depth_field_benchmark: this CPU lacks AVX2 and FMA: --kernel scalar\n");
    return 2;
  }
  using Clock = std::chrono::steady_clock;
  const HapticScene scene = MakeBlockOnGearScene();
  PipelineOptions options;
  options.texture_threads = 1;
  options.depth_fields = true;
  options.depth_field_subdivision = subdivision;
  options.depth_field_margin_m = margin_mm * 1e-3;
  options.Validate();
  HapticTexturePipeline pipeline(scene, options,
                                 std::make_unique<CpuPenetrationDepthBackend>(
                                     options.max_window_resolution(), TextureStagePath::kFast, 1));
  // Lowered onto the gear until the model's deepest contact is 30 µm deep.
  RigidTransform X_WT = scene.X_WT_home;
  ContactModel model;
  StepTimings timings;
  for (int k = 0; k < 2000; ++k) {
    model = pipeline.Step(X_WT, 1, timings);
    double deepest = -1.0;
    for (int c = 0; c < model.num_contacts; ++c)
      deepest = std::max(deepest, model.contacts[c].depth_m);
    if (deepest >= 30e-6) break;
    X_WT.translation.z -= 2e-6;
  }
  if (pipeline.last_depth_fields().empty()) {
    std::fprintf(stderr, "depth_field_benchmark: no field at the resting pose\n");
    return 1;
  }
  // The remote node's side: the step with and without its fields, and a field's render and
  // preparation alone.
  std::vector<double> field_us;
  DepthFieldRenderer renderer;
  DepthField scratch;
  scratch.Reserve();
  const ContactQuery query = pipeline.last_contact_queries()[0];
  const DepthField& first = *pipeline.last_depth_fields()[0];
  const glm::dmat3 R_WF = glm::mat3_cast(first.X_WF.rotation);
  const DepthFieldLattice lattice{R_WF[0], R_WF[1], R_WF[2], first.cell_m};
  for (int k = 0; k < 200; ++k) {
    const auto t0 = Clock::now();
    renderer.Render(*scene.tool, X_WT, query, lattice, first.travel_margin_m, 1,
                    kDepthFieldSmoothMaxM, scratch);
    field_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  const DepthField& field = *pipeline.last_depth_fields()[0];
  std::printf("fields %zu, first: %d x %d nodes, cell %.3f mm, margin %.2f mm\n",
              pipeline.last_depth_fields().size(), field.nx, field.ny, field.cell_m * 1e3,
              field.travel_margin_m * 1e3);
  std::printf("remote: render + prepare one field p50 %.1f us, p99 %.1f us\n",
              Quantile(field_us, 0.5), Quantile(field_us, 0.99));
  // The operator's side: the field at poses a hand reaches meanwhile.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> eval_us, nodes, tested;
  double largest_depth_difference_m = 0.0, largest_gradient_difference = 0.0;
  for (int k = 0; k < poses; ++k) {
    const Twist dq{glm::dvec3(u(rng), u(rng), 0.0) * (travel_mm * 1e-3 / std::sqrt(2.0)) +
                       glm::dvec3(0.0, 0.0, u(rng) * 20e-6),
                   glm::dvec3(u(rng), u(rng), u(rng)) * (tilt_mrad * 1e-3 / std::sqrt(3.0))};
    const RigidTransform X = Displace(X_WT, dq);
    const auto t0 = Clock::now();
    double sum = 0.0;
    int n = 0, t = 0;
    for (const DepthField* f : pipeline.last_depth_fields()) {
      const DepthFieldEvaluation e = DepthFieldDepthAt(*f, X, kernel);
      sum += e.depth_m;
      n += e.nodes_evaluated;
      t += e.nodes_tested;
    }
    tested.push_back(t);
    eval_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    // The other kernel at the same pose (not timed): the two must agree to rounding.
    if (kernel == DepthFieldKernel::kAvx2) {
      for (const DepthField* f : pipeline.last_depth_fields()) {
        const DepthFieldEvaluation a = DepthFieldDepthAt(*f, X, DepthFieldKernel::kScalar);
        const DepthFieldEvaluation b = DepthFieldDepthAt(*f, X, DepthFieldKernel::kAvx2);
        if (!std::isfinite(a.depth_m) || !std::isfinite(b.depth_m)) continue;
        largest_depth_difference_m =
            std::max(largest_depth_difference_m, std::abs(a.depth_m - b.depth_m));
        largest_gradient_difference =
            std::max(largest_gradient_difference,
                     glm::length(a.gradient.d_translation_W - b.gradient.d_translation_W));
      }
    }
    nodes.push_back(n);
    if (sum == 12345.0) std::printf(" ");  // keeps the evaluation
  }
  std::printf(
      "operator (%s): all fields at one pose p50 %.1f us, p99 %.1f us; nodes computed p50 %.0f, "
      "p99 %.0f; tested p50 %.0f, p99 %.0f\n",
      kernel == DepthFieldKernel::kAvx2 ? "avx2" : "scalar", Quantile(eval_us, 0.5),
      Quantile(eval_us, 0.99), Quantile(nodes, 0.5), Quantile(nodes, 0.99), Quantile(tested, 0.5),
      Quantile(tested, 0.99));
  if (kernel == DepthFieldKernel::kAvx2) {
    std::printf("avx2 against scalar: largest depth difference %.3g m, gradient %.3g\n",
                largest_depth_difference_m, largest_gradient_difference);
  }
  return 0;
}
