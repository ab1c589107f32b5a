#include "fit.hpp"

#include <nlopt.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include "experiments.hpp"
#include "pedalwave/config/scene.hpp"
#include "pedalwave/toolkit/table.hpp"

namespace pedalwave::identify {

namespace fs = std::filesystem;

namespace {

std::string read_text(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  if (!f) throw std::runtime_error("cannot read scene file " + p.string());
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}

// The runs a target list needs.
enum Run { kFlatHigh, kFlatLow, kFriction, kStair0, kStairKc, kRuns };
const char* kRunName[kRuns] = {"flat_high", "flat_low", "friction", "stair_0", "stair_kc"};

std::set<Run> runs_needed(const Targets& t) {
  std::set<Run> s;
  for (const Target& x : t.list) switch (x.measure) {
      case Measure::flat_speed: s.insert(kFlatHigh); break;
      case Measure::friction_gain: s.insert(kFlatHigh); s.insert(kFlatLow); break;
      case Measure::torque_peak_change: s.insert(kFriction); break;
      case Measure::stair_speed: s.insert(kStairKc); break;
      case Measure::stair_gain: s.insert(kStair0); s.insert(kStairKc); break;
    }
  return s;
}

std::string fmt(double v, int sig = 4) { return toolkit::Table::num(v, sig); }

std::vector<std::size_t> continuous_dims(const std::vector<FitParam>& ps) {
  std::vector<std::size_t> d;
  for (std::size_t i = 0; i < ps.size(); ++i)
    if (!ps[i].is_choice()) d.push_back(i);
  return d;
}

double to_z(const FitParam& p, double v) {
  if (p.def->log_scale) return (std::log(v) - std::log(p.lo)) / (std::log(p.hi) - std::log(p.lo));
  return (v - p.lo) / (p.hi - p.lo);
}
double from_z(const FitParam& p, double z) {
  z = std::clamp(z, 0.0, 1.0);
  if (p.def->log_scale) return std::exp(std::log(p.lo) + z * (std::log(p.hi) - std::log(p.lo)));
  return p.lo + z * (p.hi - p.lo);
}

double halton(std::size_t i, int base) {
  double f = 1, r = 0;
  while (i > 0) {
    f /= base;
    r += f * static_cast<double>(i % static_cast<std::size_t>(base));
    i /= static_cast<std::size_t>(base);
  }
  return r;
}

double cost_of(const std::vector<double>& r) {
  double c = 0;
  for (double x : r) c += 0.5 * x * x;
  return c;
}

}  // namespace

double Measures::get(Measure m) const {
  switch (m) {
    case Measure::flat_speed: return v_flat_high;
    case Measure::friction_gain: return v_flat_high / v_flat_low - 1.0;
    case Measure::torque_peak_change: return peak_change;
    case Measure::stair_speed: return v_stair_kc;
    case Measure::stair_gain: return v_stair_kc / v_stair0 - 1.0;
  }
  return NAN;
}

// ---- one simulation -------------------------------------------------------------------------------
std::string run_line(const std::string& line) {
  const campaign::Record in = campaign::Record::parse(line, "pedalwave_identify run specification");
  if (in.text("kind") != "identify.run")
    throw std::invalid_argument("run specification: kind = " + in.text("kind") + ": expected identify.run");
  model::Scene sc = config::parse_scene(in.text("scene_yaml"), in.text("scene"));
  const long long np = in.integer("params");
  for (long long i = 0; i < np; ++i) {
    const std::string key = "p" + std::to_string(i);
    find_param(in.text(key + "_name")).apply(sc, in.number(key));
  }
  sc.duration = in.number("duration");
  paper::RunSpec spec;
  spec.scene = sc;
  spec.k_c = in.number("k_c");
  spec.integ = sc.integrator;
  const bool peaks = in.integer("peaks") != 0;
  if (peaks) {
    spec.sample_every = 0.005;
    spec.cross_x = in.number("cross_x");
  }
  campaign::Record out;
  paper::RunResult r;
  try {
    model::validate(spec.scene);
    r = paper::run(spec);
  } catch (const std::invalid_argument& e) {
    // A parameter set the model refuses: no measures (the fit sees a failed evaluation).
    out.put_int("status", -1).put_text("why", e.what());
    return out.line();
  }
  out.put_int("status", static_cast<long long>(r.status))
      .put("avg_speed", r.status == model::StepStatus::kOk ? r.avg_speed : NAN)
      .put("t_body_past", r.stair.t_body_past);
  if (peaks) {
    const double period = paper::gait_period(spec.scene);
    std::vector<double> before, after;
    for (std::size_t i : paper::negative_peaks(r.trace.t, r.trace.tau_head, period)) {
      const double t = r.trace.t[i];
      if (t < period) continue;  // the start-up transient (as pedalwave_paper friction)
      (std::isnan(r.t_head_cross) || t < r.t_head_cross ? before : after).push_back(std::abs(r.trace.tau_head[i]));
    }
    auto mean = [](const std::vector<double>& v) {
      double s = 0;
      for (double x : v) s += x;
      return v.empty() ? NAN : s / static_cast<double>(v.size());
    };
    out.put("peak_change", r.status == model::StepStatus::kOk ? mean(after) / mean(before) - 1.0 : NAN)
        .put_int("peaks_before", static_cast<long long>(before.size()))
        .put_int("peaks_after", static_cast<long long>(after.size()));
  }
  return out.line();
}

// ---- the evaluator ----------------------------------------------------------------------------------
Evaluator::Evaluator(std::vector<FitParam> params, Targets targets, FitSettings settings)
    : params_(std::move(params)), targets_(std::move(targets)), settings_(std::move(settings)) {
  for (Run r : runs_needed(targets_)) {
    std::string name;
    switch (r) {
      case kFlatHigh: name = "flat_high_friction"; break;
      case kFlatLow: name = "flat_low_friction"; break;
      case kFriction: name = "friction_change"; break;
      default: name = settings_.stair_scene; break;
    }
    if (!scene_text_.count(name)) {
      const fs::path p = name.find('/') != std::string::npos || name.ends_with(".yaml")
                             ? fs::path(name) : settings_.scenes_dir / (name + ".yaml");
      scene_text_[name] = read_text(p);
      (void)config::parse_scene(scene_text_[name], p.string());  // refuse a bad scene now, with its name
    }
  }
  if (!settings_.cache_file.empty() && fs::exists(settings_.cache_file)) {
    std::ifstream f(settings_.cache_file);
    std::string l;
    while (std::getline(f, l)) {
      const auto tab = l.find('\t');
      if (tab == 16) cache_[l.substr(0, tab)] = l.substr(tab + 1);  // a torn last line is skipped
    }
  }
}

Point Evaluator::start_point(const std::vector<int>& choice) const {
  const model::Scene base = config::parse_scene(scene_text_.begin()->second, scene_text_.begin()->first);
  Point p(params_.size());
  std::size_t c = 0;
  for (std::size_t i = 0; i < params_.size(); ++i) {
    const FitParam& f = params_[i];
    if (f.is_choice()) p[i] = choice.at(c++);
    else p[i] = std::isfinite(f.start) ? f.start : std::clamp(f.def->get(base), f.lo, f.hi);
  }
  return p;
}

std::vector<std::string> Evaluator::specs_of(const Point& p) const {
  std::vector<std::string> out;
  for (Run r : runs_needed(targets_)) {
    std::string name;
    double dur = 0, k_c = 0;
    switch (r) {
      case kFlatHigh: name = "flat_high_friction"; dur = settings_.horizon.flat; break;
      case kFlatLow: name = "flat_low_friction"; dur = settings_.horizon.flat; break;
      case kFriction: name = "friction_change"; dur = settings_.horizon.friction; break;
      case kStair0: name = settings_.stair_scene; dur = settings_.horizon.stair; break;
      case kStairKc: name = settings_.stair_scene; dur = settings_.horizon.stair; k_c = targets_.k_c; break;
      case kRuns: break;
    }
    campaign::Record rec;
    rec.put_text("kind", "identify.run").put_text("run", kRunName[r]).put_text("scene", name)
        .put_text("scene_yaml", scene_text_.at(name)).put("duration", dur).put("k_c", k_c)
        .put_int("peaks", r == kFriction ? 1 : 0);
    if (r == kFriction) {
      const model::Scene sc = config::parse_scene(scene_text_.at(name), name);
      if (sc.ground.patches.empty())
        throw std::invalid_argument("scene " + name + ": expected a ground patch (the friction change)");
      rec.put("cross_x", sc.ground.patches.front().x_begin);
    }
    rec.put_int("params", static_cast<long long>(params_.size()));
    for (std::size_t i = 0; i < params_.size(); ++i) {
      const std::string key = "p" + std::to_string(i);
      rec.put_text(key + "_name", params_[i].def->name).put(key, p[i]);
    }
    out.push_back(rec.line());
  }
  return out;
}

std::vector<Measures> Evaluator::evaluate(const std::vector<Point>& points, const std::string& label) {
  std::vector<std::vector<std::string>> specs;
  std::vector<std::string> todo;
  std::set<std::string> todo_hash;
  for (const Point& p : points) {
    specs.push_back(specs_of(p));
    for (const std::string& s : specs.back()) {
      const std::string h = campaign::hash(s);
      if (cache_.count(h)) ++cache_hits_;
      else if (todo_hash.insert(h).second) todo.push_back(s);
    }
  }
  evaluations_ += points.size();
  if (!todo.empty()) {
    campaign::Options o = settings_.campaign;
    o.progress = settings_.progress;
    char name[32];
    std::snprintf(name, sizeof name, "eval-%05zu", batches_++);
    const std::vector<std::string> res = campaign::run(name, todo, run_line, o);
    std::ofstream cf;
    if (!settings_.cache_file.empty()) cf.open(settings_.cache_file, std::ios::app);
    for (std::size_t i = 0; i < todo.size(); ++i) {
      const std::string h = campaign::hash(todo[i]);
      cache_[h] = res[i];
      if (cf) cf << h << '\t' << res[i] << '\n';
    }
    sims_run_ += todo.size();
  }
  std::vector<Measures> out;
  for (const auto& sp : specs) {
    Measures m;
    for (const std::string& s : sp) {
      const campaign::Record spec = campaign::Record::parse(s, "spec");
      const campaign::Record r = campaign::Record::parse(cache_.at(campaign::hash(s)), "pedalwave_identify run result");
      const std::string run = spec.text("run");
      const bool ok = r.integer("status") == 0;
      const double v = ok ? r.number("avg_speed") : NAN;
      if (run == "flat_high") m.v_flat_high = v;
      else if (run == "flat_low") m.v_flat_low = v;
      else if (run == "stair_0") { m.v_stair0 = v; m.t_body_past0 = ok ? r.number("t_body_past") : NAN; }
      else if (run == "stair_kc") { m.v_stair_kc = v; m.t_body_past_kc = ok ? r.number("t_body_past") : NAN; }
      else if (run == "friction") {
        m.peak_change = ok ? r.number("peak_change") : NAN;
        if (ok) {
          m.peaks_before = static_cast<int>(r.integer("peaks_before"));
          m.peaks_after = static_cast<int>(r.integer("peaks_after"));
        }
      }
    }
    out.push_back(m);
  }
  if (settings_.log)
    *settings_.log << "  " << label << ": " << points.size() << " point(s), " << todo.size()
                   << " simulation(s) run, " << cache_.size() << " cached\n";
  return out;
}

std::vector<double> Evaluator::residuals(const Measures& m) const {
  std::vector<double> r;
  for (const Target& t : targets_.list) {
    const double v = m.get(t.measure);
    r.push_back(std::isfinite(v) ? (v - t.value) / t.tolerance : kFailedResidual);
  }
  return r;
}

std::vector<std::pair<std::string, std::string>> Evaluator::fitted_scene_yaml(const Point& p) const {
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& [name, text] : scene_text_) {
    YAML::Node n = YAML::Load(text);
    for (std::size_t i = 0; i < params_.size(); ++i) {
      const ParamDef& d = *params_[i].def;
      if (d.section == "obstacles") {
        if (n["obstacles"])
          for (std::size_t b = 0; b < n["obstacles"].size(); ++b) n["obstacles"][b][d.key] = p[i];
        continue;
      }
      if (d.name == "module_size") continue;  // below: the key the shape uses
      if (d.choices.empty()) n[d.section][d.key] = p[i];
      else if (d.name == "friction_at") n[d.section][d.key] = std::lround(p[i]) == 1;
      else n[d.section][d.key] = d.choices[static_cast<std::size_t>(std::lround(p[i]))];
    }
    for (std::size_t i = 0; i < params_.size(); ++i) {
      if (params_[i].def->name != "module_size") continue;
      // The shape after the point (fitted or the scene's own): capsule → link_radius, box → link_height.
      model::Scene sc = config::parse_scene(text, name);
      for (std::size_t j = 0; j < params_.size(); ++j) params_[j].def->apply(sc, p[j]);
      if (sc.robot.link_shape == model::LinkShape::kCapsule) n["robot"]["link_radius"] = sc.robot.link_radius;
      if (sc.robot.link_shape == model::LinkShape::kBox) n["robot"]["link_height"] = sc.robot.link_height;
    }
    const std::string stem = fs::path(name).stem().string();
    n["name"] = "paper_fit_" + stem;
    n["description"] = (n["description"] ? n["description"].as<std::string>() + "; " : std::string()) +
                       "parameters fitted by pedalwave_identify";
    YAML::Emitter e;
    e.SetDoublePrecision(6);
    e << n;
    out.emplace_back(stem, std::string(e.c_str()) + "\n");
  }
  return out;
}

// ---- the fit ----------------------------------------------------------------------------------------
namespace {

struct Ctx {
  Evaluator* ev;
  Point base;
  std::vector<std::size_t> dims;
  double best = INFINITY;
  Point best_p;
  std::string error;
  int n = 0;
};

double objective(unsigned n, const double* z, double* grad, void* data) {
  auto* c = static_cast<Ctx*>(data);
  (void)grad;  // derivative-free
  try {
    Point p = c->base;
    for (unsigned i = 0; i < n; ++i) p[c->dims[i]] = from_z(c->ev->params()[c->dims[i]], z[i]);
    const Measures m = c->ev->evaluate({p}, "local step " + std::to_string(++c->n)).front();
    const double f = cost_of(c->ev->residuals(m));
    if (f < c->best) {
      c->best = f;
      c->best_p = p;
    }
    if (c->ev->settings().log) *c->ev->settings().log << "    cost " << fmt(f) << ", best " << fmt(c->best) << '\n';
    return f;
  } catch (const std::exception& e) {
    c->error = e.what();
    return HUGE_VAL;
  }
}

}  // namespace

FitResult fit(Evaluator& ev) {
  const auto& ps = ev.params();
  const FitSettings& s = ev.settings();
  const std::vector<std::size_t> dims = continuous_dims(ps);
  // Choice combinations (cartesian product of the allowed indices).
  std::vector<std::vector<int>> combos{{}};
  for (const FitParam& p : ps)
    if (p.is_choice()) {
      std::vector<std::vector<int>> next;
      for (const auto& c : combos)
        for (int k : p.choices) {
          auto d = c;
          d.push_back(k);
          next.push_back(d);
        }
      combos = next;
    }
  FitResult out;
  out.cost = INFINITY;
  static const int kPrimes[] = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37};
  for (const auto& combo : combos) {
    std::string label;
    {
      std::size_t c = 0;
      for (const FitParam& p : ps)
        if (p.is_choice())
          label += (label.empty() ? "" : ", ") + p.def->name + " = " + p.def->choices[static_cast<std::size_t>(combo[c++])];
      if (label.empty()) label = "continuous parameters only";
    }
    if (s.log) *s.log << "== " << label << '\n';
    // Global stage: the start and quasi-random points, one batch.
    std::vector<Point> pts{ev.start_point(combo)};
    for (int k = 1; k < s.starts; ++k) {
      Point p = pts.front();
      for (std::size_t i = 0; i < dims.size(); ++i)
        p[dims[i]] = from_z(ps[dims[i]], halton(static_cast<std::size_t>(k), kPrimes[i % 12]));
      pts.push_back(p);
    }
    const std::vector<Measures> ms = ev.evaluate(pts, "starts");
    std::size_t bi = 0;
    double bc = INFINITY;
    for (std::size_t k = 0; k < pts.size(); ++k) {
      const double c = cost_of(ev.residuals(ms[k]));
      if (c < bc) bc = c, bi = k;
    }
    Ctx ctx{&ev, pts[bi], dims, bc, pts[bi], "", 0};
    std::string status = "no continuous parameter";
    if (!dims.empty() && s.max_evals > 0) {
      nlopt_opt opt = nlopt_create(dims.size() >= 2 ? NLOPT_LN_BOBYQA : NLOPT_LN_SBPLX, static_cast<unsigned>(dims.size()));
      std::vector<double> lb(dims.size(), 0.0), ub(dims.size(), 1.0), z(dims.size()), step(dims.size(), 0.1);
      for (std::size_t i = 0; i < dims.size(); ++i) z[i] = std::clamp(to_z(ps[dims[i]], pts[bi][dims[i]]), 0.0, 1.0);
      nlopt_set_lower_bounds(opt, lb.data());
      nlopt_set_upper_bounds(opt, ub.data());
      nlopt_set_min_objective(opt, objective, &ctx);
      nlopt_set_maxeval(opt, s.max_evals);
      nlopt_set_xtol_abs1(opt, s.xtol);
      nlopt_set_initial_step(opt, step.data());
      double f = 0;
      const nlopt_result res = nlopt_optimize(opt, z.data(), &f);
      nlopt_destroy(opt);
      if (!ctx.error.empty()) throw std::runtime_error(ctx.error);
      switch (res) {
        case NLOPT_MAXEVAL_REACHED: status = "evaluation budget reached"; break;
        case NLOPT_XTOL_REACHED: status = "step below xtol"; break;
        case NLOPT_FTOL_REACHED: status = "ftol reached"; break;
        case NLOPT_SUCCESS: status = "converged"; break;
        case NLOPT_ROUNDOFF_LIMITED: status = "roundoff limited"; break;
        default: status = "nlopt code " + std::to_string(static_cast<int>(res)); break;
      }
    }
    if (s.log) *s.log << "  best cost " << fmt(ctx.best) << " (" << status << ")\n";
    out.combos.emplace_back(label, ctx.best);
    if (ctx.best < out.cost) {
      out.cost = ctx.best;
      out.best = ctx.best_p;
      out.nlopt_status = status;
    }
  }
  out.measures = ev.evaluate({out.best}, "best").front();
  out.residuals = ev.residuals(out.measures);
  analyse(ev, out);
  return out;
}

void analyse(Evaluator& ev, FitResult& r) {
  const auto& ps = ev.params();
  const std::vector<std::size_t> dims = continuous_dims(ps);
  const std::size_t m = ev.targets().list.size(), n = dims.size();
  const double h = ev.settings().fd_step;
  std::vector<Point> pts;
  std::vector<double> zlo(n), zhi(n);
  for (std::size_t i = 0; i < n; ++i) {
    const FitParam& p = ps[dims[i]];
    const double z = to_z(p, r.best[dims[i]]);
    zlo[i] = std::max(0.0, z - h);
    zhi[i] = std::min(1.0, z + h);
    Point a = r.best, b = r.best;
    a[dims[i]] = from_z(p, zlo[i]);
    b[dims[i]] = from_z(p, zhi[i]);
    pts.push_back(a);
    pts.push_back(b);
  }
  const std::vector<Measures> ms = ev.evaluate(pts, "sensitivities");
  Eigen::MatrixXd J(m, n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto ra = ev.residuals(ms[2 * i]), rb = ev.residuals(ms[2 * i + 1]);
    for (std::size_t k = 0; k < m; ++k)
      J(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(i)) = (rb[k] - ra[k]) / (zhi[i] - zlo[i]);
  }
  r.params.clear();
  for (std::size_t i = 0; i < ps.size(); ++i) {
    ParamReport pr;
    pr.name = ps[i].def->name;
    pr.unit = ps[i].def->unit;
    pr.value = r.best[i];
    if (ps[i].is_choice()) {
      pr.word = ps[i].def->choices[static_cast<std::size_t>(std::lround(r.best[i]))];
    } else {
      pr.lo = ps[i].lo;
      pr.hi = ps[i].hi;
      const double z = to_z(ps[i], r.best[i]);
      pr.at_bound = z < 0.01 || z > 0.99;
    }
    r.params.push_back(pr);
  }
  if (n == 0) return;
  // Sensitivity: the measure's change for +10 % of the parameter.
  for (std::size_t i = 0; i < n; ++i) {
    const FitParam& p = ps[dims[i]];
    const double dz = p.def->log_scale ? std::log(1.1) / (std::log(p.hi) - std::log(p.lo))
                                       : 0.1 * std::abs(r.best[dims[i]]) / (p.hi - p.lo);
    for (std::size_t k = 0; k < m; ++k)
      r.params[dims[i]].sensitivity.push_back(J(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(i)) * dz *
                                              ev.targets().list[k].tolerance);
  }
  // Determinacy: J = U S Vᵀ; cov_z ≈ (JᵀJ)⁻¹ (residuals in units of the targets' tolerances).
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  const Eigen::MatrixXd V = svd.matrixV();
  r.singular_values.assign(sv.data(), sv.data() + sv.size());
  const double smax = sv.size() > 0 ? sv(0) : 0.0;
  std::vector<bool> null_dir(n, false);
  for (std::size_t k = 0; k < n; ++k) {
    const double s = static_cast<Eigen::Index>(k) < sv.size() ? sv(static_cast<Eigen::Index>(k)) : 0.0;
    if (s > 1e-3 * smax && s > 0) continue;
    null_dir[k] = true;
    // The direction, by its largest components.
    std::vector<std::pair<double, std::size_t>> comp;
    for (std::size_t i = 0; i < n; ++i) comp.emplace_back(std::abs(V(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k))), i);
    std::sort(comp.rbegin(), comp.rend());
    std::string d;
    for (std::size_t c = 0; c < comp.size() && c < 3 && comp[c].first > 0.2; ++c) {
      const double v = V(static_cast<Eigen::Index>(comp[c].second), static_cast<Eigen::Index>(k));
      d += (c ? " " : "") + std::string(v < 0 ? "−" : (c ? "+" : "")) + fmt(std::abs(v), 2) + "·" +
           ps[dims[comp[c].second]].def->name;
    }
    r.undetermined.push_back(d + (s > 0 ? " (σ = " + fmt(s, 2) + ")" : " (no target moves it)"));
  }
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  for (std::size_t k = 0; k < n; ++k)
    if (!null_dir[k]) {
      const Eigen::VectorXd v = V.col(static_cast<Eigen::Index>(k));
      const double s = sv(static_cast<Eigen::Index>(k));
      cov += v * v.transpose() / (s * s);
    }
  for (std::size_t i = 0; i < n; ++i) {
    bool undet = false;
    for (std::size_t k = 0; k < n; ++k)
      if (null_dir[k] && std::abs(V(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k))) > 0.2) undet = true;
    if (undet) continue;
    const FitParam& p = ps[dims[i]];
    const double sz = std::sqrt(cov(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i)));
    const double v = r.best[dims[i]];
    if (p.def->log_scale) {
      const double f = std::exp(sz * (std::log(p.hi) - std::log(p.lo)));
      r.params[dims[i]].sigma_lo = v / f;
      r.params[dims[i]].sigma_hi = v * f;
    } else {
      r.params[dims[i]].sigma_lo = v - sz * (p.hi - p.lo);
      r.params[dims[i]].sigma_hi = v + sz * (p.hi - p.lo);
    }
  }
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) {
      // Pairs among the determined parameters only (an undetermined one has no finite variance).
      if (!std::isfinite(r.params[dims[i]].sigma_lo) || !std::isfinite(r.params[dims[j]].sigma_lo)) continue;
      const double c = cov(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
      const double d = std::sqrt(cov(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i)) *
                                 cov(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(j)));
      if (d > 0 && std::abs(c / d) > 0.9)
        r.correlated.push_back(ps[dims[i]].def->name + " ~ " + ps[dims[j]].def->name + ": ρ = " + fmt(c / d, 3));
    }
  r.evaluations = ev.evaluations();
  r.simulations = ev.simulations_run();
  r.cache_hits = ev.cache_hits();
}

// ---- reports ----------------------------------------------------------------------------------------
toolkit::Json to_json(const Evaluator& ev, const FitResult& r) {
  using toolkit::Json;
  Json j = Json::object();
  j.set("cost", r.cost);
  j.set("local_search", r.nlopt_status);
  Json h = Json::object();
  h.set("flat_s", ev.settings().horizon.flat).set("friction_s", ev.settings().horizon.friction)
      .set("stair_s", ev.settings().horizon.stair);
  j.set("horizon", h);
  j.set("k_c", ev.targets().k_c);
  Json ts = Json::array();
  for (std::size_t k = 0; k < ev.targets().list.size(); ++k) {
    const Target& t = ev.targets().list[k];
    Json x = Json::object();
    x.set("measure", to_string(t.measure)).set("target", t.value).set("model", r.measures.get(t.measure))
        .set("tolerance", t.tolerance).set("residual", r.residuals[k]).set("source", t.source);
    ts.push(x);
  }
  j.set("targets", ts);
  Json pa = Json::array();
  for (const ParamReport& p : r.params) {
    Json x = Json::object();
    x.set("name", p.name).set("unit", p.unit);
    if (!p.word.empty()) x.set("value", p.word);
    else {
      x.set("value", p.value).set("min", p.lo).set("max", p.hi).set("at_bound", p.at_bound)
          .set("sigma_lo", p.sigma_lo).set("sigma_hi", p.sigma_hi);
      Json s = Json::object();
      for (std::size_t k = 0; k < p.sensitivity.size(); ++k)
        s.set(to_string(ev.targets().list[k].measure), p.sensitivity[k]);
      x.set("sensitivity_per_10pct", s);
    }
    pa.push(x);
  }
  j.set("parameters", pa);
  Json sv = Json::array();
  for (double v : r.singular_values) sv.push(v);
  j.set("singular_values", sv);
  Json c = Json::array();
  for (const auto& x : r.correlated) c.push(x);
  j.set("correlated", c);
  Json u = Json::array();
  for (const auto& x : r.undetermined) u.push(x);
  j.set("undetermined", u);
  Json co = Json::array();
  for (const auto& [l, v] : r.combos) {
    Json x = Json::object();
    x.set("choices", l).set("cost", v);
    co.push(x);
  }
  j.set("choice_combinations", co);
  Json st = Json::object();
  st.set("evaluations", r.evaluations).set("simulations", r.simulations).set("cache_hits", r.cache_hits);
  j.set("work", st);
  Json ms = Json::object();
  ms.set("stair_body_past_s_kc0", r.measures.t_body_past0).set("stair_body_past_s_kc", r.measures.t_body_past_kc)
      .set("peaks_before", r.measures.peaks_before).set("peaks_after", r.measures.peaks_after);
  j.set("events", ms);
  return j;
}

std::string report_text(const Evaluator& ev, const FitResult& r) {
  std::ostringstream os;
  auto shown = [](Measure m, double v) {
    return m == Measure::flat_speed || m == Measure::stair_speed ? fmt(100 * v, 3) + " cm/s"
                                                                  : (v >= 0 ? "+" : "") + fmt(100 * v, 3) + " %";
  };
  toolkit::Table t({"target", "figure", "model", "tolerance", "residual"});
  for (std::size_t k = 0; k < ev.targets().list.size(); ++k) {
    const Target& x = ev.targets().list[k];
    const double v = r.measures.get(x.measure);
    t.add_row({to_string(x.measure), shown(x.measure, x.value), shown(x.measure, v),
               x.measure == Measure::flat_speed || x.measure == Measure::stair_speed ? fmt(100 * x.tolerance, 3) + " cm/s"
                                                                                     : fmt(100 * x.tolerance, 3) + " %",
               fmt(r.residuals[k], 3)});
  }
  os << "Targets (cost ½Σr² = " << fmt(r.cost) << ", local search: " << r.nlopt_status << ")\n" << t.to_markdown() << '\n';
  std::vector<std::string> head{"parameter", "fit", "bounds", "±1σ (approx.)"};
  for (const Target& x : ev.targets().list) head.push_back(std::string("Δ") + to_string(x.measure) + " /+10 %");
  toolkit::Table p(head);
  for (const ParamReport& x : r.params) {
    std::vector<std::string> row{x.name};
    if (!x.word.empty()) {
      row.insert(row.end(), {x.word, "choice", "—"});
      for (std::size_t k = 0; k < ev.targets().list.size(); ++k) row.push_back("—");
    } else {
      row.push_back(fmt(x.value) + (x.unit.empty() ? "" : " " + x.unit) + (x.at_bound ? " (at bound)" : ""));
      row.push_back("[" + fmt(x.lo, 3) + ", " + fmt(x.hi, 3) + "]");
      row.push_back(std::isfinite(x.sigma_lo) ? fmt(x.sigma_lo, 3) + " … " + fmt(x.sigma_hi, 3) : "undetermined");
      for (std::size_t k = 0; k < x.sensitivity.size(); ++k) {
        const Measure m = ev.targets().list[k].measure;
        row.push_back(m == Measure::flat_speed || m == Measure::stair_speed ? fmt(100 * x.sensitivity[k], 2) + " cm/s"
                                                                           : fmt(100 * x.sensitivity[k], 2) + " pt");
      }
    }
    p.add_row(row);
  }
  os << "Parameters (sensitivity: change of each figure for +10 % of the parameter, central differences)\n"
     << p.to_markdown() << '\n';
  os << "Singular values of the residual Jacobian (normalized parameters):";
  for (double v : r.singular_values) os << ' ' << fmt(v, 3);
  os << "\nCorrelated pairs (|ρ| > 0.9):" << (r.correlated.empty() ? " none" : "");
  for (const auto& c : r.correlated) os << "\n  " << c;
  os << "\nUndetermined directions (σ < 1e-3 σ_max):" << (r.undetermined.empty() ? " none" : "");
  for (const auto& c : r.undetermined) os << "\n  " << c;
  os << "\nStair: whole body past the box at k_c = 0: "
     << (std::isfinite(r.measures.t_body_past0) ? fmt(r.measures.t_body_past0, 3) + " s" : "never")
     << ", at k_c = " << fmt(ev.targets().k_c, 3) << ": "
     << (std::isfinite(r.measures.t_body_past_kc) ? fmt(r.measures.t_body_past_kc, 3) + " s" : "never") << '\n';
  os << "Choice combinations:";
  for (const auto& [l, v] : r.combos) os << "\n  " << l << ": cost " << fmt(v);
  os << "\nWork: " << r.evaluations << " evaluations, " << r.simulations << " simulations run, " << r.cache_hits
     << " taken from the cache\n";
  return os.str();
}

}  // namespace pedalwave::identify
