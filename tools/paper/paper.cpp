#include "paper.hpp"

#include "pedalwave/model/lanes.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/toolkit/body_csv.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "pedalwave/toolkit/progress.hpp"
#include "pedalwave/toolkit/report_template.hpp"
#include "pedalwave/toolkit/table.hpp"

namespace pedalwave::paper {

namespace tk = pedalwave::toolkit;
namespace fs = std::filesystem;

namespace {

std::ostream& log(const Settings& s) { return s.log ? *s.log : std::cout; }

// The toolkit's formatter (toolkit/format.hpp), "—" for a missing value.
std::string fmt(double v, int precision = 3) { return std::isnan(v) ? "—" : tk::sig(v, precision); }
// Fixed decimals.
std::string fixed(double v, int decimals) { return std::isnan(v) ? "—" : tk::fixed(v, decimals); }
// Speed in cm/s: 2 decimals, 3 below 1 cm/s (the stair's stuck runs differ in the third).
std::string cms(double v) {
  if (std::isnan(v)) return "—";
  return fixed(v * 100.0, std::abs(v) < 0.01 ? 3 : 2) + " cm/s";
}
std::string pct(double v) {
  if (std::isnan(v)) return "—";
  return (v >= 0 ? "+" : "") + fixed(v * 100.0, 1) + " %";
}
std::string secs(double t) { return std::isnan(t) ? "never" : fixed(t, 1) + " s"; }
std::string kc_tag(double k_c) { return "kc" + fmt(k_c, 4); }

void write_text(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path().empty() ? fs::path(".") : p.parent_path());
  std::ofstream f(p);
  f << text;
  if (!f) throw std::runtime_error("cannot write " + p.string());
}

std::string describe(const model::IntegratorOptions& i) {
  return std::string(model::to_string(i.method)) + ", h = " + fmt(i.h) + " s";
}

std::string describe_integ(const Settings& s, const model::Scene& sc) { return describe(integ_of(s, sc)); }

// " --scene-prefix P" when the scenes are not the shipped ones (commands in the Markdown).
std::string prefix_arg(const Settings& s) {
  return s.scene_prefix.empty() ? std::string() : " --scene-prefix " + s.scene_prefix;
}
// " --stair-scene NAME" when the box scene is not the shipped stair (commands in the Markdown).
std::string stair_arg(const Settings& s) {
  return prefix_arg(s) + (s.stair_scene == "stair" ? std::string() : " --stair-scene " + s.stair_scene);
}

// Runs the specs over s.jobs threads with a progress bar; results in spec order.
std::vector<RunResult> run_all(const Settings& s, const std::vector<RunSpec>& specs,
                               const std::string& label, double* wall_s = nullptr) {
  std::vector<RunResult> out(specs.size());
  tk::Progress progress(label, specs.size(),
                        tk::Progress::Options{.style = s.progress ? tk::Progress::Style::automatic
                                                                  : tk::Progress::Style::silent});
  const auto w0 = std::chrono::steady_clock::now();
  parallel_for(
      specs.size(), s.jobs, [&](std::size_t i) { out[i] = run(specs[i]); },
      [&]() { progress.advance(); });
  if (wall_s) *wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  progress.finish();
  return out;
}

// Runs of `base` at each gain of `k_c` as a campaign of groups of up to Settings::group
// consecutive gains (run_group: in lockstep lanes where Settings::lanes, the machine and the scene
// allow), the results in k_c's order.
std::vector<RunResult> run_group_campaign(const Settings& s, const RunSpec& base, const std::vector<double>& k_c,
                                          const std::string& name, const std::string& scene_name,
                                          const std::string& scene_text, double* wall_s = nullptr) {
  std::vector<std::string> lines;
  const auto group = static_cast<std::size_t>(std::max(1, s.group));
  for (std::size_t i = 0; i < k_c.size(); i += group) {
    const std::vector<double> g(k_c.begin() + static_cast<std::ptrdiff_t>(i),
                                k_c.begin() + static_cast<std::ptrdiff_t>(std::min(k_c.size(), i + group)));
    lines.push_back(encode_group(base, g, s.lanes, scene_name, scene_text));
  }
  campaign::Options o = s.campaign;
  o.jobs = s.jobs;
  o.progress = s.progress;
  if (o.slurm.dir.empty()) o.slurm.dir = s.out_dir / "campaign";
  const auto w0 = std::chrono::steady_clock::now();
  const std::vector<std::string> res = campaign::run(name, lines, run_line, o);
  if (wall_s) *wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  std::vector<RunResult> out;
  out.reserve(k_c.size());
  for (const std::string& r : res)
    for (RunResult& x : decode_group_result(r)) out.push_back(std::move(x));
  if (out.size() != k_c.size())
    throw std::runtime_error("campaign " + name + ": " + std::to_string(out.size()) + " results for " +
                             std::to_string(k_c.size()) + " runs");
  return out;
}

// How the sweep's runs are stepped, for the console: "8 at a time in AVX-512 lanes" or why not.
std::string lanes_note(const Settings& s, const RunSpec& base) {
  if (!s.lanes) return "one by one (--no-lanes)";
  const std::string why = lockstep_refusal(base);
  if (!why.empty()) return "one by one (not in lanes: " + why + ")";
  const int w = model::LanePlant::machine_width();
  return std::to_string(s.group) + " at a time in lockstep, " + std::to_string(w) + " per SIMD vector (" +
         (w == 8 ? "AVX-512" : "AVX2") + ")";
}

// The campaign name of a sweep over the box scene (its folder under the campaign dir): "sweep"
// for the shipped stair, else "sweep-<scene>" (path characters replaced), so that `all`'s two
// sweeps never share a folder.
std::string sweep_campaign(const Settings& s, const std::string& what) {
  if (s.stair_scene == "stair") return what;
  std::string tag;
  for (char c : s.stair_scene) tag += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' ? c : '_';
  return what + "-" + tag;
}

std::string read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream os;
  os << f.rdbuf();
  if (!f) throw std::runtime_error("cannot read " + p.string());
  return os.str();
}

RunSpec make_spec(const Settings& s, model::Scene scene, double duration, double k_c,
                  double sample_every) {
  if (duration > 0) scene.duration = duration;
  RunSpec r;
  r.scene = std::move(scene);
  r.k_c = k_c;
  r.integ = integ_of(s, r.scene);
  r.rate_hz = s.rate_hz;
  r.sample_every = sample_every;
  return r;
}

// The report's templates (tools/paper/report/*.md.in): the source tree's while it exists, else the
// installed ones beside the figure scripts, <figures>/paper_report (runtime/deploy/CMakeLists.txt).
fs::path report_template(const std::string& name) {
  return tk::pick_figures_dir(fs::path(PEDALWAVE_PAPER_SOURCE_DIR) / "report", tk::figures_dir() / "paper_report") / name;
}

// The console summary's prose: a template of report/console/*.txt.in filled with the tool's values
// (the report's mechanism, toolkit/report_template.hpp) and printed.
void say(const Settings& s, const std::string& name, const std::map<std::string, std::string>& values) {
  log(s) << tk::fill_template(report_template("console/" + name), values);
}
// A number as an ostream prints it by default (the console's durations and positions).
std::string plain(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}
void say_stopped(const Settings& s, const RunResult& r) {
  if (r.status != model::StepStatus::kOk)
    say(s, "run_stopped.txt.in", {{"t_end", plain(r.t_end)}, {"status", std::string(model::to_string(r.status))}});
}

// One Markdown table row ("| a | b |", '|' in a cell escaped) for a template's {{rows}}.
std::string markdown_row(const std::vector<std::string>& cells) {
  std::string out = "|";
  for (const std::string& c : cells) {
    out += ' ';
    for (char ch : c) out += ch == '|' ? std::string("\\|") : std::string(1, ch);
    out += " |";
  }
  return out;
}

// Fills a report template and lines up its tables; rows: the body rows of its first table.
std::string fill_report(const std::string& name, const std::map<std::string, std::string>& values,
                        std::size_t* rows = nullptr) {
  std::vector<std::size_t> per_table;
  std::string md = tk::align_markdown_tables(tk::fill_template(report_template(name), values), &per_table);
  if (rows) *rows = per_table.empty() ? 0 : per_table.front();
  return md;
}

// ---- The figures' data: <out>/data/<figure>.json (what tools/figures/paper.py draws, its kind and
// numbers) and the CSVs it names (traces). draw() runs the script on a list of figures.

fs::path data_dir(const Settings& s) { return s.out_dir / "data"; }

void write_figure(const Settings& s, const std::string& name, tk::Json spec) {
  fs::create_directories(data_dir(s));
  write_text(data_dir(s) / (name + ".json"), spec.dump(2) + "\n");
}

// A run's trace as CSV (t, COM, head and tail tips, the head joint's torque and η, and the body
// points when sampled); returns its file name in the data folder.
std::string write_trace(const Settings& s, const std::string& name, const Trace& tr) {
  const std::size_t P = tr.body_x.empty() ? 0 : tr.body_x.front().size();
  const std::string file = name + ".csv";
  tk::BodyPointsCsv csv(data_dir(s) / file,
                        {"t", "com_x", "com_z", "head_x", "head_z", "tail_x", "tail_z", "tau_head", "eta_head"}, P);
  for (std::size_t i = 0; i < tr.t.size(); ++i) {
    csv.row({tr.t[i], tr.com_x[i], tr.com_z[i], tr.head_x[i], tr.head_z[i], tr.tail_x[i], tr.tail_z[i],
             tr.tau_head[i], tr.eta_head[i]},
            P ? std::span<const double>(tr.body_x[i]) : std::span<const double>(),
            P ? std::span<const double>(tr.body_z[i]) : std::span<const double>());
  }
  csv.close();
  return file;
}

tk::Json numbers(const std::vector<double>& v) {
  tk::Json a = tk::Json::array();
  for (double x : v) a.push(x);
  return a;
}

tk::Json scene_json(const model::Scene& sc) {
  tk::Json boxes = tk::Json::array(), patches = tk::Json::array();
  for (const model::Box& b : sc.boxes)
    boxes.push(tk::Json::object()
                   .set("x0", b.x_near).set("x1", b.x_near + b.width)
                   .set("z0", sc.ground.z).set("z1", sc.ground.z + b.height));
  for (const auto& p : sc.ground.patches) patches.push(tk::Json::object().set("x_begin", p.x_begin).set("mu", p.mu));
  return tk::Json::object()
      .set("ground_z", sc.ground_on ? tk::Json(sc.ground.z) : tk::Json())
      .set("boxes", std::move(boxes))
      .set("patches", std::move(patches));
}

// Draws the figures (tools/figures/paper.py) whose data/<name>.json were written.
void draw(const Settings& s, const std::vector<std::string>& names) {
  if (!s.plots || names.empty()) return;
  std::vector<std::string> args{s.out_dir.string()};
  args.insert(args.end(), names.begin(), names.end());
  const tk::FigureOutcome r = tk::draw_figures("paper.py", args);
  if (r.status == tk::FigureOutcome::Status::drawn)
    say(s, "figures.txt.in", {{"message", r.message}});
  else  // loudly, also with --quiet: the data are written, the figures are not
    std::cerr << "pedalwave_paper: " << r.message << '\n';
}

// The negative torque peaks of a friction run, split at the head's crossing.
struct PeakSplit {
  std::vector<double> t_before, before, t_after, after;
  double mean_before = kNaN, mean_after = kNaN, change = kNaN;
};
PeakSplit split_peaks(const RunResult& r, double period, double t_cross) {
  PeakSplit p;
  const Trace& tr = r.trace;
  for (std::size_t i : negative_peaks(tr.t, tr.tau_head, period)) {
    const double t = tr.t[i];
    if (t < period) continue;  // the first gait period: start-up transient
    if (std::isnan(t_cross) || t < t_cross) {
      p.t_before.push_back(t);
      p.before.push_back(tr.tau_head[i]);
    } else {
      p.t_after.push_back(t);
      p.after.push_back(tr.tau_head[i]);
    }
  }
  auto mean_abs = [](const std::vector<double>& v) {
    if (v.empty()) return kNaN;
    double s = 0;
    for (double x : v) s += std::abs(x);
    return s / static_cast<double>(v.size());
  };
  p.mean_before = mean_abs(p.before);
  p.mean_after = mean_abs(p.after);
  p.change = p.mean_after / p.mean_before - 1.0;
  return p;
}

double patch_x(const model::Scene& sc) {
  if (sc.ground.patches.empty())
    throw std::invalid_argument("scene " + sc.name + ": expected a ground patch (the friction change)");
  return sc.ground.patches.front().x_begin;
}

}  // namespace

std::filesystem::path scene_file(const Settings& s, const std::string& name) {
  // A path (a folder in it, or a .yaml name) is taken as given: /path/x.yaml, not x.yaml.yaml.
  if (name.find('/') != std::string::npos || name.ends_with(".yaml")) return name;
  return s.scenes_dir / (s.scene_prefix + name + ".yaml");
}

model::Scene load(const Settings& s, const std::string& name) {
  // The paper's runs inject no faults: a scene with a faults: list is refused.
  return config::load_scene(scene_file(s, name).string(), {.faults = false, .consumer = "pedalwave_paper"});
}

model::IntegratorOptions integ_of(const Settings& s, const model::Scene& scene) {
  return s.integ ? *s.integ : scene.integrator;
}

// ================================================================================================
FlatResult flat(const Settings& s, double duration) {
  const model::Scene hi = load(s, "flat_high_friction");
  say(s, "flat_start.txt.in", {{"duration", plain(duration)}, {"integrator", describe_integ(s, hi)}});
  std::vector<RunSpec> specs{make_spec(s, hi, duration, 0.0, 0.05),
                             make_spec(s, load(s, "flat_low_friction"), duration, 0.0, 0.05)};
  const auto res = run_all(s, specs, "flat");
  FlatResult f;
  f.duration = duration;
  f.avg_from = res[0].avg_from;
  f.v_high = res[0].avg_speed;
  f.v_low = res[1].avg_speed;
  f.ratio = f.v_high / f.v_low;
  f.gain = f.ratio - 1.0;
  for (const auto& r : res) say_stopped(s, r);
  say(s, "flat.txt.in", {{"v_high", cms(f.v_high)},
                         {"v_low", cms(f.v_low)},
                         {"ratio", fmt(f.ratio, 4)},
                         {"gain", pct(f.gain)},
                         {"avg_from", fmt(f.avg_from)},
                         {"duration", fmt(duration)}});

  if (s.plots) {
    tk::Json runs = tk::Json::array();
    runs.push(tk::Json::object().set("label", "μ = 0.82: " + cms(f.v_high)).set("csv", write_trace(s, "flat_high", res[0].trace)));
    runs.push(tk::Json::object().set("label", "μ = 0.40: " + cms(f.v_low)).set("csv", write_trace(s, "flat_low", res[1].trace)));
    write_figure(s, "flat_com", tk::Json::object().set("kind", "flat_com").set("avg_from", f.avg_from).set("runs", std::move(runs)));
    draw(s, {"flat_com"});
  }
  f.markdown = fill_report("flat.md.in", {{"args", prefix_arg(s)},
                                           {"avg_from", fmt(f.avg_from)},
                                           {"duration", fmt(duration)},
                                           {"integrator", describe(specs[0].integ)},
                                           {"rate_hz", fmt(s.rate_hz)},
                                           {"v_high", cms(f.v_high)},
                                           {"v_low", cms(f.v_low)},
                                           {"gain", pct(f.gain)}});
  write_text(s.out_dir / "flat.md", f.markdown);
  return f;
}

// ================================================================================================
FrictionResult friction(const Settings& s, double duration) {
  model::Scene sc = load(s, "friction_change");
  FrictionResult f;
  f.duration = duration > 0 ? duration : sc.duration;
  f.cross_x = patch_x(sc);
  say(s, "friction_start.txt.in", {{"mu_after", plain(sc.ground.patches.front().mu)},
                                   {"cross_x", plain(f.cross_x)},
                                   {"duration", plain(f.duration)},
                                   {"integrator", describe_integ(s, sc)}});
  RunSpec spec = make_spec(s, sc, f.duration, 0.0, 0.005);
  spec.cross_x = f.cross_x;
  const RunResult r = run_all(s, {spec}, "friction").front();
  say_stopped(s, r);
  const double period = gait_period(sc);
  f.t_cross = r.t_head_cross;
  const PeakSplit p = split_peaks(r, period, f.t_cross);
  f.peak_t_before = p.t_before;
  f.peak_before = p.before;
  f.peak_t_after = p.t_after;
  f.peak_after = p.after;
  f.mean_before = p.mean_before;
  f.mean_after = p.mean_after;
  f.change = p.change;
  say(s, "friction.txt.in", {{"cross_x", plain(f.cross_x)},
                             {"t_cross", secs(f.t_cross)},
                             {"period", fmt(period)},
                             {"peaks_before", std::to_string(p.before.size())},
                             {"peaks_after", std::to_string(p.after.size())},
                             {"mean_before", fmt(f.mean_before, 4)},
                             {"mean_after", fmt(f.mean_after, 4)},
                             {"change", pct(f.change)}});

  if (s.plots) {
    tk::Json fig = tk::Json::object();
    fig.set("kind", "friction_torque").set("trace", write_trace(s, "friction", r.trace));
    fig.set("t_cross", f.t_cross).set("cross_x", f.cross_x);
    fig.set("peaks_before", tk::Json::object().set("t", numbers(p.t_before)).set("tau", numbers(p.before)));
    fig.set("peaks_after", tk::Json::object().set("t", numbers(p.t_after)).set("tau", numbers(p.after)));
    fig.set("mean_before", f.mean_before).set("mean_after", f.mean_after).set("change_label", pct(f.change));
    write_figure(s, "friction_torque", std::move(fig));
    draw(s, {"friction_torque"});
  }
  f.markdown = fill_report("friction.md.in", {{"args", prefix_arg(s)},
                                               {"scene", s.scene_prefix + "friction_change"},
                                               {"mu_after", fmt(sc.ground.patches.front().mu, 2)},
                                               {"cross_x", fmt(f.cross_x)},
                                               {"duration", fmt(f.duration)},
                                               {"integrator", describe_integ(s, sc)},
                                               {"t_cross", secs(f.t_cross)},
                                               {"peaks_before", std::to_string(p.before.size())},
                                               {"peaks_after", std::to_string(p.after.size())},
                                               {"mean_before", fmt(f.mean_before, 4)},
                                               {"mean_after", fmt(f.mean_after, 4)},
                                               {"change", pct(f.change)}});
  write_text(s.out_dir / "friction.md", f.markdown);
  return f;
}

// ================================================================================================
namespace {

// The data of stair_shapes_<tag> and stair_film_<tag>: the run's trace, the climb window and the
// snapshot period, the box and its events; returns the figure name.
std::string stair_figure(const Settings& s, const StairCase& c, double snapshot_every) {
  const RunResult& r = c.run;
  const Trace& tr = r.trace;
  if (tr.t.empty()) return {};
  const double T = tr.t.back();
  const StairEvents& e = r.stair;
  // The climb window: until a few seconds after the whole body passed, or the whole run.
  const double t_hi = std::isnan(e.t_body_past) ? T : std::min(T, e.t_body_past + 3.0);
  const std::string tag = kc_tag(c.k_c);
  tk::Json spec = tk::Json::object();
  spec.set("kind", "stair").set("tag", tag).set("k_c", c.k_c).set("trace", write_trace(s, "stair_" + tag, tr));
  spec.set("t_hi", t_hi).set("every", std::max(snapshot_every, t_hi / 30.0));
  spec.set("t_head_on_top", e.t_head_on_top).set("t_body_past", e.t_body_past);
  spec.set("scene", scene_json(r.resolved));
  write_figure(s, "stair_" + tag, std::move(spec));
  return "stair_" + tag;
}

}  // namespace

StairResult stair(const Settings& s, double duration, std::vector<double> k_c, double snapshot_every,
                  std::vector<double> heights) {
  if (k_c.empty()) throw std::invalid_argument("--k_c: expected at least one value");
  for (double h : heights)
    if (!(h > 0) || !std::isfinite(h)) throw std::invalid_argument("--heights " + fmt(h) + ": expected > 0 [m]");
  const model::Scene sc = load(s, s.stair_scene);
  std::string k_c_list;
  for (double k : k_c) k_c_list += fmt(k) + ' ';
  say(s, "stair_start.txt.in", {{"k_c", k_c_list},
                                {"scene", s.scene_prefix + s.stair_scene},
                                {"duration", plain(duration)},
                                {"integrator", describe_integ(s, sc)}});
  std::vector<RunSpec> specs;
  for (double k : k_c) specs.push_back(make_spec(s, sc, duration, k, 0.05));
  for (double h : heights)
    for (double k : k_c) {
      model::Scene low = sc;
      for (model::Box& b : low.boxes) b.height = h;
      specs.push_back(make_spec(s, low, duration, k, 0.0));
    }
  auto res = run_all(s, specs, "stair");
  StairResult out;
  out.duration = duration;
  for (std::size_t i = 0; i < k_c.size(); ++i) out.cases.push_back({k_c[i], std::move(res[i])});
  for (std::size_t hi = 0; hi < heights.size(); ++hi) {
    StairHeight row{heights[hi], {}, {}};
    for (std::size_t i = 0; i < k_c.size(); ++i) {
      const RunResult& r = res[k_c.size() * (1 + hi) + i];
      row.speed.push_back(r.avg_speed);
      row.t_body_past.push_back(r.stair.t_body_past);
    }
    out.heights.push_back(std::move(row));
  }
  const StairEvents& e0 = out.cases.front().run.stair;
  say(s, "stair_box.txt.in", {{"x_near", fmt(e0.x_near)}, {"x_far", fmt(e0.x_far)}, {"top", fmt(e0.top)}});
  std::string rows;  // the report's table (report/stair.md.in)
  for (const StairCase& c : out.cases) {
    const RunResult& r = c.run;
    const std::string k = fmt(c.k_c);
    say(s, "stair_case.txt.in",
        {{"k_c", std::string(k.size() < 5 ? 5 - k.size() : 0, ' ') + k},  // right-aligned in 5
         {"speed", cms(r.avg_speed)},
         {"head_on_top", secs(r.stair.t_head_on_top)},
         {"com_past", secs(r.stair.t_com_past)},
         {"body_past", secs(r.stair.t_body_past)},
         {"max_head_z", fmt(r.stair.max_head_z * 100, 3)},
         {"stopped", r.status == model::StepStatus::kOk ? std::string()
                                                         : ", STOPPED: " + std::string(model::to_string(r.status))}});
    rows += (rows.empty() ? "" : "\n") +
            markdown_row({fmt(c.k_c), cms(r.avg_speed), secs(r.stair.t_head_on_top), secs(r.stair.t_com_past),
                          secs(r.stair.t_body_past), fmt(r.stair.max_head_z * 100, 3) + " cm",
                          r.status == model::StepStatus::kOk ? "ok" : std::string(model::to_string(r.status))});
  }
  if (out.cases.size() >= 2) {
    const double g = out.cases[1].run.avg_speed / out.cases[0].run.avg_speed - 1.0;
    say(s, "stair_gain.txt.in", {{"k_c", fmt(out.cases[1].k_c)}, {"k_c0", fmt(out.cases[0].k_c)}, {"gain", pct(g)}});
  }
  std::vector<std::string> hh{"box height"};
  for (double k : k_c) hh.push_back("k_c = " + fmt(k) + ": speed, whole body past");
  tk::Table ht(hh);
  std::string height_rows;
  for (const StairHeight& h : out.heights) {
    std::vector<std::string> cells{fmt(h.height * 100) + " cm"};
    for (std::size_t i = 0; i < k_c.size(); ++i) cells.push_back(cms(h.speed[i]) + ", " + secs(h.t_body_past[i]));
    height_rows += (height_rows.empty() ? "" : "\n") + markdown_row(cells);
    ht.add_row(cells);
  }
  if (!out.heights.empty()) {
    std::string table = ht.to_text();
    if (!table.empty() && table.back() == '\n') table.pop_back();  // the template ends the line
    say(s, "stair_heights.txt.in", {{"table", table}});
  }
  if (s.plots) {
    std::vector<std::string> names;
    tk::Json cases = tk::Json::array();
    for (const StairCase& c : out.cases) {
      const std::string name = stair_figure(s, c, snapshot_every);
      if (name.empty()) continue;  // no samples
      names.push_back(name);
      cases.push(tk::Json::object().set("k_c", c.k_c).set("trace", name + ".csv"));
    }
    write_figure(s, "stair_progress", tk::Json::object()
                                          .set("kind", "stair_progress")
                                          .set("top", e0.top).set("x_near", e0.x_near).set("x_far", e0.x_far)
                                          .set("cases", std::move(cases)));
    names.push_back("stair_progress");
    draw(s, names);
  }
  // The report (report/stair.md.in; the box-height scan and each case's figures are their own
  // templates).
  std::string height_scan, figures;
  if (!out.heights.empty())
    height_scan = fill_report("stair_heights.md.in",
                          {{"header", markdown_row(hh) + "\n" + markdown_row(std::vector<std::string>(hh.size(), "---"))},
                           {"rows", height_rows}});
  for (const StairCase& c : out.cases)
    figures += fill_report("stair_figures.md.in", {{"k_c", fmt(c.k_c)}, {"tag", kc_tag(c.k_c)}});
  out.markdown = fill_report("stair.md.in", {{"args", stair_arg(s)},
                                             {"scene", s.scene_prefix + s.stair_scene},
                                             {"width_cm", fmt((e0.x_far - e0.x_near) * 100)},
                                             {"height_cm", fmt(e0.top * 100)},
                                             {"x_near", fmt(e0.x_near)},
                                             {"x_far", fmt(e0.x_far)},
                                             {"duration", fmt(duration)},
                                             {"integrator", describe_integ(s, sc)},
                                             {"on_top_below_cm", fmt(kOnTopBelow * 100)},
                                             {"on_top_above_cm", fmt(kOnTopAbove * 100)},
                                             {"avg_from", fmt(out.cases.front().run.avg_from)},
                                             {"rows", rows},
                                             {"heights", height_scan},
                                             {"figures", figures}});
  write_text(s.out_dir / "stair.md", out.markdown);
  return out;
}

// ================================================================================================
std::vector<double> sweep_grid(double from, double to, double step) {
  if (!(step > 0) || !std::isfinite(step))
    throw std::invalid_argument("--step " + fmt(step) + ": expected > 0");
  if (!(to >= from) || !std::isfinite(from) || !std::isfinite(to))
    throw std::invalid_argument("--from " + fmt(from) + " --to " + fmt(to) + ": expected finite from ≤ to");
  std::vector<double> g;
  for (long long i = 0;; ++i) {
    const double k = from + static_cast<double>(i) * step;
    if (k > to + step * 1e-3) break;
    g.push_back(std::round(k * 1e9) / 1e9);
  }
  return g;
}

std::size_t best_index(const std::vector<SweepPoint>& points) {
  std::size_t best = points.size();
  for (std::size_t i = 0; i < points.size(); ++i)
    if (std::isfinite(points[i].speed) && (best == points.size() || points[i].speed > points[best].speed))
      best = i;
  return best;
}

SweepResult sweep(const Settings& s, const SweepOptions& o) {
  SweepResult out;
  out.options = o;
  out.jobs = s.jobs;
  const auto grid = sweep_grid(o.from, o.to, o.step);
  const model::Scene sc = load(s, s.stair_scene);
  const std::string sc_text = read_file(scene_file(s, s.stair_scene));
  const RunSpec base = make_spec(s, sc, o.duration, 0.0, 0.0);
  say(s, "sweep_start.txt.in",
      {{"scene", s.scene_prefix + s.stair_scene},
       {"runs", std::to_string(grid.size())},
       {"from", fmt(o.from)},
       {"to", fmt(o.to)},
       {"step", fmt(o.step)},
       {"duration", plain(o.duration)},
       {"integrator", describe_integ(s, sc)},
       {"where", (s.campaign.backend == campaign::Backend::slurm
                      ? "Slurm job arrays of " + std::to_string(s.campaign.slurm.chunk) + " groups per task"
                      : std::to_string(s.jobs) + " threads") +
                     ", runs " + lanes_note(s, base)}});
  const auto res =
      run_group_campaign(s, base, grid, sweep_campaign(s, "sweep"), s.stair_scene, sc_text, &out.wall_s);
  for (std::size_t i = 0; i < grid.size(); ++i) {
    out.points.push_back({grid[i], res[i].avg_speed, res[i].stair, res[i].status, res[i].cpu_s});
    out.cpu_s += res[i].cpu_s;
  }
  out.realtime_factor = out.wall_s > 0 ? static_cast<double>(grid.size()) * o.duration / out.wall_s : 0.0;
  out.best = best_index(out.points);
  auto zero = std::find_if(out.points.begin(), out.points.end(), [](const SweepPoint& p) { return p.k_c == 0.0; });
  if (zero != out.points.end()) {
    out.v0 = zero->speed;
  } else {
    out.v0 = run(make_spec(s, sc, o.duration, 0.0, 0.0)).avg_speed;
  }
  const bool have_best = out.best < out.points.size();
  if (have_best) out.gain = out.points[out.best].speed / out.v0 - 1.0;
  int failed = 0, past = 0;
  for (const SweepPoint& p : out.points) {
    failed += p.status != model::StepStatus::kOk;
    past += !std::isnan(p.stair.t_body_past);
  }
  say(s, "sweep_cost.txt.in", {{"wall_s", fmt(out.wall_s, 4)},
                               {"cpu_s", fmt(out.cpu_s, 4)},
                               {"cores", fmt(out.cpu_s / std::max(out.wall_s, 1e-9), 3)},
                               {"realtime_factor", fmt(out.realtime_factor, 4)},
                               {"stopped", failed ? ", " + std::to_string(failed) + " runs STOPPED" : ""}});
  if (have_best)
    say(s, "sweep_best.txt.in", {{"k_c", fmt(out.points[out.best].k_c)},
                                 {"speed", cms(out.points[out.best].speed)},
                                 {"v0", cms(out.v0)},
                                 {"gain", pct(out.gain)}});
  say(s, "sweep_past.txt.in", {{"duration", fmt(o.duration)},
                               {"past", std::to_string(past)},
                               {"points", std::to_string(out.points.size())}});

  // Accuracy: a few k_c values again at a finer step.
  if (o.checks > 0 && have_best) {
    std::vector<double> ks{0.0, out.points[out.best].k_c};
    if (PaperValues::kBestKc >= o.from && PaperValues::kBestKc <= o.to) ks.push_back(PaperValues::kBestKc);
    ks.push_back(grid[grid.size() / 2]);
    std::vector<double> uniq;
    for (double k : ks)
      if (std::find(uniq.begin(), uniq.end(), k) == uniq.end() && static_cast<int>(uniq.size()) < o.checks)
        uniq.push_back(k);
    Settings fine = s;
    fine.integ = integ_of(s, sc);
    fine.integ->h = o.check_h;
    const auto cr = run_group_campaign(s, make_spec(fine, sc, o.duration, 0.0, 0.0), uniq,
                                       sweep_campaign(s, "sweep-check"), s.stair_scene, sc_text);
    for (std::size_t i = 0; i < uniq.size(); ++i) {
      SweepCheck c{uniq[i], kNaN, cr[i].avg_speed};
      for (const SweepPoint& p : out.points)
        if (p.k_c == uniq[i]) c.speed = p.speed;
      if (std::isnan(c.speed) && uniq[i] == 0.0) c.speed = out.v0;
      out.checks.push_back(c);
      say(s, "sweep_check.txt.in", {{"k_c", fmt(c.k_c)},
                                    {"h", fmt(integ_of(s, sc).h)},
                                    {"speed", cms(c.speed)},
                                    {"h_fine", fmt(o.check_h)},
                                    {"speed_fine", cms(c.speed_fine)},
                                    {"delta", fixed((c.speed - c.speed_fine) * 100, 3)}});
    }
  }

  // CSV of every point.
  {
    tk::CsvWriter csv(s.out_dir / "sweep.csv", {"k_c", "speed_m_s", "t_head_on_top_s", "t_com_past_s",
                                                "t_body_past_s", "max_head_z_m", "status", "cpu_s"});
    csv.comment("pedalwave_paper sweep: stair, " + fmt(o.duration) + " s per run, " + describe_integ(s, sc) +
                "; speed = COM x average from one gait period on; NaN time = never");
    for (const SweepPoint& p : out.points)
      csv.row({p.k_c, p.speed, p.stair.t_head_on_top, p.stair.t_com_past, p.stair.t_body_past,
               p.stair.max_head_z, static_cast<double>(p.status), p.cpu_s});
    csv.close();
  }
  if (s.plots && !out.points.empty()) {
    tk::Json spec = tk::Json::object();
    spec.set("kind", "sweep_speed").set("csv", "../sweep.csv").set("duration", o.duration).set("v0", out.v0);
    spec.set("paper_best_k_c", PaperValues::kBestKc);
    if (have_best)
      spec.set("best", tk::Json::object()
                           .set("k_c", out.points[out.best].k_c)
                           .set("speed", out.points[out.best].speed)
                           .set("gain_label", pct(out.gain)));
    write_figure(s, "sweep_speed", std::move(spec));
    draw(s, {"sweep_speed"});
  }
  // The report (report/sweep.md.in; the best and the accuracy check are their own templates, left
  // out when there is none).
  std::string best, checks, rows;
  if (have_best)
    best = fill_report("sweep_best.md.in", {{"k_c", fmt(out.points[out.best].k_c)},
                                            {"speed", cms(out.points[out.best].speed)},
                                            {"v0", cms(out.v0)},
                                            {"gain", pct(out.gain)},
                                            {"past", std::to_string(past)},
                                            {"points", std::to_string(out.points.size())}});
  if (!out.checks.empty()) {
    for (const SweepCheck& c : out.checks)
      rows += (rows.empty() ? "" : "\n") + markdown_row({fmt(c.k_c), cms(c.speed), cms(c.speed_fine),
                                                         fixed((c.speed - c.speed_fine) * 100, 3)});
    checks = fill_report("sweep_checks.md.in",
                         {{"check_h", fmt(o.check_h)}, {"h", fmt(integ_of(s, sc).h)}, {"rows", rows}});
    rows.clear();
  }
  for (const SweepPoint& p : out.points) {
    const double frac = p.k_c - std::floor(p.k_c + 1e-9);
    const bool integer = std::abs(frac) < 1e-6;
    if (integer || &p == &out.points[std::min(out.best, out.points.size() - 1)])
      rows += (rows.empty() ? "" : "\n") + markdown_row({fmt(p.k_c) + (&p == &out.points[out.best] ? " (best)" : ""),
                                                         cms(p.speed), secs(p.stair.t_head_on_top),
                                                         secs(p.stair.t_body_past)});
  }
  out.markdown = fill_report(
      "sweep.md.in",
      {{"args", stair_arg(s)},
       {"runs", std::to_string(grid.size())},
       {"scene", s.stair_scene},
       {"from", fmt(o.from)},
       {"to", fmt(o.to)},
       {"step", fmt(o.step)},
       {"duration", fmt(o.duration)},
       {"integrator", describe_integ(s, sc)},
       {"where", s.campaign.backend == campaign::Backend::slurm
                     ? "as Slurm job arrays (" + std::to_string(s.campaign.slurm.chunk) + " runs per task)"
                     : "on " + std::to_string(s.jobs) + " threads"},
       {"wall_s", fmt(out.wall_s, 3)},
       {"cpu_s", fmt(out.cpu_s, 3)},
       {"realtime_factor", fmt(out.realtime_factor, 3)},
       {"best", best},
       {"checks", checks},
       {"rows", rows}});
  write_text(s.out_dir / "sweep.md", out.markdown);
  return out;
}

// ================================================================================================
SensitivityResult sensitivity(const Settings& s, const SensitivityOptions& o) {
  SensitivityResult out;
  out.options = o;
  const model::Scene hi = load(s, "flat_high_friction"), lo = load(s, "flat_low_friction"),
                     fr = load(s, "friction_change"), st = load(s, "stair");
  const model::Scene base = hi;
  const double K0 = base.robot.stiffness(0), Ir0 = base.robot.I_r;
  struct Variant {
    std::string parameter, value;
    std::function<void(model::Scene&)> apply;
  };
  std::vector<Variant> vars;
  vars.push_back({"baseline", "K = " + fmt(K0) + ", I_r = " + fmt(Ir0), [](model::Scene&) {}});
  for (double K : o.K)
    if (K != K0)
      vars.push_back({"K [N·m/rad]", fmt(K), [K](model::Scene& sc) {
                        sc.robot.K.clear();
                        sc.robot.K_all = K;
                      }});
  for (double I : o.I_r)
    if (I != Ir0) vars.push_back({"I_r [kg·m²]", fmt(I), [I](model::Scene& sc) { sc.robot.I_r = I; }});
  if (o.model_options) {
    vars.push_back({"friction at", "link COMs only (paper)", [](model::Scene& sc) { sc.ground.friction_at_com = true; }});
    vars.push_back({"v_s [m/s]", "1e-4", [](model::Scene& sc) { sc.ground.v_s = 1e-4; }});
  }
  say(s, "sensitivity_start.txt.in", {{"variants", std::to_string(vars.size())},
                                      {"k_c", fmt(o.k_c)},
                                      {"integrator", describe_integ(s, hi)},
                                      {"stair_integrator", describe_integ(s, st)}});
  constexpr int kRuns = 5;
  std::vector<RunSpec> specs;
  const double fr_dur = o.friction_duration > 0 ? o.friction_duration : fr.duration;
  for (const Variant& v : vars) {
    auto mod = [&](model::Scene sc) {
      v.apply(sc);
      return sc;
    };
    specs.push_back(make_spec(s, mod(hi), o.flat_duration, 0.0, 0.0));
    specs.push_back(make_spec(s, mod(lo), o.flat_duration, 0.0, 0.0));
    RunSpec f = make_spec(s, mod(fr), fr_dur, 0.0, 0.005);
    f.cross_x = patch_x(fr);
    specs.push_back(f);
    specs.push_back(make_spec(s, mod(st), o.stair_duration, 0.0, 0.0));
    specs.push_back(make_spec(s, mod(st), o.stair_duration, o.k_c, 0.0));
  }
  const auto res = run_all(s, specs, "sensitivity");
  tk::Table t({"parameter", "value", "flat v (0.82)", "flat v (0.40)", "friction gain", "torque-peak change",
               "stair v k_c=0", "stair v k_c=" + fmt(o.k_c), "stair gain", "body past (0 / " + fmt(o.k_c) + ")"});
  std::string md_rows;  // the same rows for the report's template
  for (std::size_t i = 0; i < vars.size(); ++i) {
    const RunResult* r = &res[i * kRuns];
    SensitivityRow row;
    row.parameter = vars[i].parameter;
    row.value = vars[i].value;
    row.v_high = r[0].avg_speed;
    row.v_low = r[1].avg_speed;
    row.gain = row.v_high / row.v_low - 1.0;
    const PeakSplit ps = split_peaks(r[2], gait_period(fr), r[2].t_head_cross);
    row.peak_change = ps.change;
    row.peaks_before = static_cast<int>(ps.before.size());
    row.peaks_after = static_cast<int>(ps.after.size());
    row.stair_v0 = r[3].avg_speed;
    row.stair_vkc = r[4].avg_speed;
    row.stair_gain = row.stair_vkc / row.stair_v0 - 1.0;
    row.past0 = r[3].stair.t_body_past;
    row.pastkc = r[4].stair.t_body_past;
    row.top0 = r[3].stair.t_head_on_top;
    row.topkc = r[4].stair.t_head_on_top;
    std::string bad;
    for (int k = 0; k < kRuns; ++k)
      if (r[k].status != model::StepStatus::kOk) bad += " run " + std::to_string(k) + " " + std::string(model::to_string(r[k].status));
    std::vector<std::string> cells{row.parameter, row.value + (bad.empty() ? "" : " (STOPPED:" + bad + ")"),
                                   cms(row.v_high), cms(row.v_low), pct(row.gain),
                                   pct(row.peak_change) + " (" + std::to_string(row.peaks_before) + "/" +
                                       std::to_string(row.peaks_after) + " peaks)",
                                   cms(row.stair_v0), cms(row.stair_vkc), pct(row.stair_gain),
                                   secs(row.past0) + " / " + secs(row.pastkc)};
    md_rows += (md_rows.empty() ? "" : "\n") + markdown_row(cells);
    t.add_row(std::move(cells));
    out.rows.push_back(row);
  }
  log(s) << t.to_text();
  out.markdown = fill_report("sensitivity.md.in", {{"K0", fmt(K0)},
                                                  {"I_r0", fmt(Ir0)},
                                                  {"flat_duration", fmt(o.flat_duration)},
                                                  {"stair_duration", fmt(o.stair_duration)},
                                                  {"friction_duration", fmt(fr_dur)},
                                                  {"flat_integrator", describe_integ(s, hi)},
                                                  {"stair_integrator", describe_integ(s, st)},
                                                  {"k_c", fmt(o.k_c)},
                                                  {"rows", md_rows}});
  write_text(s.out_dir / "sensitivity.md", out.markdown);

  if (s.plots) {
    // Flat speed and stair speeds against K (log axis).
    std::vector<double> k, vh, vl, s0, sk;
    std::vector<std::pair<double, const SensitivityRow*>> kr{{K0, &out.rows[0]}};
    for (std::size_t i = 0; i < vars.size(); ++i)
      if (vars[i].parameter == "K [N·m/rad]") kr.push_back({std::stod(vars[i].value), &out.rows[i]});
    std::sort(kr.begin(), kr.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [K, row] : kr) {
      k.push_back(K);
      vh.push_back(row->v_high * 100);
      vl.push_back(row->v_low * 100);
      s0.push_back(row->stair_v0 * 100);
      sk.push_back(row->stair_vkc * 100);
    }
    if (k.size() >= 2) {
      write_figure(s, "sensitivity_K", tk::Json::object()
                                           .set("kind", "sensitivity_K")
                                           .set("I_r", Ir0).set("k_c", o.k_c)
                                           .set("K", numbers(k)).set("flat_high", numbers(vh))
                                           .set("flat_low", numbers(vl)).set("stair_0", numbers(s0))
                                           .set("stair_kc", numbers(sk))
                                           .set("paper_flat_sim", PaperValues::kFlatSpeedSim * 100));
      draw(s, {"sensitivity_K"});
    }
  }
  return out;
}

// ================================================================================================
namespace {

// The fitted scenes beside the shipped ones: the same measures from the same experiments
// (report/fitted.md.in; the paper's values are in the template, here only for the notes).
std::string fitted_table(const AllResult& r, std::size_t* rows) {
  const FittedResult& f = *r.fitted;
  auto at = [](const StairResult& st, double k_c) {
    for (const StairCase& c : st.cases)
      if (c.k_c == k_c) return c.run.avg_speed;
    return kNaN;
  };
  auto climb = [](const StairResult& st, double k_c) {
    for (const StairCase& c : st.cases)
      if (c.k_c == k_c)
        return "COM past " + secs(c.run.stair.t_com_past) + ", whole body past " + secs(c.run.stair.t_body_past);
    return std::string("—");
  };
  auto best = [](const SweepResult& sw) {
    if (sw.best >= sw.points.size()) return std::string("—");
    return fmt(sw.points[sw.best].k_c) + ", " + pct(sw.gain);
  };
  const double s1 = at(r.stair, PaperValues::kBestKc), s0 = at(r.stair, 0.0);
  const double f1 = at(f.stair, PaperValues::kBestKc), f0 = at(f.stair, 0.0);
  std::map<std::string, std::string> v{{"prefix", f.prefix}, {"parameters", f.parameters}};
  std::vector<std::string> notes;
  // A value pair and, where the fitted figure is not the paper's within its target tolerance
  // (config/identify/paper_targets.yaml), a sentence giving the difference.
  auto row = [&](const std::string& key, const std::string& c, double paper, double shipped, double fitted,
                 bool percent, double tol) {
    const auto show = [&](double x) { return percent ? pct(x) : cms(x); };
    v["shipped." + key] = show(shipped);
    v["fitted." + key] = show(fitted);
    const double d = fitted - paper;
    if (!(std::abs(d) <= tol))
      notes.push_back("**" + c + "**: fitted " + show(fitted) + " against the paper's " + show(paper) + " (" +
                      (percent ? fixed(d * 100, 1) + " points" : (d > 0 ? "+" : "") + fixed(d * 100, 2) + " cm/s") +
                      ", " + (std::isfinite(d) ? fmt(std::abs(d) / tol, 2) : std::string("—")) +
                      " tolerances); shipped " + show(shipped) + ".");
  };
  row("flat_v_high", "flat, μ = 0.82: average speed", PaperValues::kFlatSpeedSim, r.flat.v_high, f.flat.v_high, false,
      0.001);
  v["shipped.flat_v_low"] = cms(r.flat.v_low);
  v["fitted.flat_v_low"] = cms(f.flat.v_low);
  row("flat_gain", "speed gain μ = 0.82 over 0.40", PaperValues::kFrictionGainSim, r.flat.gain, f.flat.gain, true, 0.02);
  row("peak_change", "SEA torque-peak change after the head enters μ = 0.40", PaperValues::kPeakChangeSim,
      r.friction.change, f.friction.change, true, 0.03);
  row("stair_v_kc", "stair, k_c = 10.1: average speed (60 s)", PaperValues::kStairSpeedSim, s1, f1, false, 0.002);
  v["shipped.stair_v_0"] = cms(s0);
  v["fitted.stair_v_0"] = cms(f0);
  v["shipped.climb_kc"] = climb(r.stair, PaperValues::kBestKc);
  v["fitted.climb_kc"] = climb(f.stair, PaperValues::kBestKc);
  row("stair_gain", "stair gain of k_c = 10.1 over k_c = 0", PaperValues::kStairGainSim, s1 / s0 - 1.0, f1 / f0 - 1.0,
      true, 0.05);
  v["shipped.sweep_best"] = best(r.sweep);
  v["fitted.sweep_best"] = best(f.sweep);
  if (f.sweep.best < f.sweep.points.size() && std::abs(f.sweep.points[f.sweep.best].k_c - PaperValues::kBestKc) > 1.0)
    notes.push_back("**Best k_c**: fitted " + fmt(f.sweep.points[f.sweep.best].k_c) + " against the paper's 10.1 (gain " +
                    pct(f.sweep.gain) + " against +24.8 %).");
  std::string list;
  if (notes.empty()) list = "Every fitted figure is the paper's within its tolerance.";
  for (const std::string& n : notes) list += (list.empty() ? "" : "\n") + ("- " + n);
  v["notes"] = list;
  return fill_report("fitted.md.in", v, rows);
}

// The fitted values of a scene, as one line (the identification's parameters).
std::string scene_parameters(const model::Scene& sc) {
  std::ostringstream os;
  os << "K = " << fmt(sc.robot.stiffness(0)) << " N·m/rad, I_l = " << fmt(sc.robot.I_l) << " kg·m², I_r = "
     << fmt(sc.robot.I_r) << " kg·m², ground k = " << fmt(sc.ground.k) << " N/m, d = " << fmt(sc.ground.d)
     << " N·s/m, " << model::to_string(sc.ground.law) << " friction, v_s = " << fmt(sc.ground.v_s) << " m/s, at the "
     << (sc.ground.friction_at_com ? "link COMs" : "contact points") << ", links " << model::to_string(sc.robot.link_shape);
  if (sc.robot.link_shape == model::LinkShape::kCapsule) os << " r = " << fmt(sc.robot.link_radius * 1000) << " mm";
  if (sc.robot.link_shape == model::LinkShape::kBox) os << " h_m = " << fmt(sc.robot.link_height * 1000) << " mm";
  return os.str();
}

}  // namespace

std::string paper_table(const AllResult& r, std::size_t* rows, std::size_t* fitted_rows) {
  // The report's text is the template tools/paper/report/table.md.in; here only the values.
  std::map<std::string, std::string> v;
  // Ranges of a measure over the sensitivity rows of one parameter (with the baseline).
  auto range = [&](const std::string& param, double SensitivityRow::*field, bool percent) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const SensitivityRow& row : r.sensitivity.rows)
      if (row.parameter == param || row.parameter == "baseline") {
        const double x = row.*field;
        if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
      }
    if (!std::isfinite(lo)) return std::string("—");
    return percent ? pct(lo) + " … " + pct(hi) : fixed(lo * 100, 2) + " … " + fixed(hi * 100, 2) + " cm/s";
  };
  auto option = [&](const std::string& param, double SensitivityRow::*field, bool percent) {
    for (const SensitivityRow& row : r.sensitivity.rows)
      if (row.parameter == param) return percent ? pct(row.*field) : cms(row.*field);
    return std::string("—");
  };
  // <measure>.over_K, .over_I_r, .friction_at_com, .v_s: how the measure moves with the
  // unpublished parameters and the two model options (sensitivity.md).
  auto evidence = [&](const std::string& measure, double SensitivityRow::*field, bool percent) {
    v[measure + ".over_K"] = range("K [N·m/rad]", field, percent);
    v[measure + ".over_I_r"] = range("I_r [kg·m²]", field, percent);
    v[measure + ".friction_at_com"] = option("friction at", field, percent);
    v[measure + ".v_s"] = option("v_s [m/s]", field, percent);
  };
  evidence("v_high", &SensitivityRow::v_high, false);
  evidence("v_low", &SensitivityRow::v_low, false);
  evidence("gain", &SensitivityRow::gain, true);
  evidence("peak_change", &SensitivityRow::peak_change, true);
  evidence("stair_vkc", &SensitivityRow::stair_vkc, false);
  evidence("stair_gain", &SensitivityRow::stair_gain, true);

  // The run of a stair result at a given k_c (nullptr if it was not run).
  auto case_at = [](const StairResult& st, double k_c) -> const StairCase* {
    for (const StairCase& c : st.cases)
      if (c.k_c == k_c) return &c;
    return nullptr;
  };
  // "; k_c = …: v → v_fine" for each of a sweep's accuracy re-runs.
  auto check_list = [](const SweepResult& sr) {
    std::string text;
    for (const SweepCheck& c : sr.checks)
      text += "; k_c = " + fmt(c.k_c) + ": " + cms(c.speed) + " → " + cms(c.speed_fine);
    return text;
  };
  auto climb = [](const StairCase* c) {
    if (!c) return std::string("—");
    const StairEvents& e = c->run.stair;
    return "head on top " + secs(e.t_head_on_top) + ", COM past " + secs(e.t_com_past) + ", whole body past " +
           secs(e.t_body_past);
  };
  // Where a stair run ended (a sentence, or nothing when the case was not run).
  auto stuck = [](const StairCase* c) {
    if (!c) return std::string();
    const RunResult& q = c->run;
    if (!std::isnan(q.stair.t_body_past))
      return "With k_c = " + fmt(c->k_c) + " the whole body is past the box at " + secs(q.stair.t_body_past) + ". ";
    if (!std::isnan(q.stair.t_com_past))
      return "With k_c = " + fmt(c->k_c) + " the robot climbs: its COM passes the far edge at " +
             secs(q.stair.t_com_past) + " and ends at x = " + fixed(q.com_x_final * 100, 1) +
             " cm, the tail still over the box when the run ends. ";
    return "With k_c = " + fmt(c->k_c) + " the robot does not get past the box: its COM ends at x = " +
           fixed(q.com_x_final * 100, 1) + " cm (box " + fixed(q.stair.x_near * 100, 1) + " … " +
           fixed(q.stair.x_far * 100, 1) + " cm). ";
  };
  // The stair values of one box scene under `key` (stair, grip).
  auto stair_values = [&](const std::string& key, const StairResult& st) {
    const StairCase* s0 = case_at(st, 0.0);
    const StairCase* s1 = case_at(st, PaperValues::kBestKc);
    const double v0 = s0 ? s0->run.avg_speed : kNaN, v1 = s1 ? s1->run.avg_speed : kNaN;
    v[key + ".v_kc"] = cms(v1);
    v[key + ".v_0"] = cms(v0);
    v[key + ".climb_kc"] = climb(s1);
    v[key + ".climb_0"] = climb(s0);
    v[key + ".gain"] = pct(v1 / v0 - 1.0);
    v[key + ".outcome_0"] = stuck(s0);
    v[key + ".outcome_kc"] = stuck(s1);
  };

  v["flat.v_high"] = cms(r.flat.v_high);
  v["flat.v_low"] = cms(r.flat.v_low);
  v["flat.gain"] = pct(r.flat.gain);
  v["flat.v_high_vs_paper"] = pct(r.flat.v_high / PaperValues::kFlatSpeedSim - 1.0);
  v["friction.change"] = pct(r.friction.change);
  v["friction.cross_x"] = fmt(r.friction.cross_x);
  v["friction.t_cross"] = secs(r.friction.t_cross);
  stair_values("stair", r.stair);
  v["stair.on_top_below_cm"] = fmt(kOnTopBelow * 100);
  v["stair.on_top_above_cm"] = fmt(kOnTopAbove * 100);
  {
    // Which box heights were climbed (a sentence, or nothing without the scan).
    double best_h = kNaN;
    for (const StairHeight& h : r.stair.heights)
      for (double tp : h.t_body_past)
        if (!std::isnan(tp)) best_h = std::isnan(best_h) ? h.height : std::max(best_h, h.height);
    std::string climbable;
    if (!r.stair.heights.empty())
      climbable = std::isnan(best_h)
                      ? "In the box-height scan (stair.md) no height was passed within the run. "
                      : "In the box-height scan (stair.md) the highest box the whole body passed is " +
                            fmt(best_h * 100) + " cm. ";
    v["stair.heights"] = climbable;
  }
  const SweepResult& sw = r.sweep;
  const bool have_best = sw.best < sw.points.size();
  v["sweep.best_k_c"] = fmt(have_best ? sw.points[sw.best].k_c : kNaN);
  v["sweep.best_speed"] = cms(have_best ? sw.points[sw.best].speed : kNaN);
  v["sweep.gain"] = pct(sw.gain);
  v["sweep.v0"] = cms(sw.v0);
  v["sweep.check_h"] = fmt(sw.options.check_h);
  v["sweep.checks"] = check_list(sw);
  v["sweep.wall_s"] = fmt(sw.wall_s, 3);
  v["sweep.jobs"] = std::to_string(sw.jobs);
  v["sweep.realtime_factor"] = fmt(sw.realtime_factor, 3);
  v["sweep.cpu_s"] = fmt(sw.cpu_s, 3);
  v["sweep.cpu_s_per_job"] = fmt(sw.cpu_s / std::max(1, sw.jobs), 3);
  // The calibrated edge friction (scene stair_grip), where the robot climbs.
  stair_values("grip", r.stair_grip);
  const SweepResult& gs = r.sweep_grip;
  v["grip_sweep.best"] = gs.best < gs.points.size() ? fmt(gs.points[gs.best].k_c) + ", " + pct(gs.gain) + " (" +
                                                          cms(gs.points[gs.best].speed) + " vs " + cms(gs.v0) + ")"
                                                    : std::string("—");
  v["grip_sweep.check_h"] = fmt(gs.options.check_h);
  v["grip_sweep.checks"] = check_list(gs);

  std::string md = fill_report("table.md.in", v, rows);
  if (fitted_rows) *fitted_rows = 0;
  if (r.fitted) md += '\n' + fitted_table(r, fitted_rows);
  return md;
}

AllResult all(const Settings& s, const AllOptions& o) {
  AllResult r;
  r.flat = flat(s, o.flat_duration);
  r.friction = friction(s, o.friction_duration);
  r.stair = stair(s, o.stair_duration);
  r.sweep = sweep(s, o.sweep);
  {
    // The same on the calibrated edge friction, where the robot climbs (tools/paper/README.md).
    Settings g = s;
    g.stair_scene = "stair_grip";
    g.out_dir = s.out_dir / "stair_grip";
    r.stair_grip = stair(g, o.stair_duration);
    r.sweep_grip = sweep(g, o.sweep);
  }
  r.sensitivity = sensitivity(s, o.sensitivity);
  if (!o.fitted_prefix.empty()) {
    // The identification's fitted scenes, when --scenes has them (into out_dir/<prefix without _>).
    Settings f = s;
    f.scene_prefix = o.fitted_prefix;
    f.stair_scene = "stair";
    std::string dir = o.fitted_prefix;
    while (!dir.empty() && dir.back() == '_') dir.pop_back();
    f.out_dir = s.out_dir / dir;
    bool have = true;
    for (const char* n : {"flat_high_friction", "flat_low_friction", "friction_change", "stair"})
      have = have && fs::exists(scene_file(f, n));
    if (have) {
      FittedResult fr;
      fr.prefix = o.fitted_prefix;
      fr.parameters = scene_parameters(load(f, "stair"));
      fr.flat = flat(f, o.flat_duration);
      fr.friction = friction(f, o.friction_duration);
      fr.stair = stair(f, o.stair_duration, {0.0, PaperValues::kBestKc}, 1.5, {});
      fr.sweep = sweep(f, o.sweep);
      r.fitted = std::move(fr);
    } else {
      say(s, "all_no_fitted.txt.in", {{"prefix", o.fitted_prefix}, {"scenes", s.scenes_dir.string()}});
    }
  }
  r.table = paper_table(r, &r.table_rows, &r.fitted_rows);
  write_text(s.out_dir / "paper_table.md", r.table);
  std::ostringstream all_md;
  all_md << r.table << '\n' << r.flat.markdown << '\n' << r.friction.markdown << '\n' << r.stair.markdown << '\n'
         << r.sweep.markdown << '\n' << r.stair_grip.markdown << '\n' << r.sweep_grip.markdown << '\n'
         << r.sensitivity.markdown;
  if (r.fitted)
    all_md << '\n' << r.fitted->flat.markdown << '\n' << r.fitted->friction.markdown << '\n'
           << r.fitted->stair.markdown << '\n' << r.fitted->sweep.markdown;
  write_text(s.out_dir / "paper.md", all_md.str());
  say(s, "all_wrote.txt.in", {{"table", (s.out_dir / "paper_table.md").string()}, {"paper", (s.out_dir / "paper.md").string()}});
  return r;
}

}  // namespace pedalwave::paper
