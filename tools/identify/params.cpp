#include "params.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "pedalwave/config/yaml_reader.hpp"

namespace pedalwave::identify {

namespace {

std::vector<ParamDef> make_table() {
  std::vector<ParamDef> t;
  // ---- one row per fittable scene parameter ----------------------------------------------------
  t.push_back({"K", "N·m/rad", "robot", "K", true, {},
               [](model::Scene& s, double v) { s.robot.K.clear(); s.robot.K_all = v; },
               [](const model::Scene& s) { return s.robot.stiffness(0); },
               "SEA spring stiffness, every joint"});
  t.push_back({"I_l", "kg·m²", "robot", "I_l", true, {},
               [](model::Scene& s, double v) { s.robot.I_l = v; },
               [](const model::Scene& s) { return s.robot.I_l; }, "link inertia about its COM"});
  t.push_back({"I_r", "kg·m²", "robot", "I_r", true, {},
               [](model::Scene& s, double v) { s.robot.I_r = v; },
               [](const model::Scene& s) { return s.robot.I_r; }, "rotor inertia (reflected: n² I_r)"});
  t.push_back({"ground_k", "N/m", "ground", "k", true, {},
               [](model::Scene& s, double v) { s.ground.k = v; },
               [](const model::Scene& s) { return s.ground.k; }, "contact stiffness (ground and boxes)"});
  t.push_back({"ground_d", "N·s/m", "ground", "d", true, {},
               [](model::Scene& s, double v) { s.ground.d = v; },
               [](const model::Scene& s) { return s.ground.d; }, "contact damping (ground and boxes)"});
  t.push_back({"v_s", "m/s", "ground", "v_s", true, {},
               [](model::Scene& s, double v) { s.ground.v_s = v; },
               [](const model::Scene& s) { return s.ground.v_s; }, "stiction / regularization velocity"});
  t.push_back({"friction_law", "", "ground", "friction", false,
               {"coulomb", "regularized", "tanh", "stick_slip"},
               [](model::Scene& s, double v) { s.ground.law = static_cast<model::FrictionLaw>(std::lround(v)); },
               [](const model::Scene& s) { return static_cast<double>(s.ground.law); }, "friction law"});
  t.push_back({"friction_at", "", "ground", "friction_at_com", false, {"contact_points", "link_coms"},
               [](model::Scene& s, double v) { s.ground.friction_at_com = std::lround(v) == 1; },
               [](const model::Scene& s) { return s.ground.friction_at_com ? 1.0 : 0.0; },
               "where friction acts: every contact point, or the link COMs only (the paper)"});
  t.push_back({"edge_mu", "-", "obstacles", "edge_mu", false, {},
               [](model::Scene& s, double v) { for (model::Box& b : s.boxes) b.edge_mu = v; },
               [](const model::Scene& s) { return s.boxes.empty() || std::isnan(s.boxes.front().edge_mu)
                                                      ? (s.boxes.empty() ? 0.82 : s.boxes.front().mu)
                                                      : s.boxes.front().edge_mu; },
               "friction of the box corners against the links (stair scenes only)"});
  // Module size (README "Link shapes"): the contact solid around each link axis, and its size as one
  // row — the surface's distance from the axis, i.e. the capsule's radius r or half the box's height
  // h_m / 2 — so the same bound reads the same for both shapes and the row does not depend on the
  // order in which a point's values are applied (it sets both; the shape picks which one counts).
  t.push_back({"link_shape", "", "robot", "link_shape", false, {"segment", "capsule", "box"},
               [](model::Scene& s, double v) { s.robot.link_shape = static_cast<model::LinkShape>(std::lround(v)); },
               [](const model::Scene& s) { return static_cast<double>(s.robot.link_shape); },
               "module contact solid: the axis (segment), a capsule, or a box around it"});
  t.push_back({"module_size", "m", "robot", "link_radius", false, {},
               [](model::Scene& s, double v) { s.robot.link_radius = v; s.robot.link_height = 2.0 * v; },
               [](const model::Scene& s) { return s.robot.half_thickness(); },
               "module half-thickness: capsule radius r = link_radius, or box link_height / 2"});
  return t;
}

}  // namespace

const std::vector<ParamDef>& parameter_table() {
  static const std::vector<ParamDef> table = make_table();
  return table;
}

const ParamDef& find_param(const std::string& name) {
  std::string known;
  for (const ParamDef& d : parameter_table()) {
    if (d.name == name) return d;
    known += (known.empty() ? "" : ", ") + d.name;
  }
  throw std::invalid_argument("unknown parameter " + name + ": expected one of " + known);
}

std::vector<FitParam> load_params(const std::string& file) {
  const config::Reader r = config::Reader::load_file(file);
  r.allow_only({"parameters", "description"});
  const config::Reader l = r.required("parameters", "a list of parameters");
  if (!l.is_sequence() || l.size() == 0) l.fail("a non-empty list of parameters");
  std::vector<FitParam> out;
  for (std::size_t i = 0; i < l.size(); ++i) {
    const config::Reader e = l.at(i);
    e.allow_only({"name", "min", "max", "start", "choices", "reason"});
    const config::Reader nm = e.required("name", "a parameter name");
    FitParam p;
    try {
      p.def = &find_param(nm.as_string());
    } catch (const std::invalid_argument& x) {
      nm.fail(std::string(x.what()).substr(std::string(x.what()).find("expected ") + 9));
    }
    for (const FitParam& q : out)
      if (q.def == p.def) nm.fail("a parameter not listed before");
    p.reason = e.required("reason", "the reason for the bounds (text)").as_string();
    if (p.is_choice()) {
      const config::Reader c = e.required("choices", "a list of words");
      if (!c.is_sequence() || c.size() == 0) c.fail("a non-empty list of words");
      for (std::size_t k = 0; k < c.size(); ++k) {
        const std::string w = c.at(k).as_string();
        int idx = -1;
        std::string words;
        for (std::size_t m = 0; m < p.def->choices.size(); ++m) {
          if (p.def->choices[m] == w) idx = static_cast<int>(m);
          words += (m ? ", " : "") + p.def->choices[m];
        }
        if (idx < 0) c.at(k).fail("one of " + words);
        p.choices.push_back(idx);
      }
      if (e.has("min") || e.has("max")) e.fail_key("min", "no bounds for a choice parameter");
    } else {
      if (e.has("choices")) e.fail_key("choices", "no choices for a continuous parameter");
      p.lo = e.required("min", "the lower bound").as_number();
      p.hi = e.required("max", "the upper bound").as_number();
      if (!std::isfinite(p.lo) || !std::isfinite(p.hi) || !(p.lo < p.hi))
        e["max"].fail("a finite number above min = " + std::to_string(p.lo));
      if (p.def->log_scale && !(p.lo > 0)) e["min"].fail("a number > 0 (" + p.def->name + " is searched on a log scale)");
      p.start = std::numeric_limits<double>::quiet_NaN();
      if (e.has("start")) {
        p.start = e["start"].as_number();
        if (!(p.start >= p.lo && p.start <= p.hi)) e["start"].fail("a number within [min, max]");
      }
    }
    out.push_back(p);
  }
  return out;
}

const char* to_string(Measure m) {
  switch (m) {
    case Measure::flat_speed: return "flat_speed";
    case Measure::friction_gain: return "friction_gain";
    case Measure::torque_peak_change: return "torque_peak_change";
    case Measure::stair_speed: return "stair_speed";
    case Measure::stair_gain: return "stair_gain";
  }
  return "?";
}

Targets load_targets(const std::string& file) {
  const config::Reader r = config::Reader::load_file(file);
  r.allow_only({"targets", "k_c", "description"});
  Targets t;
  t.k_c = r.bounded("k_c", t.k_c, 0, 1e3, "-");
  const config::Reader l = r.required("targets", "a list of targets");
  if (!l.is_sequence() || l.size() == 0) l.fail("a non-empty list of targets");
  for (std::size_t i = 0; i < l.size(); ++i) {
    const config::Reader e = l.at(i);
    e.allow_only({"measure", "value", "tolerance", "source"});
    Target x;
    const std::string m = e.choice("measure", "", {"flat_speed", "friction_gain", "torque_peak_change",
                                                   "stair_speed", "stair_gain"});
    if (m.empty()) e.fail_key("measure", "a measure (the key is required)");
    for (Measure k : {Measure::flat_speed, Measure::friction_gain, Measure::torque_peak_change,
                      Measure::stair_speed, Measure::stair_gain})
      if (m == to_string(k)) x.measure = k;
    for (const Target& y : t.list)
      if (y.measure == x.measure) e["measure"].fail("a measure not listed before");
    x.value = e.required("value", "the target figure").as_number();
    x.tolerance = e.bounded("tolerance", 0, 0, 1e6, "", true);
    if (!e.has("tolerance")) e.fail_key("tolerance", "the residual's unit, > 0 (the key is required)");
    x.source = e.string("source", "");
    t.list.push_back(x);
  }
  return t;
}

}  // namespace pedalwave::identify
