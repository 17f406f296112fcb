// The tool step against a stiff contact (haptic_core/stability_map.h): the product's implicit
// step is stable over the whole map, and an explicit step of the same forces is stable exactly
// where theory says (h·ω < 2), so the two differ where they must.

#include "haptic_core/stability_map.h"

#include <gtest/gtest.h>

namespace ht {
namespace {

TEST(StabilityMap, ImplicitIsStableEverywhereAndExplicitOnlyBelowTheLimit) {
  int differ = 0, checked_unstable = 0, checked_stable = 0;
  for (double rate : {250.0, 1000.0, 4000.0}) {
    for (double m : {0.01, 0.1, 1.0}) {
      for (double k : {1e3, 1e4, 1e5, 1e6}) {
        StabilityProbe p;
        p.stiffness_n_per_m = k;
        p.mass_kg = m;
        p.rate_hz = rate;
        const StabilityResult imp = ProbeStability(p, ToolIntegrator::kImplicitEuler);
        const StabilityResult exp = ProbeStability(p, ToolIntegrator::kExplicitEuler);
        SCOPED_TRACE(testing::Message()
                     << "k " << k << " m " << m << " rate " << rate << " h·ω " << imp.h_omega);
        EXPECT_TRUE(imp.stable);
        EXPECT_LT(imp.late_amplitude_m, 1e-3);
        if (exp.h_omega >= 2.2) {  // beyond the explicit step's limit, with a margin for damping
          EXPECT_FALSE(exp.stable);
          ++checked_unstable;
        }
        if (exp.h_omega <= 1.0) {
          EXPECT_TRUE(exp.stable);
          ++checked_stable;
        }
        differ += imp.stable != exp.stable;
      }
    }
  }
  EXPECT_GT(checked_unstable, 3);
  EXPECT_GT(checked_stable, 10);
  EXPECT_GT(differ, 3);
}

TEST(StabilityMap, BadProbesAreUnstableNotCrashes) {
  StabilityProbe p;
  p.mass_kg = 0.0;
  EXPECT_FALSE(ProbeStability(p, ToolIntegrator::kImplicitEuler).stable);
  p = {};
  p.rate_hz = -1.0;
  EXPECT_FALSE(ProbeStability(p, ToolIntegrator::kExplicitEuler).stable);
}

}  // namespace
}  // namespace ht
