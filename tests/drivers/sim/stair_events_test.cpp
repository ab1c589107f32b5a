// The stair events (simloop/stair_events.hpp), shared by pedalwave_paper and pedalwave_sim:
// head on top measured at the head module's underside (thick links), COM and whole body past.
#include <gtest/gtest.h>

#include <cmath>

#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/stair_events.hpp"

using namespace pedalwave;

namespace {

// A 2-link robot (rigid joints: q = [α, θ_N, p_x, p_z], p the joint) lying straight and level,
// its axis at height z, its head tip at x_head; a 6 cm box from x = 0 to 0.2.
model::Scene lying(model::LinkShape shape, double size, double x_head, double z) {
  model::Scene s;
  s.robot.N = 2;
  s.robot.joints = model::JointModel::kRigid;
  s.robot.link_shape = shape;
  if (shape == model::LinkShape::kCapsule) s.robot.link_radius = size;
  if (shape == model::LinkShape::kBox) s.robot.link_height = size;
  s.boxes = {model::Box{.x_near = 0.0, .width = 0.2, .height = 0.06}};
  s.initial.pose = model::InitialPose::kExplicit;
  s.initial.q = {0.0, 0.0, x_head - 2 * s.robot.l, z};
  return s;
}

simloop::StairEvents watch_once(const model::Scene& s, double t) {
  model::Plant p(s);
  Eigen::VectorXd q, v;
  p.initial_state(q, v);
  model::Data d(p.model());
  model::update_kinematics(p.model(), d, q, v);
  simloop::StairWatch w(p.scene());
  EXPECT_TRUE(w.active());
  w.observe(t, p.model(), d, q);
  return w.events();
}

}  // namespace

TEST(StairEvents, HeadOnTopIsTheHeadModulesUnderside) {
  // Resting on the top face: the axis r (h_m / 2) above it, 1 mm into the contact.
  for (const auto& [shape, size, half] : {std::tuple{model::LinkShape::kCapsule, 0.015, 0.015},
                                          std::tuple{model::LinkShape::kBox, 0.03, 0.015}}) {
    SCOPED_TRACE(model::to_string(shape));
    const simloop::StairEvents e = watch_once(lying(shape, size, 0.15, 0.06 + half - 0.001), 1.5);
    EXPECT_EQ(e.t_head_on_top, 1.5);
    EXPECT_NEAR(e.max_head_z, 0.06 + half - 0.001, 1e-12);
    EXPECT_TRUE(std::isnan(e.t_com_past));
  }
  // The same axis height with segment links is 1.4 cm over the top: not on it.
  EXPECT_TRUE(std::isnan(watch_once(lying(model::LinkShape::kSegment, 0.0, 0.15, 0.074), 1.5).t_head_on_top));
  EXPECT_EQ(watch_once(lying(model::LinkShape::kSegment, 0.0, 0.15, 0.059), 1.5).t_head_on_top, 1.5);
}

TEST(StairEvents, ComAndWholeBodyPastTheFarEdge) {
  // Head at 0.3: the tail tip (0.3 − 0.14 = 0.16) is still over the box, the COM (0.23) past it.
  simloop::StairEvents e = watch_once(lying(model::LinkShape::kSegment, 0.0, 0.30, 0.0), 2.0);
  EXPECT_EQ(e.t_com_past, 2.0);
  EXPECT_TRUE(std::isnan(e.t_body_past));
  EXPECT_TRUE(std::isnan(e.t_head_on_top)) << "the head is beyond the box";
  e = watch_once(lying(model::LinkShape::kSegment, 0.0, 0.35, 0.0), 3.0);
  EXPECT_EQ(e.t_body_past, 3.0);
  EXPECT_DOUBLE_EQ(e.x_far, 0.2);
  EXPECT_DOUBLE_EQ(e.top, 0.06);
  // No box: nothing is watched.
  model::Scene none = lying(model::LinkShape::kSegment, 0.0, 0.35, 0.0);
  none.boxes.clear();
  EXPECT_FALSE(simloop::StairWatch(none).active());
}
