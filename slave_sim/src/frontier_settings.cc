// The speed-vs-error frontier's settings (frontier.h): each setting's name, what it changes in the
// remote step (PipelineOptionsFor), the list the sweep runs, and a setting by name.

#include <stdexcept>
#include <string>
#include <vector>

#include "haptic_core/remote_step.h"
#include "slave_sim/frontier.h"

namespace ht {

const char* FrontierMethodName(FrontierMethod method) noexcept {
  switch (method) {
    case FrontierMethod::kTexture:
      return "texture";
    case FrontierMethod::kCoarseOnly:
      return "coarse_only";
    case FrontierMethod::kFullResolutionFcl:
      return "fcl_full_resolution";
  }
  return "?";
}

PipelineOptions PipelineOptionsFor(const FrontierSetting& st) {
  PipelineOptions options;
  options.grid_resolution = st.grid;
  options.refine_depth = st.refine_depth;
  options.depth_fields = st.depth_fields;
  options.force_law = st.force_law;
  // The texture stage's threads are the coarse query's too, as in the product.
  options.texture_threads = st.texture_threads;
  return options;
}

std::vector<FrontierSetting> FrontierSettings(bool quick, bool with_gpu) {
  std::vector<FrontierSetting> s;
  const FrontierSetting base{"default"};
  s.push_back(base);
  // The grid alone at N (stage 5b off): how the grid's own error goes with its cell.
  const auto grid = [&](int n) {
    FrontierSetting x = base;
    x.name = "grid" + std::to_string(n);
    x.grid = n;
    x.refine_depth = false;
    s.push_back(x);
  };
  const auto texture = [&](int n) {
    FrontierSetting x = base;
    x.name = "texture" + std::to_string(n);
    x.texture_size = n;
    s.push_back(x);
  };
  const auto gpu = [&](int bits) {
    FrontierSetting x = base;
    x.name = "gpu" + std::to_string(bits);
    x.backend = "gpu";
    x.depth_bits = bits;
    s.push_back(x);
  };
  // The grid's cell samples at the default N (stage 5b off): the reference stage 5b refines.
  FrontierSetting grid_only = base;
  grid_only.name = "grid_only";
  grid_only.refine_depth = false;
  s.push_back(grid_only);
  for (int n : {16, 100}) grid(n);
  // Stage 5b on a coarse grid: the refined depth converges as the texture does, not as the grid.
  FrontierSetting refined16 = base;
  refined16.name = "grid16_refined";
  refined16.grid = 16;
  s.push_back(refined16);
  texture(256);
  if (!quick) texture(2048);
  // Twice the seed's coarse triangles.
  FrontierSetting coarse2x = base;
  coarse2x.name = "coarse2x";
  coarse2x.coarse_scale = 2.0;
  s.push_back(coarse2x);
  if (!quick) {
    FrontierSetting product = base;  // what slave_sim --scene builds (ProductModelSettings)
    product.name = "product";
    product.product_models = true;
    s.push_back(product);
  }
  FrontierSetting ref = base;
  ref.name = "reference";
  ref.texture_path = TextureStagePath::kReference;
  s.push_back(ref);
  if (!quick) {
    FrontierSetting two = base;
    two.name = "threads2";
    two.texture_threads = 2;
    s.push_back(two);
    // The contact model as depth fields, each evaluated at the pose as the operator's loop does.
    FrontierSetting fields = base;
    fields.name = "depth_fields";
    fields.depth_fields = true;
    s.push_back(fields);
    // The same fields under the pressure law, against that law's own truth.
    FrontierSetting pressure = fields;
    pressure.name = "pressure";
    pressure.force_law = ForceLaw::kPressure;
    s.push_back(pressure);
  }
  if (with_gpu) gpu(16);
  FrontierSetting c = base;
  c.name = "coarse_only";
  c.method = FrontierMethod::kCoarseOnly;
  s.push_back(c);
  FrontierSetting f = base;
  f.name = "fcl_full_resolution";
  f.method = FrontierMethod::kFullResolutionFcl;
  s.push_back(f);
  return s;
}

FrontierSetting FrontierSettingNamed(const std::string& name, bool with_gpu) {
  for (FrontierSetting& st : FrontierSettings(false, with_gpu)) {
    if (st.name != name) continue;
    if (st.method != FrontierMethod::kTexture) {
      throw std::invalid_argument("frontier setting '" + name +
                                  "' is a baseline, not a setting of the remote step");
    }
    return st;
  }
  throw std::invalid_argument("no frontier setting named '" + name +
                              "' (speed_error_frontier --list-settings lists them)");
}

}  // namespace ht
