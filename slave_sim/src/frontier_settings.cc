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
  options.max_contacts = st.max_contacts;
  options.local_reach = st.local_reach;
  options.grazing_guard = st.grazing_guard;
  options.grazing_guard_local_reach = st.grazing_guard_local_reach;
  if (st.max_window_extent_m > 0.0) options.max_window_extent_m = st.max_window_extent_m;
  options.drop_unreachable_pairs = st.drop_unreachable_pairs;
  options.region_normals = st.region_normals;
  options.size_windows_from_clusters = st.size_windows_from_clusters;
  options.cluster_triangles = st.cluster_triangles;
  options.share_leaves_between_disjoint_windows = st.share_leaves_between_disjoint_windows;
  options.tool_leaves_follow_object_leaves = st.tool_leaves_follow_object_leaves;
  options.whole_model_region_windows = st.whole_model_region_windows;
  options.refine_depth = st.refine_depth;
  options.split_windows_at_separated_overlap = st.split_windows_at_separated_overlap;
  options.share_connected_contacts = st.share_connected_contacts;
  if (st.share_link_m >= 0.0) options.share_link_m = st.share_link_m;
  if (st.share_fade_m >= 0.0) options.share_fade_m = st.share_fade_m;
  if (st.share_temperature_m > 0.0) options.share_temperature_m = st.share_temperature_m;
  options.split_link_m = st.split_link_m;
  options.split_birth_ramp_m = st.split_birth_ramp_m;
  options.split_keeps_parent_rotation_step = st.split_keeps_parent_rotation_step;
  options.split_bridge_fade_m = st.split_bridge_fade_m;
  options.split_keeps_parent_window = st.split_keeps_parent_window;
  options.split_bridge_fade_per_depth = st.split_bridge_fade_per_depth;
  options.reuse_base_render = st.reuse_base_render;
  options.depth_refinement.subgrid_rotations = st.subgrid_rotations;
  options.depth_refinement.subgrid_translations = st.subgrid_translations;
  options.depth_refinement.conservative_screen = st.conservative_screen;
  options.depth_refinement.parallax = st.parallax;
  options.depth_refinement.seed_from_last_step = st.seed_from_last_step;
  options.depth_refinement.parallax_offset_seeds = st.parallax_offset_seeds;
  options.clustering_angle_deg = st.clustering_angle_deg;
  options.depth_refinement.neighbour_peak_seeds = st.neighbour_peak_seeds;
  options.depth_fields = st.depth_fields;
  options.depth_field_subdivision = st.depth_field_subdivision;
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
  // Coarse triangles k × the seed's, at a texture size (0: each model's from its detail).
  const auto coarse = [&](double k, const char* name,
                          int texture_size = FrontierSetting{}.texture_size) {
    FrontierSetting x = base;
    x.name = name;
    x.coarse_scale = k;
    x.texture_size = texture_size;
    s.push_back(x);
  };
  const auto gpu = [&](int bits) {
    FrontierSetting x = base;
    x.name = "gpu" + std::to_string(bits);
    x.backend = "gpu";
    x.depth_bits = bits;
    s.push_back(x);
  };
  // Issue 32: the default refines δ (stage 5b); "grid_only" is the grid's cell samples at the
  // default N, the reference it refines.
  FrontierSetting grid_only = base;
  grid_only.name = "grid_only";
  grid_only.refine_depth = false;
  s.push_back(grid_only);
  // The refinement with the conservative screen after the seeds (issue 32, sixth stop).
  FrontierSetting screen = base;
  screen.name = "screen";
  screen.conservative_screen = true;
  screen.parallax = false;  // the screen's bounds are the render's form
  s.push_back(screen);
  for (int n : {16, 25, 100}) grid(n);
  if (quick) {
    texture(256);
    coarse(2.0, "coarse2x");
    FrontierSetting refined16 = base;  // issue 32: stage 5b at N = 16
    refined16.name = "grid16_refined";
    refined16.grid = 16;
    s.push_back(refined16);
  } else {
    for (int n : {256, 512, 2048}) texture(n);
    // Issue 32: each model's texture size from its surface's detail (TextureSizingParams).
    coarse(1.0, "texture_auto", 0);
    coarse(2.0, "coarse2x_texture_auto", 0);
    coarse(4.0, "coarse4x_texture_auto", 0);
    coarse(0.5, "coarse0.5x");
    coarse(2.0, "coarse2x");
    coarse(4.0, "coarse4x");
    // More coarse triangles share the atlas among more charts (issue 32, fifth stop: the
    // objects' surface error grew with the count at 1024²): at 2048², 4x the seed's count has
    // the seed's texels per triangle at 1024², and 2x twice as many.
    coarse(2.0, "coarse2x_texture2048", 2048);
    coarse(4.0, "coarse4x_texture2048", 2048);
  }
  if (!quick) {
    FrontierSetting product = base;  // what slave_sim --scene builds (ProductModelSettings)
    product.name = "product";
    product.product_models = true;
    s.push_back(product);
    // The product's models with the render's form instead of parallax (the default before issue
    // 32's twenty-eighth stop).
    FrontierSetting product_no_parallax = product;
    product_no_parallax.name = "product_no_parallax";
    product_no_parallax.parallax = false;
    s.push_back(product_no_parallax);
    FrontierSetting product_follow = product;
    product_follow.name = "product_tool_leaves_follow";
    product_follow.tool_leaves_follow_object_leaves = true;
    s.push_back(product_follow);
    FrontierSetting product_alone = product;
    product_alone.name = "product_no_last_step_seeds";
    product_alone.seed_from_last_step = false;
    s.push_back(product_alone);
    FrontierSetting product_before = product;  // issue 32, thirty-third stop
    product_before.name = "product_before_thirty_third_stop";
    product_before.parallax_offset_seeds = false;
    product_before.clustering_angle_deg = 30.0;
    product_before.neighbour_peak_seeds = false;  // on since the thirty-fourth stop
    s.push_back(product_before);
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
    FrontierSetting seven = base;
    seven.name = "contacts7";
    seven.max_contacts = 7;
    s.push_back(seven);
    FrontierSetting local = base;
    local.name = "local_reach";
    local.local_reach = true;
    s.push_back(local);
    // The seed's contact count on both cores (issue 15's fig77 target allows both), the product's
    // rendered rotations: without and with local reach.
    FrontierSetting seven_two = base;
    seven_two.name = "contacts7_threads2";
    seven_two.max_contacts = 7;
    seven_two.texture_threads = 2;
    s.push_back(seven_two);
    FrontierSetting local_seven_two = seven_two;
    local_seven_two.name = "local_contacts7_threads2";
    local_seven_two.local_reach = true;
    s.push_back(local_seven_two);
    // Issue 31's changes one at a time, off: their own effect on the pipeline error.
    FrontierSetting no_guard = base;
    no_guard.name = "no_grazing_guard";
    no_guard.grazing_guard = false;
    s.push_back(no_guard);
    FrontierSetting model_reach = base;
    model_reach.name = "guard_model_reach";
    model_reach.grazing_guard_local_reach = false;
    s.push_back(model_reach);
    FrontierSetting sized = base;
    sized.name = "windows_from_clusters";
    sized.max_window_extent_m = 2.0 * PipelineOptions{}.window_extent_m;
    s.push_back(sized);
    FrontierSetting fixed = base;
    fixed.name = "windows_fixed";
    fixed.max_window_extent_m = PipelineOptions{}.window_extent_m;
    s.push_back(fixed);
    FrontierSetting sized4 = base;
    sized4.name = "windows_from_clusters_4w";
    sized4.max_window_extent_m = 4.0 * PipelineOptions{}.window_extent_m;
    s.push_back(sized4);
    FrontierSetting merged = sized;
    merged.name = "merge_clusters_fixed_windows";
    merged.size_windows_from_clusters = false;
    s.push_back(merged);
    FrontierSetting keep_pairs = base;
    keep_pairs.name = "keep_unreachable_pairs";
    keep_pairs.drop_unreachable_pairs = false;
    s.push_back(keep_pairs);
    FrontierSetting region = base;
    region.name = "region_normals";
    region.region_normals = true;
    s.push_back(region);
    // Issue 32, thirty-third stop: the clustering angle (60° by default) and the seeds carried by
    // parallax (on), each turned back, and both (the default before that stop).
    for (const int deg : {30, 45, 75}) {
      FrontierSetting angle = base;
      angle.name = "clustering_angle_" + std::to_string(deg);
      angle.clustering_angle_deg = deg;
      s.push_back(angle);
    }
    FrontierSetting no_offset = base;
    no_offset.name = "no_parallax_offset_seeds";
    no_offset.parallax_offset_seeds = false;
    s.push_back(no_offset);
    FrontierSetting before33 = no_offset;
    before33.name = "before_thirty_third_stop";
    before33.clustering_angle_deg = 30.0;
    before33.neighbour_peak_seeds = false;  // on since the thirty-fourth stop
    s.push_back(before33);
    FrontierSetting by_box = base;
    by_box.name = "windows_pick_by_box";
    by_box.cluster_triangles = false;
    s.push_back(by_box);
    FrontierSetting whole_leaves = base;
    whole_leaves.name = "leaves_to_deepest_pair";
    whole_leaves.share_leaves_between_disjoint_windows = false;
    s.push_back(whole_leaves);
    FrontierSetting follow = base;
    follow.name = "tool_leaves_follow";
    follow.tool_leaves_follow_object_leaves = true;
    s.push_back(follow);
    // Issue 32: stage 5b's variants (the default refines).
    const FrontierSetting& refined = base;
    // The contact model as depth fields, on the window's grid refined twice (the default) and
    // on the window's own grid.
    FrontierSetting fields = base;
    fields.name = "depth_fields";
    fields.depth_fields = true;
    s.push_back(fields);
    FrontierSetting fields_s1 = fields;
    fields_s1.name = "depth_fields_s1";
    fields_s1.depth_field_subdivision = 1;
    s.push_back(fields_s1);
    // Stage 5b without the neighbouring peaks as seeds.
    FrontierSetting no_neighbour_peaks = refined;
    no_neighbour_peaks.name = "no_neighbour_peak_seeds";
    no_neighbour_peaks.neighbour_peak_seeds = false;
    s.push_back(no_neighbour_peaks);
    // Stage 5b with the render's form h·(N·n) at the coarse point instead of parallax (the
    // form the grid renders).
    FrontierSetting no_parallax = refined;
    no_parallax.name = "no_parallax";
    no_parallax.parallax = false;
    s.push_back(no_parallax);
    // Without the seeds from the last step (they count on a trace's consecutive rows only),
    // with and without parallax: the default before issue 32's twenty-fifth stop.
    FrontierSetting alone = refined;
    alone.name = "no_last_step_seeds";
    alone.seed_from_last_step = false;
    s.push_back(alone);
    FrontierSetting no_parallax_alone = no_parallax;
    no_parallax_alone.name = "no_parallax_no_last_step_seeds";
    no_parallax_alone.seed_from_last_step = false;
    s.push_back(no_parallax_alone);
    // Stage 5a: a window per separated region of its overlap, with either gradient.
    // Stage 5a off: the default before issue 32's thirty-first stop. The split settings below
    // start from it and set the pieces they name.
    FrontierSetting no_split = refined;
    no_split.name = "no_split";
    no_split.split_windows_at_separated_overlap = false;
    no_split.split_link_m = 0.0;
    no_split.split_birth_ramp_m = 0.0;
    no_split.split_keeps_parent_rotation_step = false;
    no_split.split_bridge_fade_m = 0.0;
    no_split.split_keeps_parent_window = false;
    s.push_back(no_split);
    FrontierSetting split = no_split;
    split.name = "split_windows_at_separated_overlap";
    split.split_windows_at_separated_overlap = true;
    s.push_back(split);
    for (const int mm : {7, 10}) {
      FrontierSetting linked = split;
      linked.name = linked.name + "_link" + std::to_string(mm) + "mm";
      linked.split_link_m = mm * 1e-3;
      s.push_back(linked);
    }
    // Stage 5a made continuous (issue 32's thirtieth stop), one piece at a time at a 10 mm link:
    // the birth ramp, then the parent's rotation step, then the bridge fade, then the parent's
    // window ("split_continuous_<R>um": all four, ramp and fade R).
    FrontierSetting ramped = split;
    ramped.name = "split_link10mm_ramp50um";
    ramped.split_link_m = 10e-3;
    ramped.split_birth_ramp_m = 50e-6;
    s.push_back(ramped);
    FrontierSetting parent_step = ramped;
    parent_step.name = "split_link10mm_ramp50um_parent_step";
    parent_step.split_keeps_parent_rotation_step = true;
    s.push_back(parent_step);
    FrontierSetting bridged = parent_step;
    bridged.name = "split_link10mm_ramp50um_parent_step_bridge50um";
    bridged.split_bridge_fade_m = 50e-6;
    s.push_back(bridged);
    for (const int um : {20, 50, 100, 200, 400}) {
      FrontierSetting continuous = split;
      continuous.name = "split_continuous_" + std::to_string(um) + "um";
      continuous.split_link_m = 10e-3;
      continuous.split_birth_ramp_m = um * 1e-6;
      continuous.split_keeps_parent_rotation_step = true;
      continuous.split_bridge_fade_m = um * 1e-6;
      continuous.split_keeps_parent_window = true;
      s.push_back(continuous);
    }
    // The default's split with its bridge fade in proportion to each region's depth (issue 32's
    // thirty-first stop): "split_fade_per_depth<C>x", C = 1.5, 2, 3.
    for (const double c : {1.5, 2.0, 3.0}) {
      FrontierSetting relative = base;
      char name[64];
      std::snprintf(name, sizeof name, "split_fade_per_depth%gx", c);
      relative.name = name;
      relative.split_bridge_fade_per_depth = c;
      s.push_back(relative);
    }
    // The default with stages 5a and 5c rendering the base pose again instead of reading stage
    // 5's render (issue 32's thirty-second stop: the route before).
    FrontierSetting render_again = base;
    render_again.name = "render_base_again";
    render_again.reuse_base_render = false;
    s.push_back(render_again);
    // Stage 5c (on in the default): its link, fade and temperature varied, and off.
    const FrontierSetting& share = refined;
    for (const int mm : {5, 15}) {
      FrontierSetting t = share;
      t.name = "share_connected_contacts_link" + std::to_string(mm) + "mm";
      t.share_link_m = mm * 1e-3;
      s.push_back(t);
    }
    FrontierSetting unshared = refined;
    unshared.name = "no_shared_contacts";
    unshared.share_connected_contacts = false;
    s.push_back(unshared);
    FrontierSetting share_step = share;
    share_step.name = "share_connected_contacts_no_fade";
    share_step.share_fade_m = 0.0;
    s.push_back(share_step);
    for (const int um : {1, 20}) {
      FrontierSetting t = share;
      t.name = "share_connected_contacts_" + std::to_string(um) + "um";
      t.share_temperature_m = um * 1e-6;
      s.push_back(t);
    }
    FrontierSetting subgrid = refined;
    subgrid.name = "refined_rotations_from_subgrid";
    subgrid.subgrid_rotations = true;
    s.push_back(subgrid);
    FrontierSetting translations_subgrid = refined;
    translations_subgrid.name = "refined_translations_from_subgrid";
    translations_subgrid.subgrid_translations = true;
    s.push_back(translations_subgrid);
    for (const int n : {16, 25, 35, 70, 100}) {
      FrontierSetting coarse_grid = refined;
      coarse_grid.name = "grid" + std::to_string(n) + "_refined";
      coarse_grid.grid = n;
      s.push_back(coarse_grid);
    }
    FrontierSetting at_witness = base;
    at_witness.name = "windows_at_witness";
    at_witness.whole_model_region_windows = false;
    s.push_back(at_witness);
    // Witness windows on the grid alone (no stage 5b).
    FrontierSetting stop2 = at_witness;
    stop2.name = "witness_windows_grid_only";
    stop2.refine_depth = false;
    s.push_back(stop2);
    FrontierSetting before = no_guard;
    before.name = "issue31_before";
    before.max_window_extent_m = PipelineOptions{}.window_extent_m;
    before.drop_unreachable_pairs = false;
    before.region_normals = false;
    before.cluster_triangles = false;
    before.whole_model_region_windows = false;
    before.refine_depth = false;
    s.push_back(before);
  }
  if (with_gpu) {
    gpu(16);
    if (!quick) gpu(32);
  }
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
