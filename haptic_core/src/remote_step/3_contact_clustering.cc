#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "haptic_core/contact_clustering.h"

namespace ht {
namespace {

bool IsFinite(const glm::dvec3& v) noexcept {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// The in-plane axes ContactWindow::Make() picks for the unit normal n (kept in step with it):
// u = world x projected on the plane ⟂ n (world y when |n.x| ≥ 0.9), v = n × u.
void WindowAxes(const glm::dvec3& n, glm::dvec3& u, glm::dvec3& v) noexcept {
  const glm::dvec3 ref = std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  u = glm::normalize(ref - glm::dot(ref, n) * n);
  v = glm::cross(n, u);
}

double CosMaxAngle(const ClusteringOptions& options) noexcept {
  return std::cos(options.max_normal_angle_deg * std::numbers::pi / 180.0);
}

}  // namespace

bool ClusteringOptions::IsValid() const noexcept {
  return std::isfinite(merge_distance_m) && merge_distance_m >= 0.0 &&
         std::isfinite(max_normal_angle_deg) && max_normal_angle_deg >= 0.0 &&
         max_normal_angle_deg < 90.0 && std::isfinite(texture_margin_m) &&
         texture_margin_m >= 0.0 && std::isfinite(min_extent_m) && min_extent_m > 0.0 &&
         std::isfinite(max_extent_m) && max_extent_m >= min_extent_m &&
         std::isfinite(weight_floor_m) && weight_floor_m > 0.0 && max_contacts >= 1;
}

void ClusteringOptions::Validate() const {
  const auto fail = [](const std::string& what, double value) {
    throw std::invalid_argument("ClusteringOptions: " + what + ", got " + std::to_string(value));
  };
  if (!(std::isfinite(merge_distance_m) && merge_distance_m >= 0.0))
    fail("merge_distance_m must be finite and >= 0", merge_distance_m);
  if (!(std::isfinite(max_normal_angle_deg) && max_normal_angle_deg >= 0.0 &&
        max_normal_angle_deg < 90.0))
    fail("max_normal_angle_deg must be in [0, 90)", max_normal_angle_deg);
  if (!(std::isfinite(texture_margin_m) && texture_margin_m >= 0.0))
    fail("texture_margin_m must be finite and >= 0", texture_margin_m);
  if (!(std::isfinite(min_extent_m) && min_extent_m > 0.0))
    fail("min_extent_m must be finite and > 0", min_extent_m);
  if (!(std::isfinite(max_extent_m) && max_extent_m >= min_extent_m))
    fail("max_extent_m must be finite and >= min_extent_m", max_extent_m);
  if (!(std::isfinite(weight_floor_m) && weight_floor_m > 0.0))
    fail("weight_floor_m must be finite and > 0", weight_floor_m);
  if (max_contacts < 1) fail("max_contacts must be >= 1", max_contacts);
}

double ContactPairWeight(double signed_distance_m, double weight_floor_m) noexcept {
  const double d = signed_distance_m, f = weight_floor_m;
  if (d <= 0.0) return f - d;
  if (!(d > 0.0)) return d;  // NaN
  return f * std::exp(-std::min(d / f, 50.0));
}

ContactClusterer::ContactClusterer(int max_pairs, int max_triangles)
    : max_pairs_(max_pairs), max_triangles_(max_triangles) {
  if (max_pairs < 1) {
    throw std::invalid_argument("ContactClusterer: max_pairs must be >= 1, got " +
                                std::to_string(max_pairs));
  }
  if (max_triangles < 0) {
    throw std::invalid_argument("ContactClusterer: max_triangles must be >= 0, got " +
                                std::to_string(max_triangles));
  }
  const auto n = static_cast<std::size_t>(max_pairs);
  records_.resize(n);
  order_.resize(n);
  work_.resize(n);
  kept_.resize(n);
  work_to_out_.resize(n);
  leaf_entries_.resize(2 * n);
  object_leaf_cluster_.resize(n);
  triangles_.resize(static_cast<std::size_t>(max_triangles));
  out_.resize(n);
}

void ContactClusterer::Refresh(WorkCluster& c, const ClusteringOptions& options) const noexcept {
  c.point_W = c.sum_wp_W / c.sum_w;
  const double len = glm::length(c.sum_wn_W);
  // Below 90° between members the sum never cancels; the fallback is the seed's normal.
  c.normal_W = len > 1e-300 ? c.sum_wn_W / len : records_[c.head].normal_W;
  glm::dvec3 u, v;
  WindowAxes(c.normal_W, u, v);
  double half = 0.0;
  for (int r = c.head; r >= 0; r = records_[r].next) {
    for (const glm::dvec3& w : {records_[r].point_A_W, records_[r].point_B_W}) {
      const glm::dvec3 d = w - c.point_W;
      half = std::max({half, std::abs(glm::dot(d, u)), std::abs(glm::dot(d, v))});
    }
  }
  c.extent_m = std::clamp(2.0 * (half + options.texture_margin_m), options.min_extent_m,
                          options.max_extent_m);
}

double ContactClusterer::MergedRawExtent(const WorkCluster& a, const WorkCluster& b,
                                         const ClusteringOptions& options) const noexcept {
  const glm::dvec3 p = (a.sum_wp_W + b.sum_wp_W) / (a.sum_w + b.sum_w);
  const glm::dvec3 s = a.sum_wn_W + b.sum_wn_W;
  const double len = glm::length(s);
  const glm::dvec3 n = len > 1e-300 ? s / len : a.normal_W;
  glm::dvec3 u, v;
  WindowAxes(n, u, v);
  double half = 0.0;
  for (const WorkCluster* c : {&a, &b}) {
    for (int r = c->head; r >= 0; r = records_[r].next) {
      for (const glm::dvec3& w : {records_[r].point_A_W, records_[r].point_B_W}) {
        const glm::dvec3 d = w - p;
        half = std::max({half, std::abs(glm::dot(d, u)), std::abs(glm::dot(d, v))});
      }
    }
  }
  return 2.0 * (half + options.texture_margin_m);
}

bool ContactClusterer::MayMerge(const WorkCluster& a, const WorkCluster& b, double cos_max,
                                const ClusteringOptions& options) const noexcept {
  // Cheap rejections first: the boxes overlap only if |d|² < h² + h² + (2h)².
  const glm::dvec3 d = b.point_W - a.point_W;
  const double half_sum = 0.5 * (a.extent_m + b.extent_m);
  if (!(glm::dot(d, d) < 6.0 * half_sum * half_sum)) return false;
  if (glm::dot(a.normal_W, b.normal_W) < cos_max) return false;
  const glm::dvec3 n_mean = glm::normalize(a.normal_W + b.normal_W);
  glm::dvec3 u, v;
  WindowAxes(n_mean, u, v);
  if (!(std::abs(glm::dot(d, u)) < half_sum && std::abs(glm::dot(d, v)) < half_sum &&
        std::abs(glm::dot(d, n_mean)) < 2.0 * half_sum))
    return false;
  return MergedRawExtent(a, b, options) <= options.max_extent_m;
}

void ContactClusterer::Absorb(int into, int from) noexcept {
  WorkCluster& a = work_[into];
  WorkCluster& b = work_[from];
  for (int r = b.head; r >= 0; r = records_[r].next) records_[r].cluster = into;
  records_[a.tail].next = b.head;
  a.tail = b.tail;
  a.sum_wp_W += b.sum_wp_W;
  a.sum_wn_W += b.sum_wn_W;
  a.sum_w += b.sum_w;
  a.min_signed_distance_m = std::min(a.min_signed_distance_m, b.min_signed_distance_m);
  a.depth_bound_m = std::max(a.depth_bound_m, b.depth_bound_m);
  a.num_pairs += b.num_pairs;
  b.alive = false;
  b.head = b.tail = -1;
  b.num_pairs = 0;
}

bool ContactClusterer::WindowsOverlap(int a, int b) const noexcept {
  const ContactCluster& p = out_[static_cast<std::size_t>(a)];
  const ContactCluster& q = out_[static_cast<std::size_t>(b)];
  const glm::dvec3 d = q.point_W - p.point_W;
  const double half_sum = 0.5 * (p.extent_m + q.extent_m);
  const glm::dvec3 s = p.normal_W + q.normal_W;
  const double len = glm::length(s);
  const glm::dvec3 n = len > 1e-12 ? s / len : p.normal_W;
  glm::dvec3 u, v;
  WindowAxes(n, u, v);
  return std::abs(glm::dot(d, u)) < half_sum && std::abs(glm::dot(d, v)) < half_sum &&
         std::abs(glm::dot(d, n)) < 2.0 * half_sum;
}

int ContactClusterer::ObjectLeafCluster(int leaf) const noexcept {
  const auto first = object_leaf_cluster_.begin();
  const auto last = first + num_object_leaves_;
  const auto it = std::lower_bound(first, last, std::pair<int, int>{leaf, -1});
  return it != last && it->first == leaf ? it->second : -1;
}

int ContactClusterer::AssignTriangles(const ConvexHullHierarchy& hulls, bool tool_side,
                                      int num_records, int num_out, int write_at,
                                      bool share_disjoint, bool follow_object_leaves,
                                      bool placement_only) noexcept {
  const int num_nodes = static_cast<int>(hulls.nodes.size());
  int num_entries = 0;
  for (int r = 0; r < num_records; ++r) {
    const PairRecord& rec = records_[r];
    if (rec.cluster < 0) continue;
    const int out = work_to_out_[rec.cluster];
    if (out < 0) continue;
    const int leaf = tool_side ? rec.node_A : rec.node_B;
    if (leaf == -1) {
      (tool_side ? out_[out].tool_whole_model : out_[out].object_whole_model) = true;
      continue;
    }
    if (leaf < 0 || leaf >= num_nodes || !hulls.nodes[leaf].is_leaf()) {
      if (!placement_only) ++stats_.invalid_nodes;  // counted once, in the writing pass
      continue;
    }
    leaf_entries_[num_entries++] = {leaf, rec.signed_distance_m, rec.input_index, out, false};
    if (follow_object_leaves && tool_side) {
      // The pair's object leaf's cluster also holds this tool leaf.
      const int with = ObjectLeafCluster(rec.node_B);
      if (with >= 0) {  // also where it is the pair's own cluster: kept though not the deepest
        leaf_entries_[num_entries++] = {leaf, rec.signed_distance_m, rec.input_index, with, true};
      }
    }
  }
  const auto first = leaf_entries_.begin();
  // Per leaf, its deepest pair first (ties: lowest input index), then keep one entry per leaf.
  std::sort(first, first + num_entries, [](const LeafEntry& a, const LeafEntry& b) {
    if (a.leaf != b.leaf) return a.leaf < b.leaf;
    if (a.signed_distance_m != b.signed_distance_m)
      return a.signed_distance_m < b.signed_distance_m;
    if (a.input_index != b.input_index) return a.input_index < b.input_index;
    return !a.follows && b.follows;  // a pair's own cluster before the one it follows into
  });
  int num_leaves = 0;
  int group = 0;  // the first kept entry of the current leaf
  for (int i = 0; i < num_entries; ++i) {
    const LeafEntry entry = leaf_entries_[i];
    if (num_leaves == 0 || leaf_entries_[num_leaves - 1].leaf != entry.leaf) {
      group = num_leaves;
      leaf_entries_[num_leaves++] = entry;
      continue;
    }
    bool held = false;
    for (int k = group; k < num_leaves && !held; ++k)
      held = leaf_entries_[k].cluster == entry.cluster;
    if (held) continue;
    if (entry.follows) {  // a tool leaf following its pair's object leaf
      leaf_entries_[num_leaves++] = entry;
      continue;
    }
    if (!share_disjoint) continue;
    // A further cluster of this leaf: kept when its window overlaps none of those holding it.
    bool overlaps = false;
    for (int k = group; k < num_leaves && !overlaps; ++k) {
      overlaps = WindowsOverlap(leaf_entries_[k].cluster, entry.cluster);
    }
    if (!overlaps) leaf_entries_[num_leaves++] = entry;
  }
  if (placement_only) {
    // The object's placement, first cluster per leaf (the deepest pair's entry comes first).
    num_object_leaves_ = 0;
    for (int i = 0; i < num_leaves; ++i) {
      if (i > 0 && leaf_entries_[i - 1].leaf == leaf_entries_[i].leaf) continue;
      object_leaf_cluster_[static_cast<std::size_t>(num_object_leaves_++)] = {
          leaf_entries_[i].leaf, leaf_entries_[i].cluster};
    }
    return write_at;
  }
  std::sort(first, first + num_leaves, [](const LeafEntry& a, const LeafEntry& b) {
    return a.cluster != b.cluster ? a.cluster < b.cluster : a.leaf < b.leaf;
  });
  int e = 0;
  for (int o = 0; o < num_out; ++o) {
    const int begin = write_at;
    for (; e < num_leaves && leaf_entries_[e].cluster == o; ++e) {
      for (const int t : hulls.nodes[leaf_entries_[e].leaf].triangles) {
        if (write_at < max_triangles_) {
          triangles_[write_at++] = t;
        } else {
          ++stats_.truncated_triangles;
        }
      }
    }
    const std::span<const int> view(triangles_.data() + begin,
                                    static_cast<std::size_t>(write_at - begin));
    (tool_side ? out_[o].tool_triangles : out_[o].object_triangles) = view;
  }
  return write_at;
}

std::span<const ContactCluster> ContactClusterer::Cluster(
    std::span<const HullPairContact> pairs, const ConvexHullHierarchy& tool_hulls,
    const ConvexHullHierarchy& object_hulls, const ClusteringOptions& options,
    std::span<const double> pair_depth_bound_m) noexcept {
  const bool bounds = pair_depth_bound_m.size() == pairs.size();
  const auto bound_of = [&](int input_index) {
    if (!bounds) return std::numeric_limits<double>::infinity();
    const double b = pair_depth_bound_m[static_cast<std::size_t>(input_index)];
    return std::isnan(b) ? std::numeric_limits<double>::infinity() : b;
  };
  stats_ = {};
  stats_.input_pairs = static_cast<int>(std::min<std::size_t>(pairs.size(), 1u << 30));
  if (!options.IsValid()) {
    stats_.rejected_options = true;
    return {};
  }
  const double cos_max = CosMaxAngle(options);

  // 0. Valid pairs, deepest first. Beyond capacity a heap keeps the deepest max_pairs_.
  const auto deeper_first = [](const PairRecord& a, const PairRecord& b) {
    if (a.signed_distance_m != b.signed_distance_m)
      return a.signed_distance_m < b.signed_distance_m;
    return a.input_index < b.input_index;
  };
  int n = 0;
  for (int i = 0; i < stats_.input_pairs; ++i) {
    const HullPairContact& pair = pairs[static_cast<std::size_t>(i)];
    const double len = glm::length(pair.normal_W);
    if (!std::isfinite(pair.signed_distance_m) || !IsFinite(pair.point_A_W) ||
        !IsFinite(pair.point_B_W) || !std::isfinite(len) || !(len > 1e-12)) {
      ++stats_.skipped_nonfinite;
      continue;
    }
    const PairRecord rec{i,
                         pair.signed_distance_m,
                         ContactPairWeight(pair.signed_distance_m, options.weight_floor_m),
                         0.5 * (pair.point_A_W + pair.point_B_W),
                         pair.point_A_W,
                         pair.point_B_W,
                         pair.normal_W / len,
                         pair.node_A,
                         pair.node_B,
                         -1,
                         -1};
    if (n < max_pairs_) {
      records_[n++] = rec;
      if (n == max_pairs_) std::make_heap(records_.begin(), records_.begin() + n, deeper_first);
      continue;
    }
    ++stats_.skipped_over_capacity;
    if (deeper_first(rec, records_[0])) {  // records_[0]: the shallowest kept
      std::pop_heap(records_.begin(), records_.begin() + n, deeper_first);
      records_[n - 1] = rec;
      std::push_heap(records_.begin(), records_.begin() + n, deeper_first);
    }
  }
  std::sort(records_.begin(), records_.begin() + n, deeper_first);

  // 1. Greedy: join the nearest cluster within merge distance with an agreeing normal.
  const double merge_d2 = options.merge_distance_m * options.merge_distance_m;
  int nc = 0;
  for (int r = 0; r < n; ++r) {
    PairRecord& rec = records_[r];
    int best = -1;
    double best_d2 = merge_d2;
    for (int c = 0; c < nc; ++c) {
      const glm::dvec3 d = rec.point_W - work_[c].point_W;
      const double d2 = glm::dot(d, d);
      if (d2 < best_d2 && glm::dot(rec.normal_W, work_[c].normal_W) >= cos_max) {
        best = c;
        best_d2 = d2;
      }
    }
    const glm::dvec3 wp = rec.weight_m * rec.point_W;
    const glm::dvec3 wn = rec.weight_m * rec.normal_W;
    if (best < 0) {
      WorkCluster& c = work_[nc];
      c = {};
      c.sum_wp_W = wp;
      c.sum_wn_W = wn;
      c.sum_w = rec.weight_m;
      c.min_signed_distance_m = rec.signed_distance_m;
      c.depth_bound_m = bound_of(rec.input_index);
      c.num_pairs = 1;
      c.head = c.tail = r;
      c.alive = true;
      c.point_W = rec.point_W;
      c.normal_W = rec.normal_W;
      rec.cluster = nc++;
      continue;
    }
    WorkCluster& c = work_[best];
    c.sum_wp_W += wp;
    c.sum_wn_W += wn;
    c.sum_w += rec.weight_m;
    c.min_signed_distance_m = std::min(c.min_signed_distance_m, rec.signed_distance_m);
    c.depth_bound_m = std::max(c.depth_bound_m, bound_of(rec.input_index));
    ++c.num_pairs;
    records_[c.tail].next = r;
    c.tail = r;
    rec.cluster = best;
    c.point_W = c.sum_wp_W / c.sum_w;
    const double len = glm::length(c.sum_wn_W);
    if (len > 1e-300) c.normal_W = c.sum_wn_W / len;
  }
  for (int c = 0; c < nc; ++c) Refresh(work_[c], options);
  stats_.clusters_pass1 = nc;

  // 2. Merge clusters whose windows overlap and whose normals agree, while the merged window fits.
  // Clusters 0..i−1 are kept free of such pairs; cluster i is added by merging it into the first
  // settled one it overlaps (the lower index, i.e. the deeper seed, survives) and re-checking the
  // grown cluster. O(C²) checks plus O(C) per merge.
  for (int i = 1; i < nc; ++i) {
    for (int cand = i, k = 0; k < i; ++k) {
      if (k == cand || !work_[k].alive) continue;
      if (!MayMerge(work_[k], work_[cand], cos_max, options)) continue;
      const int into = std::min(k, cand), from = std::max(k, cand);
      Absorb(into, from);
      Refresh(work_[into], options);
      cand = into;
      k = -1;  // re-check the grown cluster against every settled one
    }
  }
  for (int c = 0; c < nc; ++c) stats_.clusters_pass2 += work_[c].alive ? 1 : 0;

  // 3. Capacity: kept clusters deepest first; the surplus merges into the nearest kept one or is
  // dropped. Clusters whose numbers overflowed are dropped first (counted as non-finite).
  int m = 0;
  for (int c = 0; c < nc; ++c) {
    WorkCluster& w = work_[c];
    if (!w.alive) continue;
    if (!IsFinite(w.point_W) || !IsFinite(w.normal_W) || !std::isfinite(w.extent_m)) {
      stats_.skipped_nonfinite += w.num_pairs;
      for (int r = w.head; r >= 0; r = records_[r].next) records_[r].cluster = -1;
      w.alive = false;
      continue;
    }
    kept_[m++] = c;
  }
  std::sort(kept_.begin(), kept_.begin() + m, [this](int a, int b) {
    const double da = work_[a].min_signed_distance_m, db = work_[b].min_signed_distance_m;
    return da != db ? da < db : a < b;
  });
  const int num_out = std::min(m, options.max_contacts);
  for (int k = num_out; k < m; ++k) {
    const int s = kept_[k];
    WorkCluster& surplus = work_[s];
    int best = -1;
    double best_d2 = 0.0;
    for (int q = 0; q < num_out; ++q) {
      const WorkCluster& target = work_[kept_[q]];
      if (glm::dot(target.normal_W, surplus.normal_W) < cos_max) continue;
      const glm::dvec3 d = target.point_W - surplus.point_W;
      const double d2 = glm::dot(d, d);
      if (best >= 0 && !(d2 < best_d2)) continue;
      if (!(MergedRawExtent(target, surplus, options) <= options.max_extent_m)) continue;
      best = q;
      best_d2 = d2;
    }
    if (best >= 0) {
      Absorb(kept_[best], s);
      Refresh(work_[kept_[best]], options);
      ++stats_.merged_for_capacity;
    } else {
      for (int r = surplus.head; r >= 0; r = records_[r].next) records_[r].cluster = -1;
      surplus.alive = false;
      ++stats_.dropped_for_capacity;
    }
  }

  // Output, deepest first.
  for (int c = 0; c < nc; ++c) work_to_out_[c] = -1;
  for (int o = 0; o < num_out; ++o) {
    const WorkCluster& w = work_[kept_[o]];
    work_to_out_[kept_[o]] = o;
    ContactCluster& out = out_[o];
    out = {};
    out.point_W = w.point_W;
    out.normal_W = w.normal_W;
    out.extent_m = w.extent_m;
    out.min_signed_distance_m = w.min_signed_distance_m;
    out.depth_bound_m = w.depth_bound_m;
    out.total_weight_m = w.sum_w;
    out.num_pairs = w.num_pairs;
  }

  // 4. Triangles: each leaf to the cluster of its deepest kept pair.
  const bool share = options.share_leaves_between_disjoint_windows;
  const bool follow = options.tool_leaves_follow_object_leaves;
  // With follow, the object's leaves are placed first (without writing) so that the tool's can
  // follow them; the tool's triangles are written first either way.
  if (follow) {
    AssignTriangles(object_hulls, /*tool_side=*/false, n, num_out, 0, share,
                    /*follow_object_leaves=*/false, /*placement_only=*/true);
  }
  const int written = AssignTriangles(tool_hulls, /*tool_side=*/true, n, num_out, 0, share,
                                      /*follow_object_leaves=*/follow);
  AssignTriangles(object_hulls, /*tool_side=*/false, n, num_out, written, share);
  return {out_.data(), static_cast<std::size_t>(num_out)};
}

}  // namespace ht
