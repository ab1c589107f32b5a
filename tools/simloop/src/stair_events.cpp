#include "pedalwave/simloop/stair_events.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace pedalwave::simloop {

StairWatch::StairWatch(const model::Scene& resolved) {
  active_ = resolved.ground_on && !resolved.boxes.empty();
  if (!active_) return;
  const model::Box& b = resolved.boxes.front();
  e_.x_near = b.x_near;
  e_.x_far = b.x_near + b.width;
  e_.top = resolved.ground.z + b.height;
  e_.max_head_z = -std::numeric_limits<double>::infinity();
  half_ = resolved.robot.half_thickness();
}

void StairWatch::observe(double t, const model::Model& m, const model::Data& d, const Eigen::VectorXd& q) {
  if (!active_) return;
  const model::Vec2 head = model::point_position(m, d, q, m.point_head());
  e_.max_head_z = std::max(e_.max_head_z, head.y());
  const double under = head.y() - half_;  // the head module's underside below the tip
  if (std::isnan(e_.t_head_on_top) && head.x() >= e_.x_near && head.x() <= e_.x_far &&
      under >= e_.top - kOnTopBelow && under <= e_.top + kOnTopAbove)
    e_.t_head_on_top = t;
  if (std::isnan(e_.t_com_past) && model::center_of_mass(m, d, q).x() > e_.x_far) e_.t_com_past = t;
  if (std::isnan(e_.t_body_past)) {
    bool past = true;
    for (int p = 0; p < m.points() && past; ++p) past = model::point_position(m, d, q, p).x() > e_.x_far;
    if (past) e_.t_body_past = t;
  }
}

StairEvents StairWatch::events() const {
  StairEvents e = e_;
  if (!std::isfinite(e.max_head_z)) e.max_head_z = std::numeric_limits<double>::quiet_NaN();
  return e;
}

std::string describe(const StairEvents& e) {
  std::ostringstream os;
  auto t = [&](double s) {
    std::ostringstream o;
    if (std::isnan(s)) o << "never";
    else o << s << " s";
    return o.str();
  };
  os << "head on top " << t(e.t_head_on_top) << ", COM past " << t(e.t_com_past) << ", whole body past "
     << t(e.t_body_past) << " (box x = " << e.x_near << " … " << e.x_far << " m, top " << e.top << " m)";
  return os.str();
}

}  // namespace pedalwave::simloop
