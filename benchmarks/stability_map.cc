// Stability map of the operator's tool step (issue 14, DESIGN.md §8): contact stiffness × tool
// mass × loop rate, the product's linearized backward-Euler step beside an explicit step of the
// same forces. Writes OUT/stability_map.csv and, with python3-matplotlib, OUT/stability_map.png.
//
// Usage: stability_map --out DIR

#include "haptic_core/stability_map.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#ifndef HT_PLOT_STABILITY_SCRIPT
#define HT_PLOT_STABILITY_SCRIPT ""
#endif

int main(int argc, char** argv) {
  CLI::App app{
      "Stability map of the tool step: contact stiffness x tool mass x loop rate, implicit\n"
      "(the product's) and explicit Euler; CSV and plot"};
  std::string out_dir;
  double duration_s = 1.0;
  app.add_option("--out", out_dir, "output folder (created)")->required();
  app.add_option("--duration", duration_s, "simulated seconds per point")
      ->check(CLI::Range(0.05, 60.0))
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  try {
    std::filesystem::create_directories(out_dir);
    const std::string csv = out_dir + "/stability_map.csv";
    std::ofstream f(csv + ".partial");
    if (!f) throw std::runtime_error("cannot write " + csv + ".partial");
    f << "stiffness_n_per_m,mass_kg,rate_hz,h_omega,implicit_stable,explicit_stable,"
         "implicit_late_amplitude_m,explicit_late_amplitude_m\n";
    int points = 0, differ = 0, implicit_unstable = 0;
    for (double rate : {250.0, 500.0, 1000.0, 2000.0, 4000.0}) {
      for (double m : {0.01, 0.03, 0.1, 0.3, 1.0}) {
        for (double k : {1e3, 3e3, 1e4, 3e4, 1e5, 3e5, 1e6}) {
          ht::StabilityProbe p;
          p.stiffness_n_per_m = k;
          p.mass_kg = m;
          p.rate_hz = rate;
          p.duration_s = duration_s;
          const auto imp = ht::ProbeStability(p, ht::ToolIntegrator::kImplicitEuler);
          const auto exp = ht::ProbeStability(p, ht::ToolIntegrator::kExplicitEuler);
          f << k << ',' << m << ',' << rate << ',' << imp.h_omega << ',' << imp.stable << ','
            << exp.stable << ',' << imp.late_amplitude_m << ',' << exp.late_amplitude_m << '\n';
          ++points;
          differ += imp.stable != exp.stable;
          implicit_unstable += !imp.stable;
        }
      }
    }
    f.close();
    if (!f) throw std::runtime_error("cannot write " + csv);
    std::filesystem::rename(csv + ".partial", csv);
    std::printf("stability_map: %d points; implicit unstable at %d; the two differ at %d; %s\n",
                points, implicit_unstable, differ, csv.c_str());
    const std::string script = HT_PLOT_STABILITY_SCRIPT;
    if (!script.empty() && std::filesystem::exists(script)) {
      const std::string cmd =
          "/usr/bin/python3 '" + script + "' '" + csv + "' '" + out_dir + "/stability_map.png'";
      if (std::system(cmd.c_str()) != 0) {
        std::fprintf(stderr, "stability_map: no plot (%s failed; needs python3-matplotlib)\n",
                     cmd.c_str());
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "stability_map: error: %s\n", e.what());
    return 2;
  }
}
