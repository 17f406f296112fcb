// The speed-vs-error frontier's files (frontier_records.h): contacts.csv's and patches.csv's rows,
// frontier.csv, and summary.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "frontier_records.h"
#include "haptic_core/contact_linearization.h"

namespace ht::frontier {
namespace {

std::string MachineLine() {
  std::string cpu = "unknown CPU";
  std::ifstream info("/proc/cpuinfo");
  for (std::string line; std::getline(info, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
  return cpu + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

// The seed's timing figures for a scene (seed §19.5.2), for summary.md.
std::string SeedFigures(const std::string& scene) {
  if (scene == "fig77") {
    return "5-10 ms per frame (100-200 Hz), about 104 pairs clustered into up to 7 contacts, on "
           "this scene";
  }
  if (scene == "hammer_torus") {
    return "the seed gives no timing for this scene; on its other complex-contact scene (file on "
           "CAD part) 5-10 ms per frame (100-200 Hz)";
  }
  return "about 2 ms per step (about 500 Hz) with one contact";
}

}  // namespace

std::string Fmt(double v, int precision) {
  if (!std::isfinite(v)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", precision, v);
  return buf;
}

void WriteQuat(std::ostream& o, const RigidTransform& X) {
  o << X.translation.x << ',' << X.translation.y << ',' << X.translation.z << ',' << X.rotation.w
    << ',' << X.rotation.x << ',' << X.rotation.y << ',' << X.rotation.z;
}

void WriteWrench(std::ostream& o, const Wrench& F) {
  o << F.force.x << ',' << F.force.y << ',' << F.force.z << ',' << F.torque.x << ',' << F.torque.y
    << ',' << F.torque.z;
}

void WriteContactsHeader(std::ostream& o) {
  o << "scene,setting,pose_id,contact,tool,object,tool_px,tool_py,tool_pz,tool_qw,tool_qx,"
       "tool_qy,tool_qz,obj_px,obj_py,obj_pz,obj_qw,obj_qx,obj_qy,obj_qz,window_cx,window_cy,"
       "window_cz,window_nx,window_ny,window_nz,window_ux,window_uy,window_uz,window_extent_m,"
       "grid,stiffness_n_per_m,delta_m,delta_gt_m,fx,fy,fz,tx,ty,tz,fx_gt,fy_gt,fz_gt,tx_gt,"
       "ty_gt,tz_gt,tool_com_x,tool_com_y,tool_com_z,gt_samples_per_side,gt_converged\n";
}

void WritePatchesHeader(std::ostream& o) {
  o << "scene,pose_id,patch,tool,object,tool_px,tool_py,tool_pz,tool_qw,tool_qx,tool_qy,tool_qz,"
       "obj_px,obj_py,obj_pz,obj_qw,obj_qx,obj_qy,obj_qz,window_cx,window_cy,window_cz,"
       "window_nx,window_ny,window_nz,window_ux,window_uy,window_uz,window_extent_m,delta_gt_m,"
       "fx_gt,fy_gt,fz_gt,tx_gt,ty_gt,tz_gt,tool_com_x,tool_com_y,tool_com_z,stiffness_n_per_m,"
       "gradient_step_m,pairs,tool_inside_area_m2,object_inside_area_m2,dV_dx,dV_dy,dV_dz,"
       "dV_dthx,dV_dthy,dV_dthz,gt_samples_per_side,gt_converged,share,gap_to_neighbour_m,"
       "tilt_step_rad,pressure_volume_m3,pressure_fx_per_kp,pressure_fy_per_kp,pressure_fz_per_kp,"
       "pressure_tx_per_kp,pressure_ty_per_kp,pressure_tz_per_kp,pressure_samples_per_side,"
       "pressure_converged\n";
}

void WritePatchRow(std::ostream& o, const SceneReport& rep, std::size_t k, std::size_t q,
                   const TruthPatch& patch, const RigidTransform& X_WFt,
                   const RigidTransform& X_WFe, const glm::dvec3& com_W, double stiffness_n_per_m) {
  const ContactWindow& w = patch.window;
  const ContactLinearization& lin = patch.contact.linearization;
  o << rep.name << ',' << k << ',' << q << ',' << rep.tool_file << ',' << rep.object_file << ',';
  WriteQuat(o, X_WFt);
  o << ',';
  WriteQuat(o, X_WFe);
  o << ',' << w.center_W.x << ',' << w.center_W.y << ',' << w.center_W.z << ',' << w.normal_W.x
    << ',' << w.normal_W.y << ',' << w.normal_W.z << ',' << w.axis_u_W.x << ',' << w.axis_u_W.y
    << ',' << w.axis_u_W.z << ',' << w.extent_m << ',' << lin.depth_m << ',';
  WriteWrench(o, patch.contact.F_T_W);
  const glm::dvec3 gx = 0.5 * (patch.dV_dx_tool_W + patch.dV_dx_environment_W);
  const glm::dvec3 gt = 0.5 * (patch.dV_dtheta_tool_W + patch.dV_dtheta_environment_W);
  o << ',' << com_W.x << ',' << com_W.y << ',' << com_W.z << ',' << stiffness_n_per_m << ','
    << patch.gradient_step_m << ',' << patch.pairs << ',' << patch.tool_inside_area_m2 << ','
    << patch.environment_inside_area_m2 << ',' << gx.x << ',' << gx.y << ',' << gx.z << ',' << gt.x
    << ',' << gt.y << ',' << gt.z << ',' << patch.contact.base.samples_per_side << ','
    << (patch.contact.base.converged ? 1 : 0) << ',' << patch.share << ','
    << patch.gap_to_neighbour_m << ',' << patch.tilt_step_rad << ',' << patch.pressure.volume_m3
    << ',';
  WriteWrench(o, patch.pressure.per_kp);
  o << ',' << patch.pressure.samples_per_side << ',' << (patch.pressure.converged ? 1 : 0) << '\n';
}

void WriteContactRow(std::ostream& o, const SceneReport& rep, const SettingRun& run,
                     const ContactRecord& c, const GtJob& job, const RigidTransform& X_WFt) {
  const ContactWindow& w = c.query.window;
  o << rep.name << ',' << run.setting.name << ',' << c.pose << ',' << c.index << ','
    << rep.tool_file << ',' << rep.object_file << ',';
  WriteQuat(o, X_WFt);
  o << ',';
  WriteQuat(o, c.query.X_WO);
  o << ',' << w.center_W.x << ',' << w.center_W.y << ',' << w.center_W.z << ',' << w.normal_W.x
    << ',' << w.normal_W.y << ',' << w.normal_W.z << ',' << w.axis_u_W.x << ',' << w.axis_u_W.y
    << ',' << w.axis_u_W.z << ',' << w.extent_m << ',' << w.resolution << ','
    << c.query.stiffness_n_per_m << ',' << c.lin.depth_m << ',' << job.result.linearization.depth_m
    << ',';
  // As the model gives it at q0 (ContactDepthAt).
  PenetrationGradient J_q0;
  const double depth_q0 = ContactDepthAt(c.lin, Twist{}, &J_q0);
  WriteWrench(o, PenaltyWrench(depth_q0, J_q0, c.lin.stiffness_n_per_m));
  o << ',';
  WriteWrench(o, job.result.F_T_W);
  const glm::dvec3 com_W = X_WFt * run.X_TFt.Inverse().translation;
  o << ',' << com_W.x << ',' << com_W.y << ',' << com_W.z << ',' << job.result.base.samples_per_side
    << ',' << (job.result.base.converged ? 1 : 0) << '\n';
}

void WriteFrontierCsv(const std::string& path, const std::vector<SceneReport>& reports) {
  PartialFile f(path);
  std::ostream& o = f.out();
  o << "scene,setting,method,backend,renderer,grid,texture_size,coarse_scale,depth_bits,"
       "tool_coarse_triangles,object_coarse_triangles,poses,contacts_mean,leaf_pairs_mean,"
       "collision_p50_us,collision_p95_us,texture_p50_us,texture_p95_us,total_p50_us,"
       "total_p95_us,force_rel_rms,force_rel_p50,torque_rel_rms,force_dir_p50_deg,force_dir_p95_"
       "deg,"
       "delta_err_p50_um,delta_err_p95_um,windows,contacts_missed,contacts_invented,"
       "poses_missed,poses_invented,pipeline_force_rel_rms,pipeline_torque_rel_rms,"
       "volume_dir_p50_deg,volume_dir_p95_deg,volume_arm_rel_p50,poses_truth_without_force,"
       "poses_force_without_truth,prediction_force_rel_rms,prediction_torque_rel_rms,"
       "tool_surface_p99_um,object_surface_p99_um,tool_surface_outside_p99_um,"
       "object_surface_outside_p99_um,tool_surface_share_outside,"
       "object_surface_share_outside,switch_jump_p50_n,switch_jump_p99_n,switch_jump_max_n,"
       "switch_jumps_over_0_2_n,pressure_force_rel_rms,pressure_torque_rel_rms,pareto,"
       "skipped\n";
  for (const SceneReport& rep : reports) {
    for (const SettingRun& r : rep.runs) {
      const FrontierSetting& s = r.setting;
      const auto clean = [](std::string t) {
        std::replace(t.begin(), t.end(), ',', ';');
        std::replace(t.begin(), t.end(), '\n', ' ');
        return t;
      };
      const Metrics& m = r.m;
      std::vector<std::string> cells = {
          rep.name,
          s.name,
          FrontierMethodName(s.method),
          s.method == FrontierMethod::kFullResolutionFcl ? "cpu" : s.backend,
          clean(r.renderer),
          std::to_string(s.grid),
          std::to_string(s.texture_size),
          Fmt(s.coarse_scale),
          std::to_string(s.backend == "gpu" ? s.depth_bits : 32),
          std::to_string(r.tool_coarse_triangles),
          std::to_string(r.object_coarse_triangles)};
      if (r.skipped.empty()) {
        for (const std::string& c : {std::to_string(r.poses.size()),
                                     Fmt(m.contacts_mean),
                                     Fmt(m.leaf_pairs_mean),
                                     Fmt(m.collision_p50),
                                     Fmt(m.collision_p95),
                                     Fmt(m.texture_p50),
                                     Fmt(m.texture_p95),
                                     Fmt(m.total_p50),
                                     Fmt(m.total_p95),
                                     Fmt(m.force_rel_rms),
                                     Fmt(m.force_rel_p50),
                                     Fmt(m.torque_rel_rms),
                                     Fmt(m.dir_p50_deg),
                                     Fmt(m.dir_p95_deg),
                                     Fmt(m.delta_p50_um),
                                     Fmt(m.delta_p95_um),
                                     std::to_string(m.windows),
                                     std::to_string(m.missed),
                                     std::to_string(m.invented),
                                     std::to_string(m.poses_missed),
                                     std::to_string(m.poses_invented),
                                     Fmt(m.pipeline_force_rel_rms),
                                     Fmt(m.pipeline_torque_rel_rms),
                                     Fmt(m.volume_dir_p50_deg),
                                     Fmt(m.volume_dir_p95_deg),
                                     Fmt(m.volume_arm_rel_p50),
                                     std::to_string(m.poses_truth_without_force),
                                     std::to_string(m.poses_force_without_truth),
                                     Fmt(m.prediction_force_rel_rms),
                                     Fmt(m.prediction_torque_rel_rms),
                                     Fmt(r.tool_surface.p99_m * 1e6),
                                     Fmt(r.object_surface.p99_m * 1e6),
                                     Fmt(r.tool_surface.outside_p99_m * 1e6),
                                     Fmt(r.object_surface.outside_p99_m * 1e6),
                                     Fmt(r.tool_surface.share_outside),
                                     Fmt(r.object_surface.share_outside),
                                     Fmt(m.switch_jump_p50_n),
                                     Fmt(m.switch_jump_p99_n),
                                     Fmt(m.switch_jump_max_n),
                                     std::to_string(m.switch_jumps_over_0_2_n),
                                     Fmt(m.pressure_force_rel_rms),
                                     Fmt(m.pressure_torque_rel_rms),
                                     std::string(m.pareto ? "1" : "0"),
                                     std::string()}) {
          cells.push_back(c);
        }
      } else {
        cells.resize(cells.size() + 43);
        cells.push_back(clean(r.skipped));
      }
      for (std::size_t i = 0; i < cells.size(); ++i) o << (i ? "," : "") << cells[i];
      o << '\n';
    }
  }
  f.Commit();
}

void WriteSummary(const std::string& path, const FrontierOptions& options,
                  const std::vector<SceneReport>& reports, const std::string& plot_note,
                  double total_s) {
  PartialFile sm(path);
  std::ostream& s = sm.out();
  s << "# Speed against error: the frontier\n\n";
  s << "Command: `" << options.command_line << "`  \n";
  s << "Machine: " << MachineLine() << "; total " << Fmt(total_s, 3) << " s.  \n";
  s << "Timed steps run one at a time on one thread (settings named threads2 on two: the texture "
       "stage and the coarse query); "
       "the ground truth afterwards on "
    << options.threads << ".\n\n";
  s << "Two measures of error, each named where it is used:\n\n"
       "- **Pipeline truth (T1)**, the headline measure: from the **full-resolution** meshes "
       "alone, at each pose, the intersecting triangle pairs (FCL) grouped into contact patches "
       "(connected regions at the method's clustering distance and angle, then merged where two "
       "would measure one interpenetration twice: a textured face's flanks, overlapping windows, "
       "slivers at an edge); per patch its direction n, the flatter surface's normal averaged over "
       "5 mm (texture finer than that does not tilt it; else −∇V, the area-weighted normals of "
       "the surfaces inside the other solid, V the patch's intersection volume), its centre "
       "(their area centroid) and a window holding their projection; `--truth-no-merge` gives "
       "the truth without them (single-linkage patches, n = −∇V); δ_gt and ∇δ_gt on that window "
       "by Embree ray casting (the method's facing and "
       "box rules), gradient steps at texel scale (0.1 mm); Φ_gt = Σ −k δ_gt ∇δ_gt. It owns its "
       "contacts: a method's window in the wrong place or along the wrong n, or a contact in no "
       "window, is error. `pipeline force / torque err` is the relative RMS "
       "√(Σ|F − F_gt|²/Σ|F_gt|²) over the poses. patches.csv lists every patch.\n"
       "- **Volume truth (T2)**, independent of the force law: the angle between the method's "
       "force and −∇_x V (summed over the pose's patches; poses where both are non-zero) and the "
       "relative error of the lever arm |τ|/|F| against |∇_θ V|/|∇_x V| (torques about the tool's "
       "centre of mass). `truth w/o force`: poses whose full-resolution meshes intersect where "
       "the method gives no force; `force w/o truth`: the converse.\n"
       "- **Texture-stage measure** (the earlier one, kept): the ground truth on each setting's "
       "**own** windows (the same centre, n and box), its gradient at the 50×50 grid's step "
       "table, so it isolates what the texture and the grid lose inside a window; the two "
       "baselines, which have no windows, against the default setting's. `texture-stage force "
       "err` (RMS; pose p50), torque, direction and δ errors and missed / invented windows use "
       "it; poses missed / invented are against FCL's intersection test.\n"
       "- **Model prediction**, what the operator's 1 kHz loop renders "
       "between two models: the contact models of about 20 poses spread evenly, evaluated "
    << Fmt(options.prediction_rotation_rad * 1e3, 3) << " mrad either way about W's x and y and "
    << Fmt(options.prediction_translation_m * 1e3, 3)
    << " mm either way along them (`--prediction-rotation-mrad`, `--prediction-translation-mm`), "
       "against the **pipeline "
       "truth** at those displaced poses; `model prediction F / τ err` is the relative RMS over "
       "them. A linearization holds one arm of a face's V: past the vertex only a depth "
       "field (evaluated where the tool is) has the other edge's torque.\n"
       "- **Pressure truth**, for the `pressure` setting (the depth fields under the pressure "
       "law, `slave_sim --force-law pressure`): on each pipeline-truth patch's window, the "
       "overlap along its n at the centres of an M×M grid of rays over the full-resolution "
       "meshes, the law's wrench k_p Σ A d (−∇d) with k_p = k / A_tool (the tool's bounding "
       "box's largest face), M doubled from "
    << options.ground_truth.initial_samples
    << " until the wrench changes by less than 1 % (patches.csv's pressure_* columns, per unit "
       "k_p); `pressure_force_rel_rms` and `pressure_torque_rel_rms` in frontier.csv are that "
       "setting's relative RMS against it.\n\n"
       "Pareto and the fastest setting within 5 % use the pipeline truth.\n\n";
  if (!plot_note.empty()) s << plot_note << "\n\n";
  for (const SceneReport& rep : reports) {
    s << "## " << rep.name << "\n\n";
    s << "- Meshes: `meshes/" << rep.tool_file << "` (tool, " << rep.tool_full
      << " triangles) and `meshes/" << rep.object_file << "` (object, " << rep.object_full
      << " triangles): " << rep.mesh_note << ".\n";
    s << "- Poses: " << rep.poses << ", from " << rep.pose_source << "; " << rep.touching
      << " of them intersect at full resolution (FCL).\n";
    const int m50 =
        static_cast<int>(Percentile(std::vector<double>(rep.gt_m.begin(), rep.gt_m.end()), 0.5));
    const int mmax = rep.gt_m.empty() ? 0 : *std::max_element(rep.gt_m.begin(), rep.gt_m.end());
    s << "- Texture-stage ground truth: " << rep.gt_windows << " distinct windows, "
      << rep.gt_converged << " converged (δ changed by < "
      << Fmt(options.ground_truth.tolerance_m * 1e6, 3)
      << " µm when M doubled); M×M samples with M from " << options.ground_truth.initial_samples
      << " (p50 " << m50 << ", max " << mmax << ", cap " << options.ground_truth.max_samples
      << "), each grid refined locally from its " << options.ground_truth.refine_seeds
      << " best cells down to " << Fmt(options.ground_truth.refine_step_m * 1e9, 3)
      << " nm; largest last change " << Fmt(rep.gt_change_max_m * 1e6, 3) << " µm; " << rep.gt_rays
      << " rays in " << Fmt(rep.gt_seconds, 3) << " s.\n";
    s << "- Pipeline truth: " << rep.truth_poses_intersecting << " of " << rep.poses
      << " poses intersect at full resolution; " << rep.truth_patches
      << " patches (window side p50 " << Fmt(Percentile(rep.truth_extents_mm, 0.5), 3)
      << " mm, max "
      << Fmt(rep.truth_extents_mm.empty()
                 ? 0.0
                 : *std::max_element(rep.truth_extents_mm.begin(), rep.truth_extents_mm.end()),
             3)
      << " mm; " << rep.truth_patches_merged
      << (options.truth_merge_patches
              ? " more merged into them: neighbours on one face at the 5 mm scale, overlapping "
                "windows within 60°, or slivers at a patch's edge"
              : " merged: --truth-no-merge")
      << "); "
      << (options.truth_share_fade_m > 0.0
              ? std::to_string(rep.truth_patches_shared) +
                    " patches share their penalty with a neighbour within the clustering distance "
                    "plus " +
                    Fmt(options.truth_share_fade_m * 1e3, 3) + " mm"
              : std::string("patches never share (--truth-share-fade-mm 0)"))
      << "; tilt steps "
      << (options.truth_tilt_lift_m > 0.0
              ? "lift the window's edge by " + Fmt(options.truth_tilt_lift_m * 1e6, 3) +
                    " um (--truth-tilt-lift-um)"
              : std::string("lift the window's edge by a texel step"))
      << "; intersecting poses with a zero truth: " << rep.truth_poses_zero
      << "; pair lists cut at the cap: " << rep.truth_pairs_truncated << "; " << rep.truth_rays
      << " rays in " << Fmt(rep.truth_seconds, 3) << " s.\n\n";
    s << "| setting | method | backend | N | texture | coarse | leaf pairs / contacts | step p50 / "
         "p95 (ms) | collision p50 | texture p50 | **pipeline force err** | pipeline torque err | "
         "volume dir p50 / p95 (°) | arm err p50 | truth w/o force / force w/o truth | "
         "model prediction F / τ err | texture-stage force err (RMS; pose p50) | texture-stage "
         "torque err | texture-stage dir "
         "p50 / p95 (°) | δ err p50 / p95 (µm) | missed / invented | Pareto |\n";
    s << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
         "\n";
    const SettingRun* fastest = nullptr;
    const SettingRun* def = nullptr;
    for (const SettingRun& r : rep.runs) {
      const FrontierSetting& st = r.setting;
      if (st.name == "default") def = &r;
      s << "| " << st.name << " | " << FrontierMethodName(st.method) << " | "
        << (st.backend == "gpu" ? "gpu " + std::to_string(st.depth_bits) + "-bit" : "cpu") << " | "
        << st.grid << " | "
        << (st.texture_size == 0 ? std::string("auto") : std::to_string(st.texture_size)) << " | ×"
        << Fmt(st.coarse_scale) << " | ";
      if (!r.skipped.empty()) {
        s << "skipped: " << r.skipped << " |||||||||||||||\n";
        continue;
      }
      const Metrics& m = r.m;
      s << Fmt(m.leaf_pairs_mean, 3) << " / " << Fmt(m.contacts_mean, 3) << " | "
        << Fmt(m.total_p50 / 1e3, 3) << " / " << Fmt(m.total_p95 / 1e3, 3) << " | "
        << Fmt(m.collision_p50 / 1e3, 3) << " | " << Fmt(m.texture_p50 / 1e3, 3) << " | **"
        << Fmt(100 * m.pipeline_force_rel_rms, 3) << " %** | "
        << Fmt(100 * m.pipeline_torque_rel_rms, 3) << " % | " << Fmt(m.volume_dir_p50_deg, 3)
        << " / " << Fmt(m.volume_dir_p95_deg, 3) << " | " << Fmt(100 * m.volume_arm_rel_p50, 3)
        << " % | " << m.poses_truth_without_force << " / " << m.poses_force_without_truth << " | "
        << (std::isfinite(m.prediction_force_rel_rms)
                ? Fmt(100 * m.prediction_force_rel_rms, 3) + " / " +
                      Fmt(100 * m.prediction_torque_rel_rms, 3) + " %"
                : std::string("—"))
        << " | " << Fmt(100 * m.force_rel_rms, 3) << " %; " << Fmt(100 * m.force_rel_p50, 3)
        << " % | " << Fmt(100 * m.torque_rel_rms, 3) << " % | " << Fmt(m.dir_p50_deg, 3) << " / "
        << Fmt(m.dir_p95_deg, 3) << " | " << Fmt(m.delta_p50_um, 3) << " / "
        << Fmt(m.delta_p95_um, 3) << " | " << m.missed << " / " << m.invented << " (poses "
        << m.poses_missed << " / " << m.poses_invented << ") | " << (m.pareto ? "yes" : "")
        << " |\n";
      if (m.pipeline_force_rel_rms <= 0.05 && (!fastest || m.total_p50 < fastest->m.total_p50)) {
        fastest = &r;
      }
    }
    s << "\n";
    for (const SettingRun& r : rep.runs) {  // e.g. a GPU that failed mid-run
      if (!r.note.empty()) s << "Note on " << r.setting.name << ": " << r.note << ".\n";
    }
    s << "Surface error of the built models (MeasureSurfaceError: full-resolution points against "
         "the textured coarse model, tool / object; p99 distance, p99 and share of points lying "
         "outside the model by more than "
      << Fmt(SurfaceErrorParams{}.outside_threshold_m * 1e6, 3)
      << " µm, where the method reads the depth low):";
    for (const SettingRun& r : rep.runs) {
      if (!r.skipped.empty() || r.tool_surface.samples == 0) continue;
      s << " " << r.setting.name << " " << Fmt(r.tool_surface.p99_m * 1e6, 3) << " / "
        << Fmt(r.object_surface.p99_m * 1e6, 3) << " µm, outside "
        << Fmt(r.tool_surface.outside_p99_m * 1e6, 3) << " / "
        << Fmt(r.object_surface.outside_p99_m * 1e6, 3) << " µm, "
        << Fmt(100 * r.tool_surface.share_outside, 3) << " / "
        << Fmt(100 * r.object_surface.share_outside, 3) << " %;";
    }
    s << "\n\n";
    for (const SettingRun& r : rep.runs) {
      if (r.local_tool_p99_m.empty()) continue;
      const std::vector<double>&t = r.local_tool_p99_m, &o = r.local_object_p99_m,
            &to = r.local_tool_outside_m, &oo = r.local_object_outside_m;
      s << "Near the truth patches of the poses where " << r.setting.name << " gives no force ("
        << t.size() << " patches, within " << Fmt(kLocalSurfaceRadiusM * 1e3, 3)
        << " mm of each centre): surface error p99, median "
        << "over the patches / largest, tool " << Fmt(Percentile(t, 0.5) * 1e6, 3) << " / "
        << Fmt(Percentile(t, 1.0) * 1e6, 3) << " µm, object " << Fmt(Percentile(o, 0.5) * 1e6, 3)
        << " / " << Fmt(Percentile(o, 1.0) * 1e6, 3) << " µm; outside p99 tool "
        << Fmt(Percentile(to, 0.5) * 1e6, 3) << " / " << Fmt(Percentile(to, 1.0) * 1e6, 3)
        << " µm, object " << Fmt(Percentile(oo, 0.5) * 1e6, 3) << " / "
        << Fmt(Percentile(oo, 1.0) * 1e6, 3) << " µm.\n";
    }
    s << "\n";
    if (fastest) {
      s << "Fastest setting with pipeline force error ≤ 5 %: **" << fastest->setting.name << "**, "
        << Fmt(fastest->m.total_p50 / 1e3, 3) << " ms per step (p50), "
        << Fmt(fastest->m.contacts_mean, 3) << " contacts per step, "
        << Fmt(fastest->m.contacts_mean > 0
                   ? fastest->m.texture_p50 / 1e3 / fastest->m.contacts_mean
                   : 0.0,
               3)
        << " ms of texture stage per contact; seed (2004 GPU): about 2 ms per contact, "
        << SeedFigures(rep.name) << ".\n";
    } else {
      const SettingRun* best = nullptr;
      for (const SettingRun& r : rep.runs) {
        if (r.skipped.empty() && std::isfinite(r.m.pipeline_force_rel_rms) &&
            (!best || r.m.pipeline_force_rel_rms < best->m.pipeline_force_rel_rms)) {
          best = &r;
        }
      }
      s << "No setting reached a pipeline force error of 5 % or less on this scene";
      if (best) {
        s << "; the most accurate was **" << best->setting.name << "** ("
          << Fmt(100 * best->m.pipeline_force_rel_rms, 3) << " %, "
          << Fmt(best->m.total_p50 / 1e3, 3) << " ms per step)";
      }
      s << ". Seed (2004 GPU): about 2 ms per contact; " << SeedFigures(rep.name) << ".\n";
    }
    if (def && def->skipped.empty()) {
      s << "The default setting (N = 50, 1024² textures, the seed's coarse counts, CPU) is "
        << (def->m.pareto ? "on" : "not on")
        << " the Pareto frontier here: " << Fmt(def->m.total_p50 / 1e3, 3) << " ms per step at "
        << Fmt(100 * def->m.pipeline_force_rel_rms, 3) << " % pipeline force error ("
        << Fmt(100 * def->m.force_rel_rms, 3) << " % on the texture-stage measure), volume "
        << "direction error p95 " << Fmt(def->m.volume_dir_p95_deg, 3) << "°.\n";
    }
    s << "\n";
  }
  sm.Commit();
}

}  // namespace ht::frontier
