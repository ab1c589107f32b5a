// The FaultInjectingDriver (what it changes, where, when) and the scene file's `faults:` list.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/drivers/fault_injecting_driver.hpp"

namespace pw = pedalwave;
using pw::model::FaultType;

namespace {

pw::model::Scene scene() {
  pw::model::Scene s;
  s.initial.pose = pw::model::InitialPose::kGaitStart;
  s.integrator.h = 5e-4;
  return s;
}

pw::drivers::Command gait_cmd(double t) {
  pw::drivers::Command c{};
  c.joints = 5;
  for (std::size_t j = 0; j < 5; ++j) {
    c.beta_ref[j] = 0.5 * std::sin(3 * t + static_cast<double>(j));
    c.beta_dot_ref[j] = 1.5 * std::cos(3 * t + static_cast<double>(j));
    c.kp[j] = 30;
    c.kd[j] = 15;
  }
  return c;
}

struct Pair {
  pw::drivers::Feedback clean, out;
};

// Runs `cycles` with one fault; returns per cycle what the bus carried and what was delivered.
std::vector<Pair> run(const pw::model::FaultSpec& f, int cycles) {
  pw::drivers::SimDriver sim(scene(), {});
  pw::drivers::FaultInjectingDriver inj(sim, &sim, {f});
  std::vector<Pair> v;
  for (int k = 0; k < cycles; ++k) {
    Pair p;
    inj.read(0, 0, p.out);
    p.clean = inj.clean_feedback();
    v.push_back(p);
    inj.write(gait_cmd(k * 1e-3));
  }
  return v;
}

TEST(Injector, SensorFaultsChangeOnlyTheirChannelAndJointFromTheOnset) {
  for (FaultType type : {FaultType::kEncoderOffset, FaultType::kEncoderStuck, FaultType::kDeflectionBias,
                         FaultType::kDeflectionScale, FaultType::kDeflectionStuck, FaultType::kNaN,
                         FaultType::kModuleSilent, FaultType::kStale}) {
    pw::model::FaultSpec f;
    f.type = type;
    f.joint = 2;
    f.t_start = 0.010;
    f.value = type == FaultType::kStale ? 3 : type == FaultType::kDeflectionScale ? 1.5 : 0.05;
    const auto v = run(f, 30);
    SCOPED_TRACE(std::string(pw::model::to_string(type)));
    for (int k = 0; k < 30; ++k) {
      const auto& p = v[static_cast<std::size_t>(k)];
      for (std::size_t j = 0; j < 5; ++j) {
        const bool hit = j == 2 && k >= 10;
        const bool same = p.out.beta[j] == p.clean.beta[j] && p.out.beta_dot[j] == p.clean.beta_dot[j] &&
                          p.out.deflection[j] == p.clean.deflection[j] && p.out.status[j] == p.clean.status[j];
        if (!hit) {
          EXPECT_TRUE(same) << "cycle " << k << " joint " << j;
        }
      }
      if (k < 10) continue;
      const auto& o = p.out;
      const auto& c = p.clean;
      switch (type) {
        case FaultType::kEncoderOffset: EXPECT_DOUBLE_EQ(o.beta[2], c.beta[2] + 0.05); break;
        case FaultType::kEncoderStuck:
          EXPECT_EQ(o.beta[2], v[10].clean.beta[2]);
          EXPECT_EQ(o.beta_dot[2], 0.0);
          break;
        case FaultType::kDeflectionBias: EXPECT_DOUBLE_EQ(o.deflection[2], c.deflection[2] + 0.05); break;
        case FaultType::kDeflectionScale: EXPECT_DOUBLE_EQ(o.deflection[2], c.deflection[2] * 1.5); break;
        case FaultType::kDeflectionStuck: EXPECT_EQ(o.deflection[2], v[10].clean.deflection[2]); break;
        case FaultType::kNaN: EXPECT_TRUE(std::isnan(o.deflection[2])); break;
        case FaultType::kModuleSilent:
          EXPECT_TRUE(o.status[2] & pw::drivers::kStatusMissing);
          EXPECT_EQ(o.beta[2], v[9].out.beta[2]);
          break;
        case FaultType::kStale:
          EXPECT_TRUE(o.status[2] & pw::drivers::kStatusStale);
          EXPECT_EQ(o.beta[2], v[static_cast<std::size_t>(k - 3)].clean.beta[2]);
          break;
        default: break;
      }
    }
  }
}

TEST(Injector, RepeatedFrameRepeatsSeqAndValues) {
  pw::model::FaultSpec f;
  f.type = FaultType::kRepeatedFrame;
  f.t_start = 0.005;
  const auto v = run(f, 20);
  int repeats = 0;
  for (std::size_t k = 1; k < v.size(); ++k)
    if (v[k].out.seq == v[k - 1].out.seq) {
      ++repeats;
      EXPECT_GE(k, 5u);
      EXPECT_EQ(v[k].out.beta[0], v[k - 1].out.beta[0]);
    }
  EXPECT_GE(repeats, 6);
}

TEST(Injector, PhysicalFaultsActOnThePlantFromOnsetToEnd) {
  pw::drivers::SimDriver sim(scene(), {});
  pw::model::FaultSpec f;
  f.type = FaultType::kTorqueGain;
  f.joint = 3;
  f.t_start = 0.005;
  f.duration = 0.010;
  f.value = 0.25;
  pw::drivers::FaultInjectingDriver inj(sim, &sim, {f});
  pw::drivers::Feedback fb{};
  for (int k = 0; k < 25; ++k) {
    inj.read(0, 0, fb);
    inj.write(gait_cmd(k * 1e-3));
    const double g = sim.sim().plant().faults().torque_gain(3);
    EXPECT_EQ(g, (k >= 5 && k < 15) ? 0.25 : 1.0) << k;
    EXPECT_EQ(sim.sim().plant().faults().torque_gain(2), 1.0);
  }
}

TEST(Injector, InvalidFaultsThrowNamingTheValue) {
  pw::drivers::SimDriver sim(scene(), {});
  pw::model::FaultSpec f;
  f.type = FaultType::kSpringScale;
  f.joint = 7;
  try {
    pw::drivers::FaultInjectingDriver inj(sim, &sim, {f});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("joint = 7"), std::string::npos) << e.what();
  }
  f.joint = 1;
  f.value = 0.0;
  EXPECT_THROW(pw::drivers::FaultInjectingDriver(sim, &sim, {f}), std::invalid_argument);
  f.value = 0.2;
  EXPECT_THROW(pw::drivers::FaultInjectingDriver(sim, nullptr, {f}), std::invalid_argument);
}

TEST(SceneFile, FaultsListIsParsedAndValidated) {
  const auto s = pw::config::parse_scene(R"(
name: t
ground: {mu: 0.8}
faults:
  - {type: torque_gain, joint: 2, t_start: 4.5, value: 0.3}
  - {type: encoder_noise, joint: 0, t_start: 1, value: 0.01, duration: 0.5}
)", "inline");
  ASSERT_EQ(s.faults.size(), 2u);
  EXPECT_EQ(s.faults[0].type, FaultType::kTorqueGain);
  EXPECT_EQ(s.faults[0].joint, 2);
  EXPECT_EQ(s.faults[0].t_start, 4.5);
  EXPECT_EQ(s.faults[0].value, 0.3);
  EXPECT_TRUE(std::isinf(s.faults[0].duration));
  EXPECT_EQ(s.faults[1].duration, 0.5);
  try {
    pw::config::parse_scene("faults:\n  - {type: gremlin, joint: 0}\n", "inline");
    FAIL();
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("torque_gain"), std::string::npos) << e.what();
  }
  EXPECT_ANY_THROW(pw::config::parse_scene("faults:\n  - {type: nan, joint: 5}\n", "inline"));
  // The decorator picks the scene's list up.
  pw::drivers::SimDriver sim(s, {});
  pw::drivers::FaultInjectingDriver inj(sim);
  EXPECT_EQ(inj.faults().size(), 2u);
}

}  // namespace
