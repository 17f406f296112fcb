// The perceptual deadband (transport/deadband.h), its negotiation (transport/session.h) and the
// Reject an operator of another protocol version gets (issue 18).
#include "transport/deadband.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>

#include "legacy_datagram.h"
#include "transport/messages.h"
#include "transport/session.h"

namespace ht {
namespace {

constexpr std::int64_t kMs = 1000000;

TEST(Deadband, ExtrapolatePoseMovesAtTheTwist) {
  RigidTransform X;
  X.translation = {0.1, 0.2, 0.3};
  const Twist V{{0.01, 0.0, -0.02}, {0.0, 0.0, 0.5}};
  const RigidTransform Y = ExtrapolatePose(X, V, 0.2);
  EXPECT_NEAR(Y.translation.x, 0.102, 1e-12);
  EXPECT_NEAR(Y.translation.z, 0.296, 1e-12);
  // 0.1 rad about +z, about T's own origin.
  const glm::dvec3 theta = RotationVectorFromQuaternion(Y.rotation);
  EXPECT_NEAR(theta.z, 0.1, 1e-12);
  EXPECT_NEAR(glm::length(glm::dvec2(theta.x, theta.y)), 0.0, 1e-12);
  const RigidTransform Z = ExtrapolatePose(X, V, -1.0);
  EXPECT_EQ(Z.translation, X.translation);
}

TEST(Deadband, OffSendsEveryToolState) {
  ToolStateDeadband d({});
  RigidTransform X;
  for (int i = 0; i < 50; ++i) {
    EXPECT_EQ(d.Decide(X, {}, i * kMs), DeadbandReason::kOff);
  }
}

TEST(Deadband, ConstantVelocityIsPredictedSoOnlyKeepAlivesGo) {
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.05;
  c.keepalive_s = 0.1;
  ToolStateDeadband d(c);
  const Twist V{{0.03, -0.01, 0.0}, {0.0, 0.2, 0.0}};
  RigidTransform X0;
  int sent = 0, keepalive = 0;
  for (int i = 0; i <= 1000; ++i) {  // one second at 1 kHz
    const RigidTransform X = ExtrapolatePose(X0, V, i * 1e-3);
    const DeadbandReason r = d.Decide(X, V, i * kMs);
    if (r != DeadbandReason::kNotSent) ++sent;
    if (r == DeadbandReason::kKeepAlive) ++keepalive;
  }
  EXPECT_EQ(keepalive, 10);
  EXPECT_EQ(sent, 11);  // the first, then one per keep-alive
}

TEST(Deadband, ToolStateThresholdsAreWeberFractionsWithFloors) {
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  c.velocity_criterion = true;
  {
    ToolStateDeadband d(c);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0), DeadbandReason::kFirst);
    // At rest the position floor is k·2 mm = 0.2 mm.
    X.translation.x = 0.15e-3;
    EXPECT_EQ(d.Decide(X, {}, kMs), DeadbandReason::kNotSent);
    X.translation.x = 0.25e-3;
    EXPECT_EQ(d.Decide(X, {}, 2 * kMs), DeadbandReason::kPosition);
  }
  {
    ToolStateDeadband d(c);
    RigidTransform X;
    const Twist V{{0.1, 0.0, 0.0}, {}};
    ASSERT_EQ(d.Decide(X, V, 0), DeadbandReason::kFirst);
    // Velocity: threshold max(k·|v_s|, k·0.02 m/s) = 0.01 m/s.
    EXPECT_EQ(d.Decide(ExtrapolatePose(X, V, 1e-3), {{0.108, 0.0, 0.0}, {}}, kMs),
              DeadbandReason::kNotSent);
    EXPECT_EQ(d.Decide(ExtrapolatePose(X, V, 2e-3), {{0.112, 0.0, 0.0}, {}}, 2 * kMs),
              DeadbandReason::kVelocity);
    // Without the velocity criterion the changed twist is not sent by itself; the pose error
    // it causes is, once it passes the floor (0.2 mm): 12 mm/s more for 20 ms = 0.24 mm.
    ToolStateDeadbandConfig pose_only = c;
    pose_only.velocity_criterion = false;
    ToolStateDeadband e(pose_only);
    ASSERT_EQ(e.Decide(X, V, 0), DeadbandReason::kFirst);
    const Twist faster{{0.112, 0.0, 0.0}, {}};
    EXPECT_EQ(e.Decide(ExtrapolatePose(X, faster, 2e-3), faster, 2 * kMs),
              DeadbandReason::kNotSent);
    EXPECT_EQ(e.Decide(ExtrapolatePose(X, faster, 21e-3), faster, 21 * kMs),
              DeadbandReason::kPosition);
  }
  {
    ToolStateDeadband d(c);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0), DeadbandReason::kFirst);
    // Rotation floor k·0.02 rad = 2 mrad.
    X.rotation = QuaternionFromRotationVector({0.0, 0.0, 1.5e-3});
    EXPECT_EQ(d.Decide(X, {}, kMs), DeadbandReason::kNotSent);
    X.rotation = QuaternionFromRotationVector({0.0, 0.0, 2.5e-3});
    EXPECT_EQ(d.Decide(X, {}, 2 * kMs), DeadbandReason::kRotation);
  }
  {
    // A larger deadband lets more through unsent: the same wobble, fewer packets.
    auto count = [&](double k) {
      ToolStateDeadbandConfig ck = c;
      ck.weber_fraction = k;
      ToolStateDeadband d(ck);
      int sent = 0;
      for (int i = 0; i < 2000; ++i) {
        const double t = i * 1e-3;
        RigidTransform X;
        X.translation = {0.02 * std::sin(2.0 * std::numbers::pi * 1.3 * t), 0.0,
                         0.005 * std::sin(2.0 * std::numbers::pi * 0.7 * t)};
        const Twist V{
            {0.02 * 2.0 * std::numbers::pi * 1.3 * std::cos(2.0 * std::numbers::pi * 1.3 * t), 0.0,
             0.005 * 2.0 * std::numbers::pi * 0.7 * std::cos(2.0 * std::numbers::pi * 0.7 * t)},
            {}};
        if (d.Decide(X, V, i * kMs) != DeadbandReason::kNotSent) ++sent;
      }
      return sent;
    };
    const int s5 = count(0.05), s10 = count(0.10), s20 = count(0.20);
    EXPECT_LT(s5, 2000 / 2);
    EXPECT_LE(s10, s5);
    EXPECT_LE(s20, s10);
    EXPECT_LT(s20, s5);
  }
}

TEST(Deadband, VelocityAdaptiveWidensThePositionFloorWhileMovingFast) {
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  const Twist V{{0.1, 0.0, 0.0}, {}};  // 0.1 m/s: floors × (1 + 0.1/0.05) = ×3
  RigidTransform X;
  RigidTransform off = ExtrapolatePose(X, V, 1e-3);
  off.translation.y += 0.4e-3;  // 0.4 mm off the prediction: above 0.2 mm, below 0.6 mm
  ToolStateDeadband plain(c);
  ASSERT_EQ(plain.Decide(X, V, 0), DeadbandReason::kFirst);
  EXPECT_EQ(plain.Decide(off, V, kMs), DeadbandReason::kPosition);
  c.velocity_adaptive = true;
  ToolStateDeadband adaptive(c);
  ASSERT_EQ(adaptive.Decide(X, V, 0), DeadbandReason::kFirst);
  EXPECT_EQ(adaptive.Decide(off, V, kMs), DeadbandReason::kNotSent);
}

TEST(Deadband, NearContactTheFloorsShrinkToTheContactScale) {
  // A tool resting on a surface that bobs by 0.1 mm and tilts by 1 mrad (the fig75 block's
  // bounce, issue 32) stays inside the free-space floors (0.2 mm, 2 mrad at k = 0.1): the remote
  // node would keep modelling it where it is not. Near contact the position floor is 20 µm; the
  // rotation floor is the free-space one unless asked (here 0.2 mrad).
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  c.contact_floor_hold_s = 0.0;  // the floors alone (the hold: the next test)
  EXPECT_DOUBLE_EQ(c.contact_rotation_floor_scale_rad, c.rotation_floor_scale_rad);
  c.contact_rotation_floor_scale_rad = 2e-3;
  // The largest distance between the tool and the pose the remote node predicts from the states
  // sent (ExtrapolatePose of the last one), over 0.2 s of a 48 Hz, 0.1 mm bob.
  auto worst_prediction_error_of_bob = [&](bool near_contact) {
    ToolStateDeadband d(c);
    RigidTransform X_sent;
    Twist V_sent;
    double t_sent = 0.0, worst = 0.0;
    for (int i = 0; i < 200; ++i) {
      const double t = i * 1e-3, w = 2.0 * std::numbers::pi * 48.0;
      RigidTransform X;
      X.translation.z = 0.1e-3 * std::sin(w * t);
      const Twist V{{0.0, 0.0, 0.1e-3 * w * std::cos(w * t)}, {}};
      if (d.Decide(X, V, i * kMs, near_contact) != DeadbandReason::kNotSent) {
        X_sent = X;
        V_sent = V;
        t_sent = t;
      }
      const RigidTransform predicted = ExtrapolatePose(X_sent, V_sent, t - t_sent);
      worst = std::max(worst, glm::length(X.translation - predicted.translation));
    }
    return worst;
  };
  EXPECT_GT(worst_prediction_error_of_bob(false), 0.15e-3);
  EXPECT_LE(worst_prediction_error_of_bob(true), 20e-6);
  {
    ToolStateDeadband d(c);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0, true), DeadbandReason::kFirst);
    X.translation.x = 15e-6;
    EXPECT_EQ(d.Decide(X, {}, kMs, true), DeadbandReason::kNotSent);
    EXPECT_EQ(d.Decide(X, {}, 2 * kMs, false), DeadbandReason::kNotSent);
    X.translation.x = 25e-6;
    EXPECT_EQ(d.Decide(X, {}, 3 * kMs, false), DeadbandReason::kNotSent);
    EXPECT_EQ(d.Decide(X, {}, 4 * kMs, true), DeadbandReason::kPosition);
  }
  {
    ToolStateDeadband d(c);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0, true), DeadbandReason::kFirst);
    X.rotation = QuaternionFromRotationVector({0.15e-3, 0.0, 0.0});
    EXPECT_EQ(d.Decide(X, {}, kMs, true), DeadbandReason::kNotSent);
    X.rotation = QuaternionFromRotationVector({0.25e-3, 0.0, 0.0});
    EXPECT_EQ(d.Decide(X, {}, 2 * kMs, false), DeadbandReason::kNotSent);
    EXPECT_EQ(d.Decide(X, {}, 3 * kMs, true), DeadbandReason::kRotation);
  }
  ToolStateDeadbandConfig bad = c;
  bad.contact_floor_hold_s = -0.1;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
  bad = c;
  bad.contact_position_floor_scale_m = 0.0;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
  bad = c;
  bad.contact_rotation_floor_scale_rad = std::nan("");
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
}

ContactModel OneContact(double depth_m, double stiffness, const glm::dvec3& p0) {
  ContactModel m;
  m.X_WT0.translation = p0;
  m.num_contacts = 1;
  ContactLinearization& c = m.contacts[0];
  c.depth_m = depth_m;
  c.gradient.d_translation_W = {0.0, 0.0, -1.0};  // moving up separates
  c.gradient.d_rotation_W = {0.01, 0.0, 0.0};
  c.stiffness_n_per_m = stiffness;
  c.normal_W = {0.0, 0.0, 1.0};
  m.F_T_W_at_q0 = PenaltyWrench(depth_m, c.gradient, stiffness);
  return m;
}

TEST(Deadband, TheContactFloorsOutlastABounceOffTheSurface) {
  // A block lands, bounces 60 µm off the gear (its model then has no contacts: near_contact
  // false) and falls back. With the free-space floor at once (0.2 mm at k = 0.1) nothing was sent
  // while it fell 0.2 mm into the gear, and the next model pushed 1.7 N (issue 32's third note).
  // Held for contact_floor_hold_s, the contact floor (20 µm) sends the fall at once.
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  ASSERT_DOUBLE_EQ(c.contact_floor_hold_s, 0.5);
  // The tool: in contact for 10 ms at rest, then free of contacts and falling at 20 mm/s (the
  // ExtrapolatePose of a resting state predicts it still); the drop when the first state goes out.
  auto drop_before_first_send = [&](double hold_s) {
    ToolStateDeadbandConfig config = c;
    config.contact_floor_hold_s = hold_s;
    ToolStateDeadband d(config);
    RigidTransform X;
    for (int i = 0; i <= 10; ++i) d.Decide(X, {}, i * kMs, true);
    for (int i = 1; i < 100; ++i) {
      X.translation.z = -0.02 * i * 1e-3;
      if (d.Decide(X, {{0.0, 0.0, -0.02}, {}}, (10 + i) * kMs, false) != DeadbandReason::kNotSent) {
        return -X.translation.z;
      }
    }
    return 1.0;
  };
  // Sent on the first tick past the 20 µm floor (one tick's fall is 20 µm).
  EXPECT_LE(drop_before_first_send(0.5), 40e-6 + 1e-9);
  EXPECT_GT(drop_before_first_send(0.0), 0.15e-3);
  // Past the hold the free-space floors are back: 0.1 mm is not sent 0.6 s after the contact.
  ToolStateDeadband d(c);
  RigidTransform X;
  ASSERT_EQ(d.Decide(X, {}, 0, true), DeadbandReason::kFirst);
  X.translation.z = 0.1e-3;
  EXPECT_EQ(d.Decide(X, {}, 600 * kMs, false), DeadbandReason::kNotSent);
  EXPECT_EQ(d.Decide(X, {}, 601 * kMs, true), DeadbandReason::kPosition);
}
// The operator evaluates a depth field only while a model it holds names it: a model naming a
// field the held one does not is sent whatever its force; one naming the held fields (or fewer)
// is judged by what it renders.
TEST(Deadband, AModelNamingANewDepthFieldIsSent) {
  ContactModelDeadbandConfig c;
  c.weber_fraction = 0.1;
  ContactModelDeadband d(c);
  ContactModel m0 = OneContact(1e-3, 2000.0, {0, 0, 0});
  m0.contacts[0].depth_field_id = 4;
  ASSERT_EQ(d.Decide(m0, 0), DeadbandReason::kFirst);
  ContactModel same = m0;
  EXPECT_EQ(d.Decide(same, kMs), DeadbandReason::kNotSent);
  ContactModel none = m0;
  none.contacts[0].depth_field_id = 0;  // the field left out: its linearization renders alike
  EXPECT_EQ(d.Decide(none, 2 * kMs), DeadbandReason::kNotSent);
  ContactModel next = m0;
  next.contacts[0].depth_field_id = 5;
  EXPECT_EQ(d.Decide(next, 3 * kMs), DeadbandReason::kDepthField);
  EXPECT_EQ(d.held().contacts[0].depth_field_id, 5u);
  EXPECT_EQ(d.counts()[static_cast<int>(DeadbandReason::kDepthField)], 1u);
  EXPECT_EQ(ToJson(d.counts())["depth_field"].get<int>(), 1);
}

// The remote node's deadband with its kept fields: two models whose contact names one field and
// whose linearizations are that field's tangents at their poses render alike wherever the
// operator holds the field, however much the tangents differ; judged by the linearizations
// alone, the second is sent.
TEST(Deadband, AModelWhoseFieldTheHeldOneNamesIsJudgedByTheField) {
  // A plate rippled along x (100 µm, 2 mm period) under a tool whose only node sits 30 µm into it
  // at a zero of the ripple.
  constexpr int n = 48;
  constexpr double h = 0.25e-3;
  DepthField f;
  f.id = 9;
  f.cell_m = h;
  f.nx = f.ny = n;
  f.travel_margin_m = 2e-3;
  f.X_WT0.translation = {24 * h, 24 * h, 5e-3};
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      f.env_height_m.push_back(
          static_cast<float>(100e-6 * std::sin(2.0 * std::numbers::pi * i * h / 2e-3)));
      f.tool_height_m.push_back(i == 24 && j == 24 ? -30e-6f : std::nanf(""));
    }
  }
  ASSERT_TRUE(f.Prepare());
  const std::array<const DepthField*, 1> kept{&f};
  // The field's model at the tool displaced by dx along x: its linearization the field's tangent.
  const auto model_at = [&](double dx) {
    ContactModel m;
    m.X_WT0 = f.X_WT0;
    m.X_WT0.translation.x += dx;
    const DepthFieldEvaluation e = DepthFieldDepthAt(f, m.X_WT0);
    EXPECT_TRUE(e.valid);
    m.num_contacts = 1;
    ContactLinearization& c = m.contacts[0];
    c.depth_m = e.depth_m;
    c.gradient = e.gradient;
    c.stiffness_n_per_m = 20000.0;
    c.depth_field_id = f.id;
    m.F_T_W_at_q0 = PenaltyWrench(c.depth_m, c.gradient, c.stiffness_n_per_m);
    return m;
  };
  ContactModelDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  ContactModelDeadband with_fields(c), alone(c);
  // A quarter period along the ripple: the depth's slope along x falls from 0.28 (the bicubic's
  // between 8 nodes a period) to 0, and the depth is 130 µm where m0's tangent says 170 µm.
  const ContactModel m0 = model_at(0.0), m1 = model_at(0.5e-3);
  ASSERT_GT(m0.contacts[0].gradient.d_translation_W.x, 0.25);
  ASSERT_NEAR(m1.contacts[0].gradient.d_translation_W.x, 0.0, 0.01);
  ASSERT_EQ(with_fields.Decide(m0, 0, kept), DeadbandReason::kFirst);
  ASSERT_EQ(alone.Decide(m0, 0), DeadbandReason::kFirst);
  EXPECT_EQ(with_fields.Decide(m1, kMs, kept), DeadbandReason::kNotSent);
  EXPECT_NE(alone.Decide(m1, kMs), DeadbandReason::kNotSent);
  // The field gone from the sender's pool (replaced): the held model is judged by its
  // linearization again.
  const std::array<const DepthField*, 1> none{nullptr};
  EXPECT_NE(with_fields.Decide(model_at(1e-3), 2 * kMs, none), DeadbandReason::kNotSent);
}

TEST(Deadband, ContactModelSentWhenTheHeldOneRendersDifferently) {
  ContactModelDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 0.1;
  ContactModelDeadband d(c);
  const ContactModel m0 = OneContact(1e-3, 2000.0, {0, 0, 0});  // 2 N
  ASSERT_EQ(d.Decide(m0, 0), DeadbandReason::kFirst);
  // The tool moved down 0.1 mm and the model says the depth grew as its gradient predicts: the
  // held model already renders that; nothing to send.
  ContactModel m1 = OneContact(1.1e-3, 2000.0, {0, 0, -1e-4});
  EXPECT_EQ(d.Decide(m1, kMs), DeadbandReason::kNotSent);
  // A bump of the texture the held model cannot know: 0.05 mm deeper than predicted is 0.1 N of
  // 2.3 N (4 %), inside 10 %; 0.3 mm deeper (0.6 N, 26 %) is sent.
  ContactModel m2 = OneContact(1.15e-3, 2000.0, {0, 0, -1e-4});
  EXPECT_EQ(d.Decide(m2, 2 * kMs), DeadbandReason::kNotSent);
  ContactModel m3 = OneContact(1.4e-3, 2000.0, {0, 0, -1e-4});
  EXPECT_EQ(d.Decide(m3, 3 * kMs), DeadbandReason::kForce);
  EXPECT_EQ(d.held().contacts[0].depth_m, 1.4e-3);
  // Stiffness doubled at the same force: the slope the operator feels changed.
  ContactModel m4 = OneContact(0.7e-3, 4000.0, {0, 0, -1e-4});
  EXPECT_EQ(d.Decide(m4, 4 * kMs), DeadbandReason::kStiffness);
  // A second contact appears (separated, so it renders nothing yet): sent.
  ContactModel m5 = m4;
  m5.num_contacts = 2;
  m5.contacts[1] = m5.contacts[0];
  m5.contacts[1].depth_m = -2e-3;
  EXPECT_EQ(d.Decide(m5, 5 * kMs), DeadbandReason::kContactCount);
  // Nothing changes: held until the keep-alive.
  EXPECT_EQ(d.Decide(m5, 50 * kMs), DeadbandReason::kNotSent);
  EXPECT_EQ(d.Decide(m5, 105 * kMs), DeadbandReason::kKeepAlive);
  EXPECT_EQ(d.counts()[static_cast<int>(DeadbandReason::kNotSent)], 3u);
}

TEST(Deadband, AModelHeldBackRendersWithinTheDeadbandOfTheNewOne) {
  // Property over a random walk of contact models: whenever a model is held back, the held
  // model evaluated where the operator is (the new q0) is within the Weber fraction (or the
  // floor) of the new model's own wrench, checked by evaluating both directly.
  std::mt19937 rng(11);
  std::normal_distribution<double> step(0.0, 2e-5);
  for (const double k : {0.05, 0.1, 0.2}) {
    ContactModelDeadbandConfig c;
    c.weber_fraction = k;
    c.keepalive_s = 1.0;
    ContactModelDeadband d(c);
    glm::dvec3 p{0.0};
    double bump = 0.0;
    int held = 0;
    for (int i = 0; i < 3000; ++i) {
      p += glm::dvec3(step(rng), step(rng), step(rng));
      bump += step(rng) * 0.5;
      const ContactModel m = OneContact(1e-3 - p.z + bump, 3000.0, p);
      if (d.Decide(m, i * kMs) != DeadbandReason::kNotSent) continue;
      ++held;
      const Wrench held_at_q0 = EvaluateContactModel(d.held(), m.X_WT0).F_T_W;
      const Wrench own = EvaluateContactModel(m, m.X_WT0).F_T_W;
      EXPECT_LE(glm::length(held_at_q0.force - own.force),
                std::max(k * glm::length(own.force), k * c.force_floor_scale_n) + 1e-12);
    }
    EXPECT_GT(held, 1000) << "k = " << k;
  }
}

TEST(Deadband, TheDepthCriterionSendsWhereTheHeldModelsDepthChangesAndNowhereElse) {
  // A contact on a 45° flank (∂δ/∂y = 1, ∂δ/∂z = −1; nothing along x), 50 µm deep. With the
  // pose floors wide (0.2 mm at k = 0.1), the depth criterion alone decides: the threshold is
  // max(k·δ, k·floor) = 5 µm of depth, which the flank reaches at 5 µm of y and never along x.
  ToolStateDeadbandConfig c;
  c.weber_fraction = 0.1;
  c.keepalive_s = 10.0;
  c.contact_position_floor_scale_m = 2e-3;
  c.contact_depth_floor_scale_m = 20e-6;
  ContactModel held;
  held.num_contacts = 1;
  held.contacts[0].depth_m = 50e-6;
  held.contacts[0].gradient.d_translation_W = {0.0, 1.0, -1.0};
  held.contacts[0].stiffness_n_per_m = 8000.0;
  held.contacts[0].normal_W = {0.0, -std::numbers::sqrt2 / 2, std::numbers::sqrt2 / 2};
  const auto decide_after = [&](const glm::dvec3& move, const ContactModel* model,
                                const ToolStateDeadbandConfig& config) {
    ToolStateDeadband d(config);
    RigidTransform X;
    EXPECT_EQ(d.Decide(X, {}, 0, true, model), DeadbandReason::kFirst);
    X.translation = move;
    return d.Decide(X, {}, kMs, true, model);
  };
  EXPECT_EQ(decide_after({100e-6, 0.0, 0.0}, &held, c), DeadbandReason::kNotSent);
  EXPECT_EQ(decide_after({0.0, 4e-6, 0.0}, &held, c), DeadbandReason::kNotSent);
  // 6 µm along y: the depth at the tool is 56 µm, k·δ = 5.6 µm < 6 µm.
  EXPECT_EQ(decide_after({0.0, 6e-6, 0.0}, &held, c), DeadbandReason::kDepth);
  // Into the flank (against its normal) by 6 µm changes the depth by 6·√2 µm; along the flank,
  // nothing.
  const glm::dvec3 n = held.contacts[0].normal_W;
  EXPECT_EQ(decide_after(-6e-6 * n, &held, c), DeadbandReason::kDepth);
  const glm::dvec3 along_flank{0.0, std::numbers::sqrt2 / 2, std::numbers::sqrt2 / 2};
  EXPECT_EQ(decide_after(50e-6 * along_flank, &held, c), DeadbandReason::kNotSent);
  // Deeper contacts get a wider threshold (k·δ): at 200 µm, 15 µm of y stays inside.
  ContactModel deep = held;
  deep.contacts[0].depth_m = 200e-6;
  EXPECT_EQ(decide_after({0.0, 15e-6, 0.0}, &deep, c), DeadbandReason::kNotSent);
  EXPECT_EQ(decide_after({0.0, 25e-6, 0.0}, &deep, c), DeadbandReason::kDepth);
  // The depth is compared with the remote node's prediction, not with the last pose sent: a tool
  // sliding up the flank at the twist it sent stays; one that stops leaves the prediction.
  {
    const Twist V_up_flank{{0.0, 1e-3, 0.0}, {}};  // 1 mm/s along y: 1 µm of depth a ms
    ToolStateDeadband d(c);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, V_up_flank, 0, true, &held), DeadbandReason::kFirst);
    X.translation.y = 10e-6;  // 10 ms later, where the prediction is
    EXPECT_EQ(d.Decide(X, V_up_flank, 10 * kMs, true, &held), DeadbandReason::kNotSent);
    EXPECT_EQ(d.Decide(X, {}, 20 * kMs, true, &held), DeadbandReason::kDepth);  // stopped
  }
  // A rotation counts through the contact's rotation gradient: 1 m/rad of lever, 6 µrad.
  {
    ContactModel lever = held;
    lever.contacts[0].gradient.d_translation_W = {0.0, 0.0, -1.0};
    lever.contacts[0].gradient.d_rotation_W = {1.0, 0.0, 0.0};
    ToolStateDeadbandConfig wide = c;
    wide.contact_rotation_floor_scale_rad = 1.0;  // the rotation floor out of the way
    ToolStateDeadband d(wide);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0, true, &lever), DeadbandReason::kFirst);
    X.rotation = QuaternionFromRotationVector({4e-6, 0.0, 0.0});
    EXPECT_EQ(d.Decide(X, {}, kMs, true, &lever), DeadbandReason::kNotSent);
    X.rotation = QuaternionFromRotationVector({6e-6, 0.0, 0.0});
    EXPECT_EQ(d.Decide(X, {}, 2 * kMs, true, &lever), DeadbandReason::kDepth);
  }
  // A contact 1 mm apart at both poses is not looked at; no model, or the criterion off, sends
  // nothing either.
  ContactModel apart = held;
  apart.contacts[0].depth_m = -1e-3;
  EXPECT_EQ(decide_after({0.0, 50e-6, 0.0}, &apart, c), DeadbandReason::kNotSent);
  EXPECT_EQ(decide_after({0.0, 6e-6, 0.0}, nullptr, c), DeadbandReason::kNotSent);
  ToolStateDeadbandConfig off = c;
  off.contact_depth_floor_scale_m = 0.0;
  EXPECT_EQ(decide_after({0.0, 6e-6, 0.0}, &held, off), DeadbandReason::kNotSent);
  // In free space (no contact floors held) the criterion does not apply.
  {
    ToolStateDeadbandConfig free_space = c;
    free_space.contact_floor_hold_s = 0.0;
    ToolStateDeadband d(free_space);
    RigidTransform X;
    ASSERT_EQ(d.Decide(X, {}, 0, false, &held), DeadbandReason::kFirst);
    X.translation.y = 6e-6;
    EXPECT_EQ(d.Decide(X, {}, kMs, false, &held), DeadbandReason::kNotSent);
  }
  ToolStateDeadbandConfig bad = c;
  bad.contact_depth_floor_scale_m = -1e-6;
  EXPECT_THROW(bad.Validate(), std::invalid_argument);
  EXPECT_STREQ(ToString(DeadbandReason::kDepth), "depth");
}

TEST(Deadband, ConfigsRefuseNonsense) {
  ToolStateDeadbandConfig t;
  t.weber_fraction = 1.5;
  EXPECT_THROW(t.Validate(), std::invalid_argument);
  t.weber_fraction = 0.1;
  t.keepalive_s = 0.0;
  EXPECT_THROW(t.Validate(), std::invalid_argument);
  ContactModelDeadbandConfig m;
  m.weber_fraction = std::nan("");
  EXPECT_THROW(m.Validate(), std::invalid_argument);
}

TEST(DeadbandNegotiation, TermsAgreedOrRefusedSayingWhich) {
  RemoteCapabilities caps;
  caps.max_deadband = 0.2f;
  caps.max_model_rate_hz = 500.0f;
  wire::HelloMessage hello;
  hello.deadband = {0.1f, 0.15f, 100, 50};
  wire::WelcomeMessage w;
  wire::RejectMessage r;
  ASSERT_TRUE(NegotiateSession(hello, caps, w, r));
  EXPECT_EQ(w.deadband.tool_state_deadband, 0.1f);
  EXPECT_EQ(w.deadband.model_deadband, 0.15f);
  EXPECT_EQ(w.deadband.model_keepalive_ms, 50);
  hello.deadband.model_deadband = 0.3f;
  EXPECT_FALSE(NegotiateSession(hello, caps, w, r));
  EXPECT_EQ(r.reason, wire::RejectReason::kCapabilities);
  EXPECT_NE(r.message().find("contact-model deadband of 30.0 %"), std::string_view::npos)
      << r.message();
  EXPECT_NE(r.message().find("20.0 %"), std::string_view::npos);
  hello.deadband = {0.25f, 0.0f, 100, 100};
  EXPECT_FALSE(NegotiateSession(hello, caps, w, r));
  EXPECT_NE(r.message().find("tool-state"), std::string_view::npos) << r.message();
  // A 1 ms keep-alive from a node that sends at most 500 models/s (one per 2 ms).
  hello.deadband = {0.1f, 0.1f, 100, 1};
  EXPECT_FALSE(NegotiateSession(hello, caps, w, r));
  EXPECT_NE(r.message().find("keep-alive of 1 ms"), std::string_view::npos) << r.message();
  // The session's model rate is the smaller of both sides': an operator asking 5 models/s (one
  // per 200 ms) cannot have a 100 ms keep-alive either.
  hello.deadband = {0.1f, 0.1f, 100, 100};
  hello.max_model_rate_hz = 5.0f;
  EXPECT_FALSE(NegotiateSession(hello, caps, w, r));
  EXPECT_NE(r.message().find("one per 200 ms"), std::string_view::npos) << r.message();
  hello.max_model_rate_hz = 0.0f;
  // The node extrapolates a tool state for at most its keep-alive: that must stay below the
  // peer timeout (here 500 ms).
  hello.deadband = {0.1f, 0.1f, 500, 100};
  EXPECT_FALSE(NegotiateSession(hello, caps, w, r));
  EXPECT_NE(r.message().find("peer timeout, 500 ms"), std::string_view::npos) << r.message();
  hello.deadband = {0.0f, 0.1f, 500, 100};  // no tool-state deadband: its keep-alive is unused
  EXPECT_TRUE(NegotiateSession(hello, caps, w, r)) << r.message();
}

TEST(DeadbandNegotiation, HelloAndWelcomeCarryTheTermsAndRefuseBadOnes) {
  const MacKey key = MacKey::Generate();
  wire::HelloMessage hello;
  hello.client_nonce = 9;
  hello.deadband = {0.05f, 0.1f, 80, 90};
  wire::Header h;
  h.sequence = 1;
  const wire::Datagram d = wire::EncodeHello(h, hello, key);
  wire::Header got;
  std::span<const std::uint8_t> body;
  ASSERT_EQ(wire::OpenDatagram(d.view(), key, got, body), wire::DecodeStatus::kOk);
  wire::HelloMessage back;
  ASSERT_EQ(wire::DecodeHello(body, back), wire::DecodeStatus::kOk);
  EXPECT_EQ(back.deadband.tool_state_deadband, 0.05f);
  EXPECT_EQ(back.deadband.model_deadband, 0.1f);
  EXPECT_EQ(back.deadband.tool_state_keepalive_ms, 80);
  EXPECT_EQ(back.deadband.model_keepalive_ms, 90);
  for (const wire::DeadbandTerms bad :
       {wire::DeadbandTerms{1.0f, 0.0f, 100, 100}, wire::DeadbandTerms{0.0f, -0.1f, 100, 100},
        wire::DeadbandTerms{0.1f, 0.1f, 0, 100},
        wire::DeadbandTerms{std::nanf(""), 0.1f, 100, 100}}) {
    hello.deadband = bad;
    const wire::Datagram b = wire::EncodeHello(h, hello, key);
    ASSERT_EQ(wire::OpenDatagram(b.view(), key, got, body), wire::DecodeStatus::kOk);
    const wire::DecodeStatus s = wire::DecodeHello(body, back);
    EXPECT_TRUE(s == wire::DecodeStatus::kBadValue || s == wire::DecodeStatus::kNonFinite)
        << wire::ToString(s);
  }
}

TEST(DeadbandNegotiation, AHelloOfAnotherVersionIsOpenedForARejectInItsVersion) {
  const MacKey key = MacKey::Generate();
  wire::HelloMessage hello;
  hello.client_nonce = 0x1122334455667788ull;
  hello.min_version = hello.max_version = 3;
  wire::Header h;
  h.sequence = 1;
  // As a version-3 operator sends it: the 28-byte header of versions 2 to 7 with version 3, the v3
  // body (32 bytes: no deadband terms), the whole 32-byte MAC.
  const wire::Datagram own = wire::EncodeHello(h, hello, key);
  const wire::Datagram d =
      test::LegacyDatagram(3, wire::MessageType::kHello, 1, test::BodyOf(own).first(32), key);
  wire::Header got;
  std::span<const std::uint8_t> body;
  EXPECT_EQ(wire::OpenDatagram(d.view(), key, got, body), wire::DecodeStatus::kBadVersion);
  wire::ForeignHello foreign;
  ASSERT_EQ(wire::OpenForeignHello(d.view(), key, foreign), wire::DecodeStatus::kOk);
  EXPECT_EQ(foreign.header_version, 3);
  EXPECT_EQ(foreign.min_version, 3);
  EXPECT_EQ(foreign.client_nonce, 0x1122334455667788ull);
  // Under another key it is not opened (no Reject for forgeries).
  EXPECT_EQ(wire::OpenForeignHello(d.view(), MacKey::Generate(), foreign),
            wire::DecodeStatus::kBadMac);
  // This version's own Hello is not foreign, and neither is a newer one (its layout is unknown).
  EXPECT_EQ(wire::OpenForeignHello(own.view(), key, foreign), wire::DecodeStatus::kBadVersion);
  wire::Datagram newer = own;
  newer.bytes[wire::kHeaderVersionOffset] = static_cast<std::uint8_t>(wire::kProtocolVersion + 1);
  newer.size -= wire::kMacBytes;
  ComputeMac(
      std::span<const std::uint8_t>(newer.bytes.data(), newer.size), key,
      std::span<std::uint8_t, wire::kMacBytes>(newer.bytes.data() + newer.size, wire::kMacBytes));
  newer.size += wire::kMacBytes;
  EXPECT_EQ(wire::OpenForeignHello(newer.view(), key, foreign), wire::DecodeStatus::kBadVersion);
  // The Reject goes out in version 3: the old header with 3 in it, the v3 Reject body, the whole
  // MAC.
  wire::RejectMessage reject;
  reject.client_nonce = foreign.client_nonce;
  reject.reason = wire::RejectReason::kVersion;
  const wire::Datagram r = wire::EncodeReject(h, reject, key, 3);
  const test::LegacyHeader rh = test::ReadLegacyHeader(r.view());
  EXPECT_EQ(rh.magic, wire::kLegacyMagic);
  EXPECT_EQ(rh.version, 3);
  EXPECT_EQ(rh.type, static_cast<std::uint8_t>(wire::MessageType::kReject));
  EXPECT_EQ(rh.flags, 0);
  EXPECT_EQ(r.size, wire::kLegacyHeaderBytes + wire::kRejectFixedBytes + wire::kLegacyMacBytes);
  EXPECT_TRUE(test::LegacyMacVerifies(r.view(), key));
}

}  // namespace
}  // namespace ht
