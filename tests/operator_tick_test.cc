// The operator's tick as a unit (master_station/operator_tick.h), run tick by tick without
// threads or sockets: a failed device read ramps the force down through the safety stage and the
// recovery ramps it back up (it used to jump); a new model blends in; a scripted jump drops the
// models of the old place; non-finite device readings give zero; and a tick never allocates.

#include "master_station/operator_tick.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "allocation_counter.h"  // the tick / step must make no allocation
#include "haptic_core/demo/demo_scenes.h"

using ht::testing_support::Allocations;

namespace ht {
namespace {

constexpr double kH = 1e-3;

OperatorTickConfig Config() {
  OperatorTickConfig c;
  c.inertia = BlockOnGearToolInertia();
  c.h_s = kH;
  c.passivity_max_damping_ns_per_m = 4.0 * 5.0;
  return c;
}

// A wall under the tool along +z: δ = 2 mm at the origin, so the coupling (1,000 N/m) pressing
// the handle 2 mm into it gives a few newtons.
ArrivedModel Wall(std::int64_t now_ns) {
  ArrivedModel a;
  a.model.num_contacts = 1;
  a.model.contacts[0].depth_m = 2e-3;
  a.model.contacts[0].stiffness_n_per_m = 8000.0;
  a.model.contacts[0].gradient.d_translation_W = {0, 0, -1};
  a.model.F_T_W_at_q0 = PenaltyWrench(2e-3, a.model.contacts[0].gradient, 8000.0);
  a.tool_state_sent_ns = now_ns;
  a.built_local_ns = now_ns;
  return a;
}

OperatorTickInput Pressing(std::int64_t now_ns) {
  OperatorTickInput in;
  in.now_ns = now_ns;
  in.device.X_MH.translation = {0, 0, -10e-3};  // the handle 10 mm below the surface
  return in;
}

TEST(OperatorTick, AFailedDeviceReadRampsDownAndTheRecoveryRampsUp) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  const SafetyLimits limits = Config().safety;
  const double max_step = limits.max_force_rate_n_per_s * kH + 1e-9;
  std::int64_t now = 0;
  ArrivedModel wall = Wall(now);
  OperatorTickInput in = Pressing(now);
  in.arrived = &wall;
  double last = 0.0, pressing = 0.0;
  for (int k = 0; k < 500; ++k) {  // settle while pressing
    in.now_ns = now += 1000000;
    wall.tool_state_sent_ns = wall.built_local_ns = now;
    last = glm::length(tick.Step(in).F_device_W.force);
    in.arrived = k % 2 ? &wall : nullptr;
  }
  pressing = last;
  ASSERT_GT(pressing, 1.0) << "the press should give a few newtons";
  // 20 failed reads: every tick through the safety stage, the force ramps to zero.
  OperatorTickInput fault;
  fault.device_ok = false;
  int ticks_to_zero = -1;
  for (int k = 0; k < 20; ++k) {
    fault.now_ns = now += 1000000;
    const double f = glm::length(tick.Step(fault).F_device_W.force);
    EXPECT_LE(std::abs(f - last), max_step) << "fault tick " << k;
    EXPECT_LE(f, last + 1e-12);
    if (ticks_to_zero < 0 && f == 0.0) ticks_to_zero = k + 1;
    last = f;
  }
  EXPECT_EQ(last, 0.0);
  EXPECT_GT(ticks_to_zero, 0);
  EXPECT_EQ(tick.counters().device_faults, 20);
  // The device answers again: the force comes back by at most the rate limit per tick.
  int ticks_to_full = -1;
  for (int k = 0; k < 50; ++k) {
    in = Pressing(now += 1000000);
    wall.tool_state_sent_ns = wall.built_local_ns = now;
    in.arrived = &wall;
    const double f = glm::length(tick.Step(in).F_device_W.force);
    EXPECT_LE(std::abs(f - last), max_step) << "recovery tick " << k;
    if (ticks_to_full < 0 && f > 0.99 * pressing) ticks_to_full = k + 1;
    last = f;
  }
  EXPECT_GT(ticks_to_full, 1) << "the force must ramp back, not jump";
  std::printf("fault: %.3f N to 0 in %d ticks; recovery to 99 %% in %d ticks (limit %.1f N/tick)\n",
              pressing, ticks_to_zero, ticks_to_full, max_step);
}

TEST(OperatorTick, FreeSpaceGivesNoForceAndTheToolFollowsTheHandle) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  OperatorTickInput in;
  in.device.X_MH.translation = {0.01, 0, 0};
  OperatorTickOutput out;
  for (int k = 0; k < 2000; ++k) {
    in.now_ns = (k + 1) * 1000000LL;
    out = tick.Step(in);
  }
  EXPECT_NEAR(tick.tool().X_WT.translation.x, 0.01, 1e-6);
  EXPECT_NEAR(glm::length(out.F_device_W.force), 0.0, 1e-6);
  EXPECT_EQ(out.model_age_ms, -1.0);
}

TEST(OperatorTick, ANewModelBlendsInWithBoundedSteps) {
  OperatorTickConfig c = Config();
  c.model_blend_ticks = 8;
  c.safety.max_force_rate_n_per_s = 1e9;  // see the blend, not the rate limit
  OperatorTick tick(c, RigidTransform{}, ToolState{});
  OperatorTickInput in = Pressing(1000000);
  for (int k = 0; k < 300; ++k) tick.Step(in);  // pressing into nothing: the tool sits at −10 mm
  ArrivedModel wall = Wall(in.now_ns);
  in.arrived = &wall;
  double last = glm::length(tick.Step(in).step.F_contact_T_W.force);
  in.arrived = nullptr;
  double biggest = 0.0;
  for (int k = 0; k < 8; ++k) {
    const double f = glm::length(tick.Step(in).step.F_contact_T_W.force);
    biggest = std::max(biggest, f - last);
    last = f;
  }
  EXPECT_GT(last, 10.0);
  EXPECT_LT(biggest, 0.6 * last) << "blended in over the ticks, not at once";
  EXPECT_EQ(tick.counters().models_used, 1);
}

TEST(OperatorTick, AWorkspaceJumpDropsModelsOfTheOldPlace) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  OperatorTickInput in;
  in.now_ns = 1000000;
  tick.Step(in);
  in.workspace_shift_M = {0.5, 0, 0};  // go 50 cm along x
  tick.Step(in);
  EXPECT_EQ(tick.counters().workspace_jumps, 1);
  EXPECT_NEAR(tick.X_WM().translation.x, 0.5, 1e-12);
  ArrivedModel old_place = Wall(in.now_ns);  // linearized at the origin
  in.arrived = &old_place;
  tick.Step(in);
  EXPECT_EQ(tick.counters().models_from_before_jump, 1);
  EXPECT_EQ(tick.counters().models_used, 0);
  ArrivedModel new_place = Wall(in.now_ns);
  new_place.model.X_WT0.translation = {0.5, 0, 0};
  in.arrived = &new_place;
  tick.Step(in);
  EXPECT_EQ(tick.counters().models_used, 1);
}

TEST(OperatorTick, AModelArrivingOnTheJumpsOwnTickIsJudgedAgainstTheNewPlace) {
  // It used to be taken before the jump was applied, counted as used, then dropped by the jump.
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  OperatorTickInput in;
  in.now_ns = 1000000;
  tick.Step(in);
  ArrivedModel old_place = Wall(in.now_ns);  // linearized at the origin
  in.workspace_shift_M = {0.5, 0, 0};
  in.arrived = &old_place;
  tick.Step(in);
  EXPECT_EQ(tick.counters().workspace_jumps, 1);
  EXPECT_EQ(tick.counters().models_from_before_jump, 1);
  EXPECT_EQ(tick.counters().models_used, 0);
  // A model of the new place arriving on a later jump's tick is taken.
  ArrivedModel new_place = Wall(in.now_ns);
  new_place.model.X_WT0.translation = {0.6, 0, 0};
  in.workspace_shift_M = {0.6, 0, 0};
  in.arrived = &new_place;
  const OperatorTickOutput out = tick.Step(in);
  EXPECT_EQ(tick.counters().workspace_jumps, 2);
  EXPECT_EQ(tick.counters().models_used, 1);
  EXPECT_GE(out.model_age_ms, 0.0);
}

TEST(OperatorTick, TheStopRampScalesTheWrenchBeforeThePassivityObserverRecordsIt) {
  // Two ticks in lockstep pressing the handle into a wall while it moves; on the last tick one
  // gets half gain. Its device wrench is half, and the observer's energy step is half too: it
  // recorded the wrench the device got (the ramp used to scale after the observer).
  OperatorTick a(Config(), RigidTransform{}, ToolState{}),
      b(Config(), RigidTransform{}, ToolState{});
  std::int64_t now = 1000000;
  ArrivedModel wall = Wall(now);
  OperatorTickOutput out_a, out_b;
  double before_a = 0.0, before_b = 0.0;
  for (int k = 0; k < 300; ++k, now += 1000000) {
    OperatorTickInput in = Pressing(now);
    in.device.X_MH.translation.z += 2e-3 * std::sin(0.05 * k);  // pressing harder and softer
    in.device.V_MH_M.linear.z = 2e-3 * 0.05 * 1000.0 * std::cos(0.05 * k);
    in.arrived = k == 0 ? &wall : nullptr;
    before_a = a.passivity().observed_energy_j();
    before_b = b.passivity().observed_energy_j();
    out_a = a.Step(in);
    if (k == 299) in.output_gain = 0.5;
    out_b = b.Step(in);
  }
  ASSERT_GT(glm::length(out_a.F_device_W.force), 0.1);
  EXPECT_NEAR(out_b.F_device_W.force.z, 0.5 * out_a.F_device_W.force.z, 1e-12);
  EXPECT_NEAR(out_b.F_H_M.force.z, 0.5 * out_a.F_H_M.force.z, 1e-12);
  EXPECT_EQ(before_a, before_b);
  const double step_a = a.passivity().observed_energy_j() - before_a;
  const double step_b = b.passivity().observed_energy_j() - before_b;
  ASSERT_NE(step_a, 0.0);
  EXPECT_NEAR(step_b, 0.5 * step_a, 1e-12 + 1e-9 * std::abs(step_a));
  // Gain 0 (and NaN, treated as 0): nothing reaches the device.
  OperatorTickInput in = Pressing(now);
  in.output_gain = std::nan("");
  EXPECT_EQ(b.Step(in).F_device_W.force, glm::dvec3(0.0));
}

TEST(OperatorTick, NonFiniteDeviceReadingsGiveZeroWrench) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  OperatorTickInput in;
  in.now_ns = 1000000;
  in.device.X_MH.translation = {std::nan(""), 0, 0};
  const OperatorTickOutput out = tick.Step(in);
  EXPECT_TRUE(IsFinite(out.F_device_W));
  EXPECT_EQ(glm::length(out.F_device_W.force), 0.0);
  EXPECT_GE(tick.counters().nonfinite, 1);
  EXPECT_TRUE(IsFiniteRigidTransform(tick.tool().X_WT));
}

TEST(OperatorTick, ATickNeverAllocates) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  ArrivedModel wall = Wall(0);
  OperatorTickInput in = Pressing(0);
  OperatorTickInput fault;
  fault.device_ok = false;
  tick.Step(in);  // warm-up
  const long before = Allocations();
  for (int k = 0; k < 5000; ++k) {
    in.now_ns = fault.now_ns = (k + 1) * 1000000LL;
    in.arrived = k % 3 == 0 ? &wall : nullptr;
    in.workspace_shift_M = k == 2500 ? glm::dvec3(0.01, 0, 0) : in.workspace_shift_M;
    tick.Step(k % 97 == 0 ? fault : in);
  }
  EXPECT_EQ(Allocations() - before, 0);
}

// Issue 33's attribution: the energy a model switch puts into the loop is the contact potential
// the new model has at the tool's pose less the old one's there (two routes: the counters and
// EvaluateContactModel at the pose the tool had before the switching tick). The same model again
// creates nothing; a shallower one takes energy out.
TEST(OperatorTick, AModelSwitchCreatesTheChangeInContactPotentialAtTheToolsPose) {
  OperatorTickConfig c = Config();
  c.model_blend_ticks = 1;  // the whole switch on one tick
  OperatorTick tick(c, RigidTransform{}, ToolState{});
  OperatorTickInput in = Pressing(1000000);
  for (int k = 0; k < 300; ++k) tick.Step(in);  // the tool at −10 mm: 12 mm deep in the wall
  const double max_force = std::numeric_limits<double>::infinity();
  ArrivedModel wall = Wall(in.now_ns);
  const RigidTransform X_before = tick.tool().X_WT;
  const double U_wall =
      EvaluateContactModel(wall.model, X_before, 1.0, max_force).potential_energy_j;
  ASSERT_GT(U_wall, 0.0);
  in.arrived = &wall;
  tick.Step(in);
  EXPECT_NEAR(tick.counters().switch_energy_created_j, U_wall, 1e-12 * U_wall);
  EXPECT_EQ(tick.counters().switch_ticks_creating, 1);
  in.arrived = nullptr;
  for (int k = 0; k < 50; ++k) tick.Step(in);
  // The same model again: no change in potential wherever the tool is.
  in.arrived = &wall;
  tick.Step(in);
  EXPECT_NEAR(tick.counters().switch_energy_created_j, U_wall, 1e-12 * U_wall);
  EXPECT_NEAR(tick.counters().switch_energy_absorbed_j, 0.0, 1e-15);
  // A shallower wall at the same tool pose: its potential less the wall's, taken out.
  ArrivedModel shallow = wall;
  shallow.model.contacts[0].depth_m = 1e-3;
  const RigidTransform X_now = tick.tool().X_WT;
  const double dU = EvaluateContactModel(shallow.model, X_now, 1.0, max_force).potential_energy_j -
                    EvaluateContactModel(wall.model, X_now, 1.0, max_force).potential_energy_j;
  ASSERT_LT(dU, 0.0);
  in.arrived = &shallow;
  tick.Step(in);
  EXPECT_NEAR(tick.counters().switch_energy_absorbed_j, dU, 1e-9 * std::abs(dU));
  EXPECT_EQ(tick.counters().switch_ticks, 3);
}

// The station's default energy reserve, through the tick: a handle swaying 1 mm into a wall
// whose models alternate between two depths (each switch puts energy in or takes it out). E stays
// non-negative and out ≤ in as without the reserve; the refill acts and is counted apart from the
// damping that keeps E ≥ 0; the tick still makes no allocation.
TEST(OperatorTick, TheEnergyReserveKeepsEnergyNonNegativeAndCountsItsRefillApart) {
  for (const double reserve_j : {0.0, 1e-4}) {
    OperatorTickConfig c = Config();
    c.passivity_reserve_j = reserve_j;
    c.passivity_refill_fraction = 0.05;
    OperatorTick tick(c, RigidTransform{}, ToolState{});
    ArrivedModel walls[2] = {Wall(0), Wall(0)};
    walls[1].model.contacts[0].depth_m = 2.1e-3;
    double min_energy = 0.0;
    std::int64_t allocations = 0;
    for (int k = 0; k < 2000; ++k) {
      const double t = k * kH, w = 2.0 * std::numbers::pi * 2.0;
      OperatorTickInput in = Pressing(static_cast<std::int64_t>(k) * 1000000 + 1000000);
      in.device.X_MH.translation.z = -10e-3 + 1e-3 * std::sin(w * t);
      in.device.V_MH_M.linear.z = 1e-3 * w * std::cos(w * t);
      ArrivedModel& wall = walls[(k / 7) % 2];
      wall.tool_state_sent_ns = wall.built_local_ns = in.now_ns;
      if (k % 7 == 0) in.arrived = &wall;
      const std::int64_t before = Allocations();
      tick.Step(in);
      allocations += Allocations() - before;
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
    }
    const PassivityController& p = tick.passivity();
    EXPECT_GE(min_energy, -1e-12) << reserve_j;
    EXPECT_LE(p.energy_out_j(), p.energy_in_j() + 1e-12) << reserve_j;
    EXPECT_EQ(allocations, 0) << reserve_j;
    EXPECT_DOUBLE_EQ(p.energy_reserve_j(), reserve_j);
    if (reserve_j > 0.0) {
      EXPECT_GT(p.refill_ticks(), 0);
      EXPECT_GT(p.refilled_j(), 0.0);
    } else {
      EXPECT_EQ(p.refill_ticks(), 0);
      EXPECT_EQ(p.refilled_j(), 0.0);
    }
  }
}

// Issue 33's energy-paced switch, on the swaying press of the test above (models alternating
// between two depths every 7 ticks, so that every other switch puts energy into the loop): the
// blend steps that would create more than the loop has dissipated are held short, and the
// passivity controller has less to remove (its damping and the guard's cut, energy and force),
// with E ≥ 0, out ≤ in and no allocation either way.
TEST(OperatorTick, AnEnergyPacedSwitchLeavesThePassivityControllerLessToRemove) {
  double removed_j[2] = {0.0, 0.0}, removed_ns[2] = {0.0, 0.0};
  for (const bool paced : {false, true}) {
    OperatorTickConfig c = Config();
    c.energy_paced_switch = paced;
    OperatorTick tick(c, RigidTransform{}, ToolState{});
    ArrivedModel walls[2] = {Wall(0), Wall(0)};
    walls[1].model.contacts[0].depth_m = 2.3e-3;
    double min_energy = 0.0;
    std::int64_t allocations = 0;
    for (int k = 0; k < 3000; ++k) {
      const double t = k * kH, w = 2.0 * std::numbers::pi * 2.0;
      OperatorTickInput in = Pressing(static_cast<std::int64_t>(k) * 1000000 + 1000000);
      in.device.X_MH.translation.z = -10e-3 + 1e-3 * std::sin(w * t);
      in.device.V_MH_M.linear.z = 1e-3 * w * std::cos(w * t);
      ArrivedModel& wall = walls[(k / 7) % 2];
      wall.tool_state_sent_ns = wall.built_local_ns = in.now_ns;
      if (k % 7 == 0) in.arrived = &wall;
      const std::int64_t before = Allocations();
      tick.Step(in);
      allocations += Allocations() - before;
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
    }
    const PassivityController& p = tick.passivity();
    EXPECT_GE(min_energy, -1e-12) << paced;
    EXPECT_LE(p.energy_out_j(), p.energy_in_j() + 1e-12) << paced;
    EXPECT_EQ(allocations, 0) << paced;
    removed_j[paced] = p.dissipated_j() + p.scaled_away_j();
    removed_ns[paced] = p.force_damped_away_ns() + p.force_scaled_away_ns();
    if (paced) {
      EXPECT_GT(tick.counters().paced_ticks, 0);
    } else {
      EXPECT_EQ(tick.counters().paced_ticks, 0);
    }
  }
  ASSERT_GT(removed_j[0], 0.0) << "the plain switch should leave the controller work";
  EXPECT_LT(removed_j[1], 0.5 * removed_j[0]);
  EXPECT_LT(removed_ns[1], removed_ns[0]);
}

// The hold is bounded. The handle is lowered onto a wall from above (the wall taken in free
// space creates nothing, so nothing is paced), and the press settles: the coupling's damping has
// dissipated some energy, the loop's margin. A wall 8 mm deeper is then far beyond it: its blend
// goes only as far as the margin allows and is held short for energy_paced_max_hold_ticks
// ticks. A model arriving meanwhile replaces the pair's deeper model: the collapse takes energy
// out and creates none. The deep wall again, held from the start, goes on at the plain rate once
// the hold runs out, and model_blend_ticks later it is wholly in use (the contact wrench the step
// used is the new model's alone at the tool's pose; two routes: the step and
// EvaluateContactModel).
TEST(OperatorTick, AnEnergyPacedSwitchIsHeldNoLongerThanItsBound) {
  OperatorTickConfig c = Config();
  c.energy_paced_switch = true;
  c.energy_paced_max_hold_ticks = 10;
  c.passivity_reserve_j = 0.0;
  ToolState start;
  start.X_WT.translation = {0, 0, 5e-3};  // 3 mm above the wall's surface (z = 2 mm)
  OperatorTick tick(c, RigidTransform{}, start);
  std::int64_t now = 0;
  ArrivedModel wall = Wall(now);
  OperatorTickInput in = Pressing(now);
  // Lowered from +5 to −4 mm over 0.5 s, then held: about 5 N, within the device's force cap
  // (a clamped force would do less work at the port than the coupling stores).
  for (int k = 0; k < 800; ++k) {
    in.now_ns = now += 1000000;
    const double s = std::min(1.0, k / 500.0);
    in.device.X_MH.translation.z = 5e-3 - 9e-3 * s;
    in.device.V_MH_M.linear.z = k < 500 ? -9e-3 / 0.5 : 0.0;
    wall.tool_state_sent_ns = wall.built_local_ns = now;  // fresh: the safety stage fades a
    in.arrived = k % 100 == 0 ? &wall : nullptr;          // model older than its timeout
    tick.Step(in);
  }
  in.arrived = nullptr;
  EXPECT_EQ(tick.counters().paced_ticks, 0) << "a wall taken in free space creates nothing";
  ArrivedModel deep = Wall(now);
  deep.model.contacts[0].depth_m = 10e-3;
  const double energy_j = tick.passivity().observed_energy_j();  // E ≥ E − S, the margin
  ASSERT_GT(energy_j, 0.0);
  const double dU = EvaluateContactModel(deep.model, tick.tool().X_WT).potential_energy_j -
                    EvaluateContactModel(wall.model, tick.tool().X_WT).potential_energy_j;
  ASSERT_GT(dU, 4.0 * energy_j) << "the deep wall should be far beyond the margin";
  in.arrived = &deep;
  for (int k = 0; k < 10; ++k) {
    in.now_ns = now += 1000000;
    tick.Step(in);
    in.arrived = nullptr;
  }
  EXPECT_EQ(tick.counters().paced_ticks, 10);
  EXPECT_EQ(tick.counters().paced_hold_expired_ticks, 0);
  EXPECT_LT(tick.counters().switch_energy_created_j, energy_j) << "at most the margin";
  EXPECT_GT(tick.counters().switch_energy_created_j, 0.0) << "the margin was used";
  // Mid-blend, the first wall again: the pair collapses onto its shallower (older) model.
  const double created = tick.counters().switch_energy_created_j;
  const double absorbed = tick.counters().switch_energy_absorbed_j;
  in.arrived = &wall;
  in.now_ns = now += 1000000;
  tick.Step(in);
  EXPECT_EQ(tick.counters().paced_collapses_to_older, 1);
  EXPECT_EQ(tick.counters().switch_energy_created_j, created);
  EXPECT_LT(tick.counters().switch_energy_absorbed_j, absorbed);
  for (int k = 0; k < 4; ++k) {  // the same wall blends in at the plain rate: U does not change
    in.now_ns = now += 1000000;
    tick.Step(in);
    in.arrived = nullptr;
  }
  EXPECT_EQ(tick.counters().paced_ticks, 10);
  // The deep wall again, held from the start: 10 ticks short, then the plain rate.
  in.arrived = &deep;
  for (int k = 0; k < 10 + c.model_blend_ticks - 1; ++k) {
    in.now_ns = now += 1000000;
    tick.Step(in);
    in.arrived = nullptr;
  }
  EXPECT_EQ(tick.counters().paced_ticks, 20);
  EXPECT_GE(tick.counters().paced_hold_expired_ticks, 1);
  in.now_ns = now += 1000000;
  const RigidTransform X_before = tick.tool().X_WT;
  const OperatorTickOutput out = tick.Step(in);
  const Wrench expected =
      EvaluateContactModel(deep.model, X_before, 1.0, c.max_contact_force_n).F_T_W;
  EXPECT_NEAR(out.step.F_contact_T_W.force.z, expected.force.z, 1e-9 * std::abs(expected.force.z));
}

// The energy-paced switch's ledger, where it has a known value. In free space, with the tool
// starting on the handle, the loop's margin (the energy put in through the coupling less what the
// loop stores) is what the coupling's damping and the implicit step have dissipated: never below
// zero, growing while the hand sways. With the tool pressed still on a wall, a switch to a deeper
// wall in one tick takes the change in contact potential at the tool's pose from it (two routes:
// the margin before and after, and EvaluateContactModel).
TEST(OperatorTick, TheLoopsMarginIsWhatItDissipatedAndASwitchTakesItsEnergyFromIt) {
  {
    ToolState start;
    start.X_WT.translation = {0.0, 0.0, 23e-3};  // on the handle's first pose
    OperatorTick tick(Config(), RigidTransform{}, start);
    double min_margin = 0.0;
    for (int k = 0; k < 3000; ++k) {
      const double t = k * kH, w = 2.0 * std::numbers::pi * 1.5;
      OperatorTickInput in = Pressing(static_cast<std::int64_t>(k + 1) * 1000000);
      in.device.X_MH.translation = {0.02 * std::sin(w * t), 0.0, 20e-3 + 3e-3 * std::cos(w * t)};
      in.device.V_MH_M.linear = {0.02 * w * std::cos(w * t), 0.0, -3e-3 * w * std::sin(w * t)};
      tick.Step(in);
      min_margin = std::min(min_margin, tick.loop_margin_j());
    }
    EXPECT_GE(min_margin, -1e-12);
    EXPECT_GT(tick.loop_margin_j(), 1e-4);
  }
  OperatorTickConfig c = Config();
  c.model_blend_ticks = 1;
  OperatorTick tick(c, RigidTransform{}, ToolState{});
  std::int64_t now = 0;
  ArrivedModel wall = Wall(now);
  OperatorTickInput in = Pressing(now);
  in.device.X_MH.translation.z = -4e-3;
  for (int k = 0; k < 1000; ++k) {  // settle (about 5 N)
    in.now_ns = now += 1000000;
    wall.tool_state_sent_ns = wall.built_local_ns = now;
    in.arrived = k % 100 == 0 ? &wall : nullptr;
    tick.Step(in);
  }
  ArrivedModel deeper = Wall(now);
  deeper.model.contacts[0].depth_m = 2.2e-3;
  const double dU = EvaluateContactModel(deeper.model, tick.tool().X_WT).potential_energy_j -
                    EvaluateContactModel(wall.model, tick.tool().X_WT).potential_energy_j;
  ASSERT_GT(dU, 0.0);
  const double before = tick.loop_margin_j();
  in.arrived = &deeper;
  in.now_ns = now += 1000000;
  tick.Step(in);
  EXPECT_NEAR(tick.loop_margin_j() - before, -dU, 0.05 * dU);
}

}  // namespace
}  // namespace ht
