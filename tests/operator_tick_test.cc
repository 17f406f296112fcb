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
    last = glm::length(tick.Step(in).F_H_W.force);
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
    const double f = glm::length(tick.Step(fault).F_H_W.force);
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
    const double f = glm::length(tick.Step(in).F_H_W.force);
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
  EXPECT_NEAR(glm::length(out.F_H_W.force), 0.0, 1e-6);
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
  EXPECT_TRUE(tick.ShiftWorkspace({0.5, 0, 0}));   // go 50 cm along x
  EXPECT_FALSE(tick.ShiftWorkspace({0.5, 0, 0}));  // already there
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
  tick.ShiftWorkspace({0.5, 0, 0});          // the driver's jump, before the tick
  in.arrived = &old_place;
  tick.Step(in);
  EXPECT_EQ(tick.counters().workspace_jumps, 1);
  EXPECT_EQ(tick.counters().models_from_before_jump, 1);
  EXPECT_EQ(tick.counters().models_used, 0);
  // A model of the new place arriving on a later jump's tick is taken.
  ArrivedModel new_place = Wall(in.now_ns);
  new_place.model.X_WT0.translation = {0.6, 0, 0};
  tick.ShiftWorkspace({0.6, 0, 0});
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
  ASSERT_GT(glm::length(out_a.F_H_W.force), 0.1);
  EXPECT_NEAR(out_b.F_H_W.force.z, 0.5 * out_a.F_H_W.force.z, 1e-12);
  EXPECT_NEAR(out_b.F_H_M.force.z, 0.5 * out_a.F_H_M.force.z, 1e-12);
  EXPECT_EQ(before_a, before_b);
  const double step_a = a.passivity().observed_energy_j() - before_a;
  const double step_b = b.passivity().observed_energy_j() - before_b;
  ASSERT_NE(step_a, 0.0);
  EXPECT_NEAR(step_b, 0.5 * step_a, 1e-12 + 1e-9 * std::abs(step_a));
  // Gain 0 (and NaN, treated as 0): nothing reaches the device.
  OperatorTickInput in = Pressing(now);
  in.output_gain = std::nan("");
  EXPECT_EQ(b.Step(in).F_H_W.force, glm::dvec3(0.0));
}

TEST(OperatorTick, NonFiniteDeviceReadingsGiveZeroWrench) {
  OperatorTick tick(Config(), RigidTransform{}, ToolState{});
  OperatorTickInput in;
  in.now_ns = 1000000;
  in.device.X_MH.translation = {std::nan(""), 0, 0};
  const OperatorTickOutput out = tick.Step(in);
  EXPECT_TRUE(IsFinite(out.F_H_W));
  EXPECT_EQ(glm::length(out.F_H_W.force), 0.0);
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
    if (k == 2500) tick.ShiftWorkspace({0.01, 0, 0});
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
// damping that keeps E ≥ 0; the tick still makes no allocation. The force each tick reports the
// stage took (trace.csv's passivity_removed_n) sums to what the controller counted.
TEST(OperatorTick, TheEnergyReserveKeepsEnergyNonNegativeAndCountsItsRefillApart) {
  for (const double reserve_j : {0.0, 1e-4}) {
    OperatorTickConfig c = Config();
    c.passivity_reserve_j = reserve_j;
    c.passivity_refill_fraction = 0.05;
    OperatorTick tick(c, RigidTransform{}, ToolState{});
    ArrivedModel walls[2] = {Wall(0), Wall(0)};
    walls[1].model.contacts[0].depth_m = 2.1e-3;
    double min_energy = 0.0, removed_ns = 0.0;
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
      const OperatorTickOutput out = tick.Step(in);
      allocations += Allocations() - before;
      EXPECT_GE(out.passivity_removed_n, 0.0);
      removed_ns += out.passivity_removed_n * kH;
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
    }
    const PassivityController& p = tick.passivity();
    EXPECT_GE(min_energy, -1e-12) << reserve_j;
    EXPECT_LE(p.energy_out_j(), p.energy_in_j() + 1e-12) << reserve_j;
    EXPECT_EQ(allocations, 0) << reserve_j;
    EXPECT_DOUBLE_EQ(p.energy_reserve_j(), reserve_j);
    // The handle moves along z only: the damping's force is α·|v| along it, so the two sums of
    // the same forces agree to rounding.
    const double counted =
        p.force_damped_away_ns() + p.force_refilled_ns() + p.force_scaled_away_ns();
    EXPECT_GT(counted, 0.0) << reserve_j;
    EXPECT_NEAR(removed_ns, counted, 1e-9 * counted + 1e-15) << reserve_j;
    if (reserve_j > 0.0) {
      EXPECT_GT(p.refill_ticks(), 0);
      EXPECT_GT(p.refilled_j(), 0.0);
    } else {
      EXPECT_EQ(p.refill_ticks(), 0);
      EXPECT_EQ(p.refilled_j(), 0.0);
    }
  }
}

// The energy-bounded switch (OperatorTickConfig::energy_bounded_switch), against the switch test
// above: the same wall arriving with the tool 12 mm deep and the observer holding no energy (the
// handle has not moved) creates no contact potential at all; the model is rendered with an offset
// that puts its surface at the tool (no contact force on that tick), and the offset comes back
// only as the handle's work pays for it, or within switch_offset_release_ms whatever the budget.
// Every tick keeps E ≥ 0 and makes no allocation.
TEST(OperatorTick, AnEnergyBoundedSwitchCreatesNoMoreThanTheObserverHoldsSpare) {
  for (const double release_ms : {std::numeric_limits<double>::infinity(), 50.0}) {
    OperatorTickConfig c = Config();
    c.model_blend_ticks = 1;
    c.energy_bounded_switch = true;
    c.switch_energy_spend_fraction = 1.0;
    c.switch_offset_release_ms = release_ms;
    OperatorTick tick(c, RigidTransform{}, ToolState{});
    OperatorTickInput in = Pressing(1000000);
    for (int k = 0; k < 300; ++k) tick.Step(in);  // the tool at −10 mm, the handle still: E = 0
    ASSERT_EQ(tick.passivity().observed_energy_j(), 0.0);
    ArrivedModel wall = Wall(in.now_ns - 150000000);  // answering a pose 150 ms old
    const double U_wall = EvaluateContactModel(wall.model, tick.tool().X_WT).potential_energy_j;
    ASSERT_GT(U_wall, 0.0);
    in.arrived = &wall;
    const OperatorTickOutput first = tick.Step(in);
    in.arrived = nullptr;
    EXPECT_LE(tick.counters().switch_energy_created_j, 1e-12 * U_wall) << release_ms;
    // The offset is the wall's depth at the tool (12 mm), to the bisection's resolution.
    EXPECT_NEAR(first.depth_offset_m, 12e-3, 5e-6) << release_ms;
    EXPECT_LT(glm::length(first.step.F_contact_T_W.force), 8000.0 * 12e-3 / 16384.0 * 2.0);
    // The next model (the same wall, as old) carries the offset on: no new onset, no jump.
    in.now_ns += 1000000;
    ArrivedModel again = Wall(in.now_ns - 150000000);
    in.arrived = &again;
    const OperatorTickOutput second = tick.Step(in);
    in.arrived = nullptr;
    EXPECT_GT(second.depth_offset_m, 0.9 * first.depth_offset_m) << release_ms;
    EXPECT_LE(second.depth_offset_m, first.depth_offset_m + 1e-15) << release_ms;
    EXPECT_LE(tick.counters().switch_energy_created_j, 1e-3 * U_wall) << release_ms;
    // The handle held still: without a release time the offset stays (nothing pays for it); with
    // one it is gone within that time.
    double offset = second.depth_offset_m, min_energy = 0.0;
    std::int64_t allocations = 0;
    for (int k = 0; k < 59; ++k) {
      in.now_ns += 1000000;
      const std::int64_t before = Allocations();
      const OperatorTickOutput out = tick.Step(in);
      allocations += Allocations() - before;
      EXPECT_LE(out.depth_offset_m, offset + 1e-15) << "tick " << k;  // it only comes back
      offset = out.depth_offset_m;
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
    }
    if (std::isinf(release_ms)) {
      EXPECT_NEAR(offset, first.depth_offset_m, 1e-4) << "nothing paid for its return";
    } else {
      EXPECT_EQ(offset, 0.0) << "50 ms after the switch";
    }
    // The handle pressing further in (−z at 20 mm/s): its work pays for the offset's return.
    for (int k = 0; k < 400; ++k) {
      in.now_ns += 1000000;
      in.device.X_MH.translation.z -= 20e-3 * kH;
      in.device.V_MH_M.linear.z = -20e-3;
      const std::int64_t before = Allocations();
      const OperatorTickOutput out = tick.Step(in);
      allocations += Allocations() - before;
      offset = out.depth_offset_m;
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
    }
    EXPECT_LT(offset, 0.5 * first.depth_offset_m) << release_ms;
    EXPECT_GE(min_energy, -1e-12) << release_ms;
    EXPECT_EQ(allocations, 0) << release_ms;
  }
  // A young model (answering a pose under switch_bound_min_age_ms old) is not bounded: the
  // switch creates the wall's whole potential, as without the option.
  OperatorTickConfig c = Config();
  c.model_blend_ticks = 1;
  c.energy_bounded_switch = true;
  OperatorTick tick(c, RigidTransform{}, ToolState{});
  OperatorTickInput in = Pressing(1000000);
  for (int k = 0; k < 300; ++k) tick.Step(in);
  ArrivedModel wall = Wall(in.now_ns - 2000000);  // 2 ms old
  const double U_wall = EvaluateContactModel(wall.model, tick.tool().X_WT).potential_energy_j;
  in.arrived = &wall;
  EXPECT_EQ(tick.Step(in).depth_offset_m, 0.0);
  EXPECT_NEAR(tick.counters().switch_energy_created_j, U_wall, 1e-12 * U_wall);
}

// The passivity stage's release (OperatorTickConfig::passivity_release_ticks): a handle resting
// 10 mm deep in the wall (E = 0: it has not moved) jerks up for one tick, so the guard cuts the
// device's force to nothing; when it stands still again the force used to come back whole on the
// next tick, and comes back over the release's ticks with it.
TEST(OperatorTick, ThePassivityReleaseBringsACutForceBackOverItsTicks) {
  for (const int release_ticks : {0, 10}) {
    OperatorTickConfig c = Config();
    c.passivity_release_ticks = release_ticks;
    OperatorTick tick(c, RigidTransform{}, ToolState{});
    ArrivedModel wall = Wall(1000000);
    OperatorTickInput in = Pressing(1000000);
    in.arrived = &wall;
    double resting = 0.0;
    for (int k = 0; k < 500; ++k) {
      in.now_ns += 1000000;
      wall.tool_state_sent_ns = wall.built_local_ns = in.now_ns;
      resting = glm::length(tick.Step(in).F_H_W.force);
      in.arrived = k % 2 ? &wall : nullptr;
    }
    ASSERT_GT(resting, 1.0);
    in.arrived = nullptr;
    in.now_ns += 1000000;
    in.device.V_MH_M.linear.z = 0.05;  // up, along the force: power to the hand that E lacks
    const double cut = glm::length(tick.Step(in).F_H_W.force);
    EXPECT_LT(cut, 0.05 * resting) << release_ticks;
    in.device.V_MH_M.linear.z = 0.0;
    double previous = cut, min_energy = tick.passivity().observed_energy_j();
    for (int k = 0; k < 30; ++k) {
      in.now_ns += 1000000;
      const double f = glm::length(tick.Step(in).F_H_W.force);
      min_energy = std::min(min_energy, tick.passivity().observed_energy_j());
      if (release_ticks == 0 && k == 0) {
        EXPECT_GT(f, 0.9 * resting) << "without the release the force is back at once";
      }
      if (release_ticks > 0) {
        EXPECT_LE(f - previous, resting / release_ticks * 1.05 + 1e-9) << "tick " << k;
      }
      previous = f;
    }
    EXPECT_GT(previous, 0.9 * resting) << release_ticks;  // back in the end
    EXPECT_GE(min_energy, -1e-12) << release_ticks;
  }
}

}  // namespace
}  // namespace ht
