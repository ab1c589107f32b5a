#include "pedalwave/toolkit/figure.hpp"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string_view>
#include <utility>

#include "pedalwave/toolkit/ticks.hpp"

extern char** environ;

namespace pedalwave::toolkit {

// ---- Axes: recording what to draw ---------------------------------------------------------------

namespace {

std::string num17(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void check_sizes(std::span<const double> x, std::span<const double> y, const std::string& label) {
  if (x.size() != y.size()) {
    throw std::invalid_argument("plot series '" + label + "': x has " + std::to_string(x.size()) +
                                " values but y has " + std::to_string(y.size()));
  }
}

void check_limit(double v, const char* which) {
  if (std::isinf(v)) {
    throw std::invalid_argument(std::string("axis limit ") + which + " = " + num17(v) +
                                ": expected a finite value or NaN (automatic)");
  }
}

}  // namespace

Axes& Axes::line(std::span<const double> x, std::span<const double> y, LineStyle style) {
  check_sizes(x, y, style.label);
  if (!style.color) style.color = cycle_color(next_color_++);
  series_.push_back({{x.begin(), x.end()}, {y.begin(), y.end()}, std::move(style), true});
  return *this;
}

Axes& Axes::scatter(std::span<const double> x, std::span<const double> y, LineStyle style) {
  check_sizes(x, y, style.label);
  if (!style.color) style.color = cycle_color(next_color_++);
  if (style.marker == Marker::none) style.marker = Marker::circle;
  series_.push_back({{x.begin(), x.end()}, {y.begin(), y.end()}, std::move(style), false});
  return *this;
}

Axes& Axes::hline(double y, RefLineStyle style) {
  ref_lines_.push_back({true, y, std::move(style)});
  return *this;
}

Axes& Axes::vline(double x, RefLineStyle style) {
  ref_lines_.push_back({false, x, std::move(style)});
  return *this;
}

Axes& Axes::rect(double x0, double x1, double y0, double y1, RectStyle style) {
  if (x0 > x1) std::swap(x0, x1);
  if (y0 > y1) std::swap(y0, y1);
  rects_.push_back({x0, x1, y0, y1, std::move(style)});
  return *this;
}

Axes& Axes::text(double x, double y, std::string text, TextStyle style) {
  texts_.push_back({x, y, std::move(text), style});
  return *this;
}

Axes& Axes::colorbar(Colormap map, double lo, double hi, std::string label) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) {
    throw std::invalid_argument("colorbar '" + label + "': range [" + num17(lo) + ", " +
                                num17(hi) + "] is not finite");
  }
  colorbar_ = ColorbarData{map, lo, hi, std::move(label)};
  return *this;
}

Axes& Axes::title(std::string text) {
  title_ = std::move(text);
  return *this;
}
Axes& Axes::xlabel(std::string text) {
  x_.label = std::move(text);
  return *this;
}
Axes& Axes::ylabel(std::string text) {
  y_.label = std::move(text);
  return *this;
}
Axes& Axes::xscale(Scale s) {
  x_.scale = s;
  return *this;
}
Axes& Axes::yscale(Scale s) {
  y_.scale = s;
  return *this;
}
Axes& Axes::xlim(double lo, double hi) {
  check_limit(lo, "x lo");
  check_limit(hi, "x hi");
  x_.lo = lo;
  x_.hi = hi;
  return *this;
}
Axes& Axes::ylim(double lo, double hi) {
  check_limit(lo, "y lo");
  check_limit(hi, "y hi");
  y_.lo = lo;
  y_.hi = hi;
  return *this;
}
Axes& Axes::xmargin(double fraction) {
  x_.margin = std::max(0.0, fraction);
  return *this;
}
Axes& Axes::ymargin(double fraction) {
  y_.margin = std::max(0.0, fraction);
  return *this;
}
Axes& Axes::equal_aspect(bool on) {
  equal_aspect_ = on;
  return *this;
}
Axes& Axes::legend(LegendPos pos) {
  legend_ = pos;
  return *this;
}
Axes& Axes::grid(bool on) {
  grid_ = on;
  return *this;
}

// ---- Figure ------------------------------------------------------------------------------------

Figure::Figure(int rows, int cols, double width_px, double height_px)
    : rows_(rows), cols_(cols), width_(width_px), height_(height_px) {
  if (rows < 1 || cols < 1) {
    throw std::invalid_argument("Figure: grid " + std::to_string(rows) + " x " +
                                std::to_string(cols) + ", expected at least 1 x 1");
  }
  size(width_px, height_px);
  axes_.resize(static_cast<std::size_t>(rows * cols));
}

Axes& Figure::axes(int row, int col) {
  return const_cast<Axes&>(static_cast<const Figure&>(*this).axes(row, col));
}

const Axes& Figure::axes(int row, int col) const {
  if (row < 0 || row >= rows_ || col < 0 || col >= cols_) {
    throw std::out_of_range("Figure::axes(" + std::to_string(row) + ", " + std::to_string(col) +
                            "): the figure has " + std::to_string(rows_) + " x " +
                            std::to_string(cols_) + " panels");
  }
  return axes_[static_cast<std::size_t>(row * cols_ + col)];
}

Figure& Figure::title(std::string text) {
  title_ = std::move(text);
  return *this;
}

Figure& Figure::share_x(bool on) {
  share_x_ = on;
  return *this;
}

Figure& Figure::size(double width_px, double height_px) {
  for (double v : {width_px, height_px}) {
    if (!(v >= 100.0 && v <= 20000.0)) {
      throw std::invalid_argument("Figure: size " + num17(v) + " px, expected 100..20000");
    }
  }
  width_ = width_px;
  height_ = height_px;
  return *this;
}

// ---- Rendering ---------------------------------------------------------------------------------

namespace {

constexpr double kTickFont = 13.0;
constexpr double kLabelFont = 14.0;
constexpr double kTitleFont = 15.0;
constexpr double kSupTitleFont = 17.0;
constexpr double kLegendFont = 12.5;
constexpr double kRefFont = 11.5;
constexpr double kTickLen = 5.0;
constexpr double kMinorLen = 3.0;
constexpr double kPxClamp = 1e6;  // pixel coordinates are clamped to ±this (renderer range)

__attribute__((format(printf, 2, 3))) void add(std::string& out, const char* fmt, ...) {
  char buf[1024];
  va_list ap;
  va_start(ap, fmt);
  const int n = std::vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  if (n < 0) return;
  if (static_cast<std::size_t>(n) < sizeof buf) {
    out.append(buf, static_cast<std::size_t>(n));
    return;
  }
  std::string big(static_cast<std::size_t>(n) + 1, '\0');
  va_start(ap, fmt);
  std::vsnprintf(big.data(), big.size(), fmt, ap);
  va_end(ap);
  big.pop_back();
  out += big;
}

std::string esc(std::string_view s) {
  std::string o;
  o.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string dash_attr(Dash d, double w) {
  const double u = std::max(w, 1.0);
  char buf[96];
  switch (d) {
    case Dash::solid: return "";
    case Dash::dashed: std::snprintf(buf, sizeof buf, " stroke-dasharray=\"%.1f %.1f\"", 4.5 * u, 3 * u); break;
    case Dash::dotted: std::snprintf(buf, sizeof buf, " stroke-dasharray=\"%.1f %.1f\"", 1.0 * u, 2.2 * u); break;
    case Dash::dash_dot:
      std::snprintf(buf, sizeof buf, " stroke-dasharray=\"%.1f %.1f %.1f %.1f\"", 5 * u, 2.5 * u,
                    1.0 * u, 2.5 * u);
      break;
  }
  return buf;
}

const char* anchor_attr(Anchor a) {
  switch (a) {
    case Anchor::start: return "start";
    case Anchor::middle: return "middle";
    case Anchor::end: return "end";
  }
  return "start";
}

struct Box {
  double x = 0, y = 0, w = 0, h = 0;
  [[nodiscard]] double right() const { return x + w; }
  [[nodiscard]] double bottom() const { return y + h; }
};

// One axis after autoscaling: data range and ticks.
struct AxisLayout {
  Scale scale = Scale::linear;
  double lo = 0.0, hi = 1.0;  // data range shown [data unit]
  std::vector<double> major;
  std::vector<double> minor;
  std::vector<std::string> labels;

  [[nodiscard]] double fwd(double v) const { return scale == Scale::log10 ? std::log10(v) : v; }
  [[nodiscard]] double inv(double u) const { return scale == Scale::log10 ? std::pow(10.0, u) : u; }
  [[nodiscard]] bool valid(double v) const {
    return std::isfinite(v) && (scale == Scale::linear || v > 0.0);
  }
  // Fraction of the range [0, 1] at data value v (valid v only).
  [[nodiscard]] double frac(double v) const { return (fwd(v) - fwd(lo)) / (fwd(hi) - fwd(lo)); }
};

struct Extent {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void add(double v, Scale s) {
    if (!std::isfinite(v) || (s == Scale::log10 && v <= 0.0)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  void merge(const Extent& o) {
    lo = std::min(lo, o.lo);
    hi = std::max(hi, o.hi);
  }
  [[nodiscard]] bool empty() const { return lo > hi; }
};

void compute_ticks(AxisLayout& a, double length_px, bool is_x) {
  a.major.clear();
  a.minor.clear();
  a.labels.clear();
  if (a.scale == Scale::linear) {
    const int target = std::clamp(static_cast<int>(std::lround(length_px / (is_x ? 95.0 : 55.0))), 3, 10);
    LinearTicks t = nice_linear_ticks(a.lo, a.hi, target);
    a.major = t.values;
    a.labels = format_linear_ticks(t.values, t.step);
  } else {
    const int max_major = std::clamp(static_cast<int>(length_px / (is_x ? 60.0 : 32.0)), 3, 14);
    LogTicks t = log_ticks(a.lo, a.hi, max_major);
    const double decades = std::log10(a.hi) - std::log10(a.lo);
    if (decades <= 3.2 && a.lo >= 1e-3 && a.hi <= 1e5 &&
        length_px / (3.0 * decades + 1.0) >= (is_x ? 75.0 : 32.0)) {
      // Short span of moderate values: label 1, 2 and 5 × 10^d in plain numbers, so the axis
      // carries more than one or two labels.
      std::vector<double> all = t.major;
      all.insert(all.end(), t.minor.begin(), t.minor.end());
      std::sort(all.begin(), all.end());
      for (double v : all) {
        const double m = v / std::pow(10.0, std::floor(std::log10(v) + 1e-9));
        const bool labelled = std::abs(m - 1.0) < 1e-6 || std::abs(m - 2.0) < 1e-6 || std::abs(m - 5.0) < 1e-6;
        if (labelled && t.stride == 1) {
          a.major.push_back(v);
          char buf[32];
          std::snprintf(buf, sizeof buf, "%g", v);
          a.labels.emplace_back(buf);
        } else {
          a.minor.push_back(v);
        }
      }
      if (a.major.size() >= 2) return;
      a.major.clear();
      a.minor.clear();
      a.labels.clear();
    }
    a.major = t.major;
    a.minor = t.minor;
    for (double v : a.major) a.labels.push_back(format_decade(static_cast<int>(std::lround(std::log10(v)))));
  }
}

// Range of an axis from its data extent and its spec (fixed limits, margin).
AxisLayout autoscale(const Axes::AxisSpec& spec, Extent data, double length_px, bool is_x) {
  AxisLayout a;
  a.scale = spec.scale;
  const bool log = spec.scale == Scale::log10;
  for (double v : {spec.lo, spec.hi}) {
    if (log && !std::isnan(v) && !(v > 0.0)) {
      throw std::invalid_argument("axis '" + spec.label + "': log10 limit " + num17(v) +
                                  " is not > 0");
    }
  }
  if (data.empty()) {
    data.lo = log ? 1.0 : 0.0;
    data.hi = log ? 10.0 : 1.0;
  }
  // Fixed limits replace the data bounds before padding, so a one-sided limit works.
  const bool fix_lo = !std::isnan(spec.lo);
  const bool fix_hi = !std::isnan(spec.hi);
  double lo = fix_lo ? spec.lo : data.lo;
  double hi = fix_hi ? spec.hi : data.hi;
  if (lo > hi) {
    if (fix_lo && !fix_hi) hi = lo;
    else if (fix_hi && !fix_lo) lo = hi;
    else std::swap(lo, hi);
  }
  double u0 = a.fwd(lo);
  double u1 = a.fwd(hi);
  if (!(u1 - u0 > 1e-12 * std::max(std::abs(u0), std::abs(u1)))) {
    const double pad = log ? 0.5 : (u0 == 0.0 ? 1.0 : std::abs(u0) * 0.1);
    if (!fix_lo) u0 -= pad;
    if (!fix_hi) u1 += pad;
    if (!(u1 > u0)) u1 = u0 + pad;  // both fixed and equal
  } else {
    const double pad = spec.margin * (u1 - u0);
    if (!fix_lo) u0 -= pad;
    if (!fix_hi) u1 += pad;
  }
  a.lo = a.inv(u0);
  a.hi = a.inv(u1);
  compute_ticks(a, length_px, is_x);
  if (log && a.major.size() < 2 && !(fix_lo && fix_hi)) {
    // Less than two labelled decades: widen to the enclosing decades.
    if (!fix_lo) u0 = std::floor(u0 + 1e-9);
    if (!fix_hi) u1 = std::ceil(u1 - 1e-9);
    if (u1 <= u0) u1 = u0 + 1.0;
    a.lo = a.inv(u0);
    a.hi = a.inv(u1);
    compute_ticks(a, length_px, is_x);
  }
  return a;
}

Extent data_extent(const Axes::SeriesData& s, bool x, const Axes::AxisSpec& xs,
                   const Axes::AxisSpec& ys) {
  Extent e;
  const auto& v = x ? s.x : s.y;
  const auto& o = x ? s.y : s.x;
  const Scale sv = x ? xs.scale : ys.scale;
  const Scale so = x ? ys.scale : xs.scale;
  for (std::size_t i = 0; i < v.size(); ++i) {
    // a point counts only if both coordinates are drawable
    if (!std::isfinite(o[i]) || (so == Scale::log10 && o[i] <= 0.0)) continue;
    e.add(v[i], sv);
  }
  return e;
}

std::string fmt_px(double v) {
  v = std::clamp(v, -kPxClamp, kPxClamp);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

struct Pt {
  double x, y;  // [px]
};

// Pixel-column reduction of a polyline (the "M4" idea): consecutive points that fall in the same
// 1-px column are replaced by the first, the lowest, the highest and the last of them, in their
// original order. The rendered line is the same at this resolution; a 10^6-sample recording
// becomes a few thousand points. Non-monotone x (paths) simply reduces less.
std::vector<Pt> m4_reduce(const std::vector<Pt>& run) {
  std::vector<Pt> out;
  out.reserve(std::min<std::size_t>(run.size(), 4096));
  std::size_t i = 0;
  const std::size_t n = run.size();
  while (i < n) {
    const double col = std::floor(run[i].x);
    std::size_t j = i, lo = i, hi = i;
    while (j + 1 < n && std::floor(run[j + 1].x) == col) {
      ++j;
      if (run[j].y < run[lo].y) lo = j;
      if (run[j].y > run[hi].y) hi = j;
    }
    std::array<std::size_t, 4> idx{i, std::min(lo, hi), std::max(lo, hi), j};
    std::size_t prev = n;  // none
    for (std::size_t k : idx) {
      if (k != prev) out.push_back(run[k]);
      prev = k;
    }
    i = j + 1;
  }
  return out;
}

// Appends "<cmd>x y" to a path's d attribute.
void lineto(std::string& d, char cmd, double x, double y) {
  d.push_back(cmd);
  d.append(fmt_px(x));
  d.push_back(' ');
  d.append(fmt_px(y));
}

struct LegendEntry {
  std::string label;
  bool patch = false;
  const LineStyle* line = nullptr;
  bool draw_line = true;
  const RectStyle* rect = nullptr;
};

constexpr double kLegendRow = 19.0, kLegendPad = 8.0, kLegendSample = 30.0;

std::vector<LegendEntry> legend_entries(const Axes::SeriesData* series, std::size_t n_series,
                                        const Axes::RectData* rects, std::size_t n_rects) {
  std::vector<LegendEntry> entries;
  for (std::size_t i = 0; i < n_rects; ++i) {
    const auto& rc = rects[i];
    if (!rc.style.label.empty()) entries.push_back({rc.style.label, true, nullptr, false, &rc.style});
  }
  for (std::size_t i = 0; i < n_series; ++i) {
    const auto& s = series[i];
    if (!s.style.label.empty()) entries.push_back({s.style.label, false, &s.style, s.draw_line, nullptr});
  }
  return entries;
}

// Width and height of the legend box [px].
std::pair<double, double> legend_size(const std::vector<LegendEntry>& entries) {
  double tw = 0.0;
  for (const auto& e : entries) tw = std::max(tw, text_width_px(e.label, kLegendFont));
  return {kLegendPad + kLegendSample + 7.0 + tw + kLegendPad,
          kLegendPad + kLegendRow * static_cast<double>(entries.size()) + kLegendPad - 4.0};
}

}  // namespace

struct FigureRenderer {
  const Figure& fig;
  std::string out;
  int clip_id = 0;

  struct Panel {
    const Axes* ax = nullptr;
    Box cell;
    Box area;
    AxisLayout xa, ya;
    bool x_ticklabels = true;
    bool x_label = true;
    double left = 0, right = 0, top = 0, bottom = 0;  // margins [px]
    double colorbar_w = 0;                            // right margin without an outside legend [px]
    Extent xdata, ydata;
  };

  explicit FigureRenderer(const Figure& f) : fig(f) {}

  // ---- layout ----
  void margins(Panel& p) const {
    const Axes& ax = *p.ax;
    double ytw = 0.0;
    for (const auto& l : p.ya.labels) ytw = std::max(ytw, text_width_px(l, kTickFont));
    p.left = 10.0 + (ax.y_.label.empty() ? 0.0 : 24.0) + ytw + kTickLen + 5.0;
    p.bottom = (p.x_ticklabels ? kTickLen + 5.0 + kTickFont + 2.0 : kTickLen + 3.0) +
               (p.x_label && !ax.x_.label.empty() ? 24.0 : 0.0) + 8.0;
    p.top = ax.title_.empty() ? 14.0 : 34.0;
    double last_xw = 0.0;
    if (p.x_ticklabels && !p.xa.labels.empty()) last_xw = text_width_px(p.xa.labels.back(), kTickFont);
    p.right = std::max(18.0, last_xw / 2.0 + 6.0);
    if (ax.colorbar_) {
      const auto& cb = *ax.colorbar_;
      LinearTicks t = nice_linear_ticks(cb.lo, cb.hi, 5);
      double w = 0.0;
      for (const auto& l : format_linear_ticks(t.values, t.step)) w = std::max(w, text_width_px(l, kTickFont));
      p.right = 18.0 + 16.0 + kTickLen + 4.0 + w + (cb.label.empty() ? 0.0 : 26.0) + 8.0;
    }
    p.colorbar_w = p.right;
    if (ax.legend_ == LegendPos::outside_right) {
      const auto entries = legend_entries(ax.series_.data(), ax.series_.size(), ax.rects_.data(), ax.rects_.size());
      if (!entries.empty()) p.right = (ax.colorbar_ ? p.right : 12.0) + legend_size(entries).first + 10.0;
    }
  }

  std::vector<Panel> layout() {
    const int rows = fig.rows_;
    const int cols = fig.cols_;
    const double top0 = fig.title_.empty() ? 0.0 : 40.0;
    const double cw = fig.width_ / cols;
    const double ch = (fig.height_ - top0) / rows;
    std::vector<Panel> ps(static_cast<std::size_t>(rows * cols));
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        Panel& p = ps[static_cast<std::size_t>(r * cols + c)];
        p.ax = &fig.axes(r, c);
        p.cell = Box{c * cw, top0 + r * ch, cw, ch};
        p.x_ticklabels = !fig.share_x_ || r == rows - 1;
        p.x_label = p.x_ticklabels;
        const Axes& ax = *p.ax;
        for (const auto& s : ax.series_) {
          p.xdata.merge(data_extent(s, true, ax.x_, ax.y_));
          p.ydata.merge(data_extent(s, false, ax.x_, ax.y_));
        }
        for (const auto& rl : ax.ref_lines_) (rl.horizontal ? p.ydata : p.xdata).add(rl.value, rl.horizontal ? ax.y_.scale : ax.x_.scale);
        for (const auto& rc : ax.rects_) {
          p.xdata.add(rc.x0, ax.x_.scale);
          p.xdata.add(rc.x1, ax.x_.scale);
          p.ydata.add(rc.y0, ax.y_.scale);
          p.ydata.add(rc.y1, ax.y_.scale);
        }
      }
    }
    if (fig.share_x_) {
      for (int c = 0; c < cols; ++c) {
        Extent e;
        for (int r = 0; r < rows; ++r) e.merge(ps[static_cast<std::size_t>(r * cols + c)].xdata);
        for (int r = 0; r < rows; ++r) ps[static_cast<std::size_t>(r * cols + c)].xdata = e;
      }
    }
    // Two passes: ticks depend on the plot size, margins depend on tick labels.
    for (auto& p : ps) {
      p.area = Box{p.cell.x + 70.0, p.cell.y + 30.0, std::max(p.cell.w - 100.0, 40.0),
                   std::max(p.cell.h - 80.0, 40.0)};
    }
    for (int pass = 0; pass < 2; ++pass) {
      for (auto& p : ps) {
        p.xa = autoscale(p.ax->x_, p.xdata, p.area.w, true);
        p.ya = autoscale(p.ax->y_, p.ydata, p.area.h, false);
        margins(p);
      }
      // align plot areas: same left/right per column, same top/bottom per row
      for (int c = 0; c < cols; ++c) {
        double l = 0, rr = 0;
        for (int r = 0; r < rows; ++r) {
          const auto& p = ps[static_cast<std::size_t>(r * cols + c)];
          l = std::max(l, p.left);
          rr = std::max(rr, p.right);
        }
        for (int r = 0; r < rows; ++r) {
          auto& p = ps[static_cast<std::size_t>(r * cols + c)];
          p.left = l;
          p.right = rr;
        }
      }
      for (int r = 0; r < rows; ++r) {
        double t = 0, b = 0;
        for (int c = 0; c < cols; ++c) {
          const auto& p = ps[static_cast<std::size_t>(r * cols + c)];
          t = std::max(t, p.top);
          b = std::max(b, p.bottom);
        }
        for (int c = 0; c < cols; ++c) {
          auto& p = ps[static_cast<std::size_t>(r * cols + c)];
          p.top = t;
          p.bottom = b;
        }
      }
      for (auto& p : ps) {
        p.area = Box{p.cell.x + p.left, p.cell.y + p.top, std::max(p.cell.w - p.left - p.right, 20.0),
                     std::max(p.cell.h - p.top - p.bottom, 20.0)};
      }
    }
    for (auto& p : ps) {
      if (p.ax->equal_aspect_) apply_equal_aspect(p);
    }
    return ps;
  }

  // One data unit gets the same pixel length on both axes. The axis with room to spare gets a
  // wider data range (centred), so the panel stays filled and aligned with its neighbours; if
  // both its limits are fixed, the box shrinks (centred) instead.
  static void apply_equal_aspect(Panel& p) {
    AxisLayout& xa = p.xa;
    AxisLayout& ya = p.ya;
    const double sx = xa.fwd(xa.hi) - xa.fwd(xa.lo);
    const double sy = ya.fwd(ya.hi) - ya.fwd(ya.lo);
    if (!(sx > 0.0 && sy > 0.0)) return;
    const double kx = p.area.w / sx;  // px per unit
    const double ky = p.area.h / sy;
    const bool x_fixed = !std::isnan(p.ax->x_.lo) && !std::isnan(p.ax->x_.hi);
    const bool y_fixed = !std::isnan(p.ax->y_.lo) && !std::isnan(p.ax->y_.hi);
    // widen to `need` units: around the centre, or away from the one fixed limit
    auto widen = [](AxisLayout& al, const Axes::AxisSpec& spec, double need, double length, bool is_x) {
      const double u0 = al.fwd(al.lo), u1 = al.fwd(al.hi);
      if (!std::isnan(spec.lo)) {
        al.hi = al.inv(u0 + need);
      } else if (!std::isnan(spec.hi)) {
        al.lo = al.inv(u1 - need);
      } else {
        const double mid = 0.5 * (u0 + u1);
        al.lo = al.inv(mid - need / 2);
        al.hi = al.inv(mid + need / 2);
      }
      compute_ticks(al, length, is_x);
    };
    if (kx > ky) {
      // x has room: show more x (or narrow the box)
      if (!x_fixed) {
        widen(xa, p.ax->x_, p.area.w / ky, p.area.w, true);
      } else {
        const double w = sx * ky;
        p.area.x += (p.area.w - w) / 2.0;
        p.area.w = w;
      }
    } else if (ky > kx) {
      if (!y_fixed) {
        widen(ya, p.ax->y_, p.area.h / kx, p.area.h, false);
      } else {
        const double h = sy * kx;
        p.area.y += (p.area.h - h) / 2.0;
        p.area.h = h;
      }
    }
  }

  // ---- drawing helpers ----
  static double px(const Panel& p, double x) { return p.area.x + p.xa.frac(x) * p.area.w; }
  static double py(const Panel& p, double y) { return p.area.bottom() - p.ya.frac(y) * p.area.h; }

  void text(double x, double y, std::string_view s, double size, Anchor a, const Color& c,
            bool bold = false, double rotate = 0.0, bool halo = false) {
    out += "<text x=\"" + fmt_px(x) + "\" y=\"" + fmt_px(y) + "\"";
    add(out, " font-size=\"%.1f\" text-anchor=\"%s\" fill=\"%s\"", size, anchor_attr(a), c.hex().c_str());
    if (bold) out += " font-weight=\"bold\"";
    if (rotate != 0.0) add(out, " transform=\"rotate(%.1f %s %s)\"", rotate, fmt_px(x).c_str(), fmt_px(y).c_str());
    if (halo) out += " stroke=\"white\" stroke-width=\"3\" stroke-linejoin=\"round\" paint-order=\"stroke\"";
    out += ">" + esc(s) + "</text>\n";
  }

  void marker_shape(Marker m, double cx, double cy, double size) {
    const double r = size / 2.0;
    switch (m) {
      case Marker::none: return;
      case Marker::circle:
        out += "<circle cx=\"" + fmt_px(cx) + "\" cy=\"" + fmt_px(cy) + "\" r=\"" + fmt_px(r) + "\"/>";
        return;
      case Marker::square:
        out += "<rect x=\"" + fmt_px(cx - 0.88 * r) + "\" y=\"" + fmt_px(cy - 0.88 * r) + "\" width=\"" +
               fmt_px(1.76 * r) + "\" height=\"" + fmt_px(1.76 * r) + "\"/>";
        return;
      case Marker::triangle:
        out += "<path d=\"M" + fmt_px(cx) + " " + fmt_px(cy - 1.15 * r) + "L" + fmt_px(cx + r) + " " +
               fmt_px(cy + 0.6 * r) + "L" + fmt_px(cx - r) + " " + fmt_px(cy + 0.6 * r) + "Z\"/>";
        return;
      case Marker::diamond:
        out += "<path d=\"M" + fmt_px(cx) + " " + fmt_px(cy - 1.2 * r) + "L" + fmt_px(cx + 0.9 * r) + " " +
               fmt_px(cy) + "L" + fmt_px(cx) + " " + fmt_px(cy + 1.2 * r) + "L" + fmt_px(cx - 0.9 * r) +
               " " + fmt_px(cy) + "Z\"/>";
        return;
      case Marker::cross:
        out += "<path d=\"M" + fmt_px(cx - r) + " " + fmt_px(cy - r) + "L" + fmt_px(cx + r) + " " +
               fmt_px(cy + r) + "M" + fmt_px(cx - r) + " " + fmt_px(cy + r) + "L" + fmt_px(cx + r) + " " +
               fmt_px(cy - r) + "\"/>";
        return;
      case Marker::plus:
        out += "<path d=\"M" + fmt_px(cx - r) + " " + fmt_px(cy) + "L" + fmt_px(cx + r) + " " +
               fmt_px(cy) + "M" + fmt_px(cx) + " " + fmt_px(cy - r) + "L" + fmt_px(cx) + " " +
               fmt_px(cy + r) + "\"/>";
        return;
    }
  }

  // Opening tag of a group carrying the paint of a series' markers.
  void marker_group_open(const LineStyle& st) {
    const Color c = st.color.value_or(colors::black);
    const bool stroke_only = st.marker == Marker::cross || st.marker == Marker::plus;
    if (stroke_only) {
      add(out, "<g class=\"markers\" fill=\"none\" stroke=\"%s\" stroke-width=\"1.6\" opacity=\"%.3g\">",
          c.hex().c_str(), st.opacity);
    } else if (st.hollow_markers) {
      add(out, "<g class=\"markers\" fill=\"white\" stroke=\"%s\" stroke-width=\"1.5\" opacity=\"%.3g\">",
          c.hex().c_str(), st.opacity);
    } else {
      add(out, "<g class=\"markers\" fill=\"%s\" stroke=\"white\" stroke-width=\"0.8\" opacity=\"%.3g\">",
          c.hex().c_str(), st.opacity);
    }
  }

  // ---- one panel ----
  void draw_panel(const Panel& p) {
    const Axes& ax = *p.ax;
    const Box& a = p.area;
    const int cid = clip_id++;
    out += "<g class=\"axes\">\n";
    add(out, "<clipPath id=\"clip%d\"><rect x=\"%s\" y=\"%s\" width=\"%s\" height=\"%s\"/></clipPath>\n", cid,
        fmt_px(a.x).c_str(), fmt_px(a.y).c_str(), fmt_px(a.w).c_str(), fmt_px(a.h).c_str());

    // grid
    if (ax.grid_) {
      out += "<g class=\"grid\" stroke-width=\"1\">\n";
      auto gx = [&](double v, const char* col) {
        if (!p.xa.valid(v)) return;
        const std::string X = fmt_px(px(p, v));
        add(out, "<line x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\" stroke=\"%s\"/>\n", X.c_str(),
            fmt_px(a.y).c_str(), X.c_str(), fmt_px(a.bottom()).c_str(), col);
      };
      auto gy = [&](double v, const char* col) {
        if (!p.ya.valid(v)) return;
        const std::string Y = fmt_px(py(p, v));
        add(out, "<line x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\" stroke=\"%s\"/>\n", fmt_px(a.x).c_str(),
            Y.c_str(), fmt_px(a.right()).c_str(), Y.c_str(), col);
      };
      for (double v : p.xa.minor) gx(v, "#f1f1f1");
      for (double v : p.ya.minor) gy(v, "#f1f1f1");
      for (double v : p.xa.major) gx(v, "#dedede");
      for (double v : p.ya.major) gy(v, "#dedede");
      out += "</g>\n";
    }

    add(out, "<g clip-path=\"url(#clip%d)\">\n", cid);
    // rectangles
    for (const auto& rc : ax.rects_) {
      auto cx = [&](double v, bool low) {
        if (std::isnan(v)) return low ? a.x : a.right();
        if (std::isinf(v) || (p.xa.scale == Scale::log10 && v <= 0.0)) return (v > 0 && std::isinf(v)) ? a.right() + 2 : a.x - 2;
        return px(p, v);
      };
      auto cy = [&](double v, bool low) {
        if (std::isnan(v)) return low ? a.bottom() : a.y;
        if (std::isinf(v) || (p.ya.scale == Scale::log10 && v <= 0.0)) return (v > 0 && std::isinf(v)) ? a.y - 2 : a.bottom() + 2;
        return py(p, v);
      };
      const double x0 = cx(rc.x0, true), x1 = cx(rc.x1, false);
      const double y0 = cy(rc.y0, true), y1 = cy(rc.y1, false);
      out += "<rect class=\"patch\" x=\"" + fmt_px(std::min(x0, x1)) + "\" y=\"" + fmt_px(std::min(y0, y1)) +
             "\" width=\"" + fmt_px(std::abs(x1 - x0)) + "\" height=\"" + fmt_px(std::abs(y1 - y0)) + "\"";
      add(out, " fill=\"%s\" fill-opacity=\"%.3g\"", rc.style.fill.hex().c_str(), rc.style.opacity);
      if (rc.style.edge) add(out, " stroke=\"%s\" stroke-width=\"%.2g\"", rc.style.edge->hex().c_str(), rc.style.edge_px);
      out += "/>\n";
    }
    // reference lines
    for (const auto& rl : ax.ref_lines_) {
      const AxisLayout& al = rl.horizontal ? p.ya : p.xa;
      if (!al.valid(rl.value)) continue;
      const double f = al.frac(rl.value);
      if (f < -1e-9 || f > 1 + 1e-9) continue;
      const auto& st = rl.style;
      std::string x1, y1, x2, y2;
      if (rl.horizontal) {
        x1 = fmt_px(a.x), x2 = fmt_px(a.right()), y1 = y2 = fmt_px(py(p, rl.value));
      } else {
        y1 = fmt_px(a.y), y2 = fmt_px(a.bottom()), x1 = x2 = fmt_px(px(p, rl.value));
      }
      add(out, "<line class=\"refline\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\" stroke=\"%s\" stroke-width=\"%.2g\"%s/>\n",
          x1.c_str(), y1.c_str(), x2.c_str(), y2.c_str(), st.color.hex().c_str(), st.width_px,
          dash_attr(st.dash, st.width_px).c_str());
    }
    // series lines: one <path> per series, one subpath per run of valid points
    for (std::size_t si = 0; si < ax.series_.size(); ++si) {
      const auto& s = ax.series_[si];
      if (!s.draw_line) continue;
      std::string d;
      std::vector<Pt> run;  // current run of valid points [px]
      auto flush = [&] {
        if (run.empty()) return;
        const std::vector<Pt> pts = m4_reduce(run);
        if (!d.empty()) d.push_back(' ');
        lineto(d, 'M', pts[0].x, pts[0].y);
        Pt last = pts[0];
        for (std::size_t k = 1; k < pts.size(); ++k) {
          // drop points closer than 0.3 px to the last drawn one, but keep the run's end
          if (k + 1 < pts.size() && std::abs(pts[k].x - last.x) < 0.3 && std::abs(pts[k].y - last.y) < 0.3) continue;
          lineto(d, 'L', pts[k].x, pts[k].y);
          last = pts[k];
        }
        run.clear();
      };
      for (std::size_t i = 0; i < s.x.size(); ++i) {
        if (!p.xa.valid(s.x[i]) || !p.ya.valid(s.y[i])) {
          flush();
          continue;
        }
        run.push_back({px(p, s.x[i]), py(p, s.y[i])});
      }
      flush();
      const auto& st = s.style;
      add(out, "<path class=\"series\" data-series=\"%zu\" fill=\"none\" stroke=\"%s\" stroke-width=\"%.3g\" "
               "stroke-opacity=\"%.3g\" stroke-linejoin=\"round\" stroke-linecap=\"round\"%s d=\"",
          si, st.color.value_or(colors::black).hex().c_str(), st.width_px, st.opacity,
          dash_attr(st.dash, st.width_px).c_str());
      out += d + "\"/>\n";
    }
    // markers
    for (const auto& s : ax.series_) {
      if (s.style.marker == Marker::none) continue;
      marker_group_open(s.style);
      for (std::size_t i = 0; i < s.x.size(); ++i) {
        if (!p.xa.valid(s.x[i]) || !p.ya.valid(s.y[i])) continue;
        marker_shape(s.style.marker, px(p, s.x[i]), py(p, s.y[i]), s.style.marker_px);
      }
      out += "</g>\n";
    }
    out += "</g>\n";

    // reference line labels (outside the clip so they are never cut)
    for (const auto& rl : ax.ref_lines_) {
      if (rl.style.label.empty()) continue;
      const AxisLayout& al = rl.horizontal ? p.ya : p.xa;
      if (!al.valid(rl.value)) continue;
      const double f = al.frac(rl.value);
      if (f < -1e-9 || f > 1 + 1e-9) continue;
      const double tw = text_width_px(rl.style.label, kRefFont);
      double tx = 0.0, ty = 0.0;  // baseline start of the label
      if (rl.horizontal) {
        const double y = py(p, rl.value);
        tx = a.right() - 5.0 - tw;
        ty = (y - a.y < 18.0) ? y + 14.0 : y - 5.0;
      } else {
        tx = px(p, rl.value) + 5.0;
        ty = a.y + 15.0;
      }
      add(out, "<rect class=\"reflabel-bg\" x=\"%s\" y=\"%s\" width=\"%s\" height=\"%s\" fill=\"white\" fill-opacity=\"0.85\"/>\n",
          fmt_px(tx - 2.0).c_str(), fmt_px(ty - kRefFont + 1.0).c_str(), fmt_px(tw + 4.0).c_str(),
          fmt_px(kRefFont + 3.0).c_str());
      text(tx, ty, rl.style.label, kRefFont, Anchor::start, rl.style.color);
    }

    // frame
    add(out, "<rect class=\"frame\" x=\"%s\" y=\"%s\" width=\"%s\" height=\"%s\" fill=\"none\" stroke=\"#404040\" stroke-width=\"1\"/>\n",
        fmt_px(a.x).c_str(), fmt_px(a.y).c_str(), fmt_px(a.w).c_str(), fmt_px(a.h).c_str());

    // ticks and tick labels
    out += "<g class=\"ticks\" stroke=\"#404040\" stroke-width=\"1\">\n";
    for (double v : p.xa.minor) {
      const std::string X = fmt_px(px(p, v));
      add(out, "<line class=\"xminor\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\"/>\n", X.c_str(), fmt_px(a.bottom()).c_str(),
          X.c_str(), fmt_px(a.bottom() + kMinorLen).c_str());
    }
    for (double v : p.ya.minor) {
      const std::string Y = fmt_px(py(p, v));
      add(out, "<line class=\"yminor\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\"/>\n", fmt_px(a.x - kMinorLen).c_str(),
          Y.c_str(), fmt_px(a.x).c_str(), Y.c_str());
    }
    for (double v : p.xa.major) {
      const std::string X = fmt_px(px(p, v));
      add(out, "<line class=\"xtick\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\"/>\n", X.c_str(), fmt_px(a.bottom()).c_str(),
          X.c_str(), fmt_px(a.bottom() + kTickLen).c_str());
    }
    for (double v : p.ya.major) {
      const std::string Y = fmt_px(py(p, v));
      add(out, "<line class=\"ytick\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\"/>\n", fmt_px(a.x - kTickLen).c_str(),
          Y.c_str(), fmt_px(a.x).c_str(), Y.c_str());
    }
    out += "</g>\n<g class=\"ticklabels\">\n";
    const Color tick_color{34, 34, 34};
    if (p.x_ticklabels) {
      for (std::size_t i = 0; i < p.xa.major.size(); ++i) {
        text(px(p, p.xa.major[i]), a.bottom() + kTickLen + 3.0 + kTickFont * 0.95, p.xa.labels[i], kTickFont,
             Anchor::middle, tick_color);
      }
    }
    for (std::size_t i = 0; i < p.ya.major.size(); ++i) {
      text(a.x - kTickLen - 4.0, py(p, p.ya.major[i]) + kTickFont * 0.36, p.ya.labels[i], kTickFont, Anchor::end,
           tick_color);
    }
    out += "</g>\n";

    // axis labels and title
    const Color label_color{20, 20, 20};
    if (p.x_label && !ax.x_.label.empty()) {
      const double y = a.bottom() + (p.x_ticklabels ? kTickLen + 5.0 + kTickFont : kTickLen) + 4.0 + kLabelFont;
      text(a.x + a.w / 2.0, y, ax.x_.label, kLabelFont, Anchor::middle, label_color);
    }
    if (!ax.y_.label.empty()) {
      text(p.cell.x + 10.0 + kLabelFont, a.y + a.h / 2.0, ax.y_.label, kLabelFont, Anchor::middle, label_color,
           false, -90.0);
    }
    if (!ax.title_.empty()) {
      text(a.x + a.w / 2.0, a.y - 10.0, ax.title_, kTitleFont, Anchor::middle, label_color, true);
    }

    // annotations
    for (const auto& t : ax.texts_) {
      if (!p.xa.valid(t.x) || !p.ya.valid(t.y)) continue;
      text(px(p, t.x) + t.style.dx_px, py(p, t.y) + t.style.dy_px, t.text, t.style.size_px, t.style.anchor,
           t.style.color, t.style.bold, 0.0, true);
    }

    if (ax.colorbar_) draw_colorbar(p, cid);
    if (ax.legend_ != LegendPos::none) draw_legend(p);
    out += "</g>\n";
  }

  void draw_colorbar(const Panel& p, int cid) {
    const auto& cb = *p.ax->colorbar_;
    const Box bar{p.area.right() + 18.0, p.area.y, 16.0, p.area.h};
    add(out, "<defs><linearGradient id=\"cbar%d\" x1=\"0\" y1=\"1\" x2=\"0\" y2=\"0\">", cid);
    constexpr int kStops = 16;
    for (int i = 0; i <= kStops; ++i) {
      const double t = static_cast<double>(i) / kStops;
      add(out, "<stop offset=\"%.4f\" stop-color=\"%s\"/>", t, colormap(cb.map, t).hex().c_str());
    }
    out += "</linearGradient></defs>\n";
    add(out, "<rect class=\"colorbar\" x=\"%s\" y=\"%s\" width=\"%s\" height=\"%s\" fill=\"url(#cbar%d)\" stroke=\"#404040\" stroke-width=\"1\"/>\n",
        fmt_px(bar.x).c_str(), fmt_px(bar.y).c_str(), fmt_px(bar.w).c_str(), fmt_px(bar.h).c_str(), cid);
    double lo = cb.lo, hi = cb.hi;
    if (hi < lo) std::swap(lo, hi);
    const double span = (hi > lo) ? hi - lo : 1.0;
    LinearTicks t = nice_linear_ticks(lo, hi, std::clamp(static_cast<int>(bar.h / 60.0), 3, 8));
    const auto labels = format_linear_ticks(t.values, t.step);
    double w = 0.0;
    for (std::size_t i = 0; i < t.values.size(); ++i) {
      const double f = (t.values[i] - lo) / span;
      if (f < -1e-9 || f > 1 + 1e-9) continue;
      const double y = bar.bottom() - f * bar.h;
      add(out, "<line x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\" stroke=\"#404040\"/>\n", fmt_px(bar.right()).c_str(),
          fmt_px(y).c_str(), fmt_px(bar.right() + kTickLen).c_str(), fmt_px(y).c_str());
      text(bar.right() + kTickLen + 3.0, y + kTickFont * 0.36, labels[i], kTickFont, Anchor::start, Color{34, 34, 34});
      w = std::max(w, text_width_px(labels[i], kTickFont));
    }
    if (!cb.label.empty()) {
      const double x = bar.right() + kTickLen + 3.0 + w + 8.0 + kLabelFont * 0.8;
      text(x, bar.y + bar.h / 2.0, cb.label, kLabelFont, Anchor::middle, Color{20, 20, 20}, false, 90.0);
    }
  }

  // Legend-box placement cost: data points, reference lines and their labels, patches and
  // annotations it would cover.
  static double legend_cost(const Panel& p, const Box& b) {
    const Axes& ax = *p.ax;
    const Box& a = p.area;
    auto inside = [&](double X, double Y, double m) {
      return X >= b.x - m && X <= b.right() + m && Y >= b.y - m && Y <= b.bottom() + m;
    };
    double hits = 0.0;
    for (const auto& s : ax.series_) {
      const std::size_t step = std::max<std::size_t>(1, s.x.size() / 2000);
      for (std::size_t i = 0; i < s.x.size(); i += step) {
        if (!p.xa.valid(s.x[i]) || !p.ya.valid(s.y[i])) continue;
        if (inside(px(p, s.x[i]), py(p, s.y[i]), 4.0)) hits += static_cast<double>(step);
      }
    }
    for (const auto& rl : ax.ref_lines_) {
      const AxisLayout& al = rl.horizontal ? p.ya : p.xa;
      if (!al.valid(rl.value)) continue;
      if (rl.horizontal) {
        const double y = py(p, rl.value);
        if (y >= b.y - 3 && y <= b.bottom() + 3) hits += 20.0;
        // label at the right end, above the line
        if (!rl.style.label.empty() && inside(a.right() - 20.0, y - 8.0, 6.0)) hits += 200.0;
      } else {
        const double x = px(p, rl.value);
        if (x >= b.x - 3 && x <= b.right() + 3) hits += 20.0;
        if (!rl.style.label.empty() && inside(x + 20.0, a.y + 8.0, 6.0)) hits += 200.0;
      }
    }
    for (const auto& rc : ax.rects_) {
      // finite patches only (ground strips and spans reach the frame and cannot be avoided)
      if (!std::isfinite(rc.x0) || !std::isfinite(rc.x1) || !std::isfinite(rc.y0) || !std::isfinite(rc.y1)) continue;
      if (!p.xa.valid(rc.x0) || !p.xa.valid(rc.x1) || !p.ya.valid(rc.y0) || !p.ya.valid(rc.y1)) continue;
      const double x0 = px(p, rc.x0), x1 = px(p, rc.x1), y0 = py(p, rc.y1), y1 = py(p, rc.y0);
      const double ox = std::max(0.0, std::min(x1, b.right()) - std::max(x0, b.x));
      const double oy = std::max(0.0, std::min(y1, b.bottom()) - std::max(y0, b.y));
      hits += ox * oy / 20.0;
    }
    for (const auto& t : ax.texts_) {
      if (!p.xa.valid(t.x) || !p.ya.valid(t.y)) continue;
      if (inside(px(p, t.x), py(p, t.y), 10.0)) hits += 100.0;
    }
    return hits;
  }

  void draw_legend(const Panel& p) {
    const Axes& ax = *p.ax;
    const std::vector<LegendEntry> entries =
        legend_entries(ax.series_.data(), ax.series_.size(), ax.rects_.data(), ax.rects_.size());
    if (entries.empty()) return;
    constexpr double kRow = kLegendRow, kPad = kLegendPad, kSample = kLegendSample;
    const auto size = legend_size(entries);
    const double w = size.first, h = size.second;
    const Box& a = p.area;
    constexpr double kInset = 8.0;
    auto corner = [&](LegendPos pos) {
      switch (pos) {
        case LegendPos::upper_left: return Box{a.x + kInset, a.y + kInset, w, h};
        case LegendPos::lower_left: return Box{a.x + kInset, a.bottom() - kInset - h, w, h};
        case LegendPos::lower_right: return Box{a.right() - kInset - w, a.bottom() - kInset - h, w, h};
        case LegendPos::outside_right:
          return Box{a.right() + (ax.colorbar_ ? p.colorbar_w : 12.0), a.y, w, h};
        default: return Box{a.right() - kInset - w, a.y + kInset, w, h};
      }
    };
    LegendPos pos = ax.legend_;
    if (pos == LegendPos::best) {
      // corner covering the least, upper right preferred on ties
      double best = std::numeric_limits<double>::infinity();
      for (LegendPos c : {LegendPos::upper_right, LegendPos::upper_left, LegendPos::lower_left, LegendPos::lower_right}) {
        const double cost = legend_cost(p, corner(c));
        if (cost < best) {
          best = cost;
          pos = c;
        }
      }
    }
    const Box b = corner(pos);
    out += "<g class=\"legend\">\n";
    add(out, "<rect x=\"%s\" y=\"%s\" width=\"%s\" height=\"%s\" rx=\"3\" fill=\"white\" fill-opacity=\"0.88\" stroke=\"#b0b0b0\" stroke-width=\"1\"/>\n",
        fmt_px(b.x).c_str(), fmt_px(b.y).c_str(), fmt_px(b.w).c_str(), fmt_px(b.h).c_str());
    for (std::size_t i = 0; i < entries.size(); ++i) {
      const auto& e = entries[i];
      const double cy = b.y + kPad + kRow * (static_cast<double>(i) + 0.5) - 2.0;
      const double sx0 = b.x + kPad, sx1 = sx0 + kSample;
      if (e.patch) {
        const auto& st = *e.rect;
        add(out, "<rect x=\"%s\" y=\"%s\" width=\"%s\" height=\"10\" fill=\"%s\" fill-opacity=\"%.3g\"", fmt_px(sx0 + 4).c_str(),
            fmt_px(cy - 5).c_str(), fmt_px(kSample - 8).c_str(), st.fill.hex().c_str(), std::max(st.opacity, 0.25));
        if (st.edge) add(out, " stroke=\"%s\" stroke-width=\"1\"", st.edge->hex().c_str());
        out += "/>\n";
      } else {
        const auto& st = *e.line;
        if (e.draw_line) {
          add(out, "<line class=\"legend-line\" x1=\"%s\" y1=\"%s\" x2=\"%s\" y2=\"%s\" stroke=\"%s\" stroke-width=\"%.3g\" stroke-opacity=\"%.3g\"%s/>\n",
              fmt_px(sx0).c_str(), fmt_px(cy).c_str(), fmt_px(sx1).c_str(), fmt_px(cy).c_str(),
              st.color.value_or(colors::black).hex().c_str(), std::min(st.width_px, 4.0), st.opacity,
              dash_attr(st.dash, std::min(st.width_px, 4.0)).c_str());
        }
        if (st.marker != Marker::none) {
          marker_group_open(st);
          marker_shape(st.marker, (sx0 + sx1) / 2.0, cy, std::min(st.marker_px, 10.0));
          out += "</g>\n";
        }
      }
      out += "<text class=\"legend-label\"";
      add(out, " x=\"%s\" y=\"%s\" font-size=\"%.1f\" fill=\"#202020\">", fmt_px(sx1 + 7.0).c_str(),
          fmt_px(cy + kLegendFont * 0.36).c_str(), kLegendFont);
      out += esc(e.label) + "</text>\n";
    }
    out += "</g>\n";
  }

  std::string render() {
    std::vector<Panel> ps = layout();
    out.clear();
    add(out, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
             "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" viewBox=\"0 0 %.0f %.0f\" "
             "font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\">\n",
        fig.width_, fig.height_, fig.width_, fig.height_);
    out += "<rect class=\"background\" width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    if (!fig.title_.empty()) {
      text(fig.width_ / 2.0, 27.0, fig.title_, kSupTitleFont, Anchor::middle, Color{10, 10, 10}, true);
    }
    for (const auto& p : ps) draw_panel(p);
    out += "</svg>\n";
    return std::move(out);
  }
};

std::string Figure::to_svg() const {
  FigureRenderer r(*this);
  return r.render();
}

void Figure::write_svg(const std::filesystem::path& path) const {
  const std::string svg = to_svg();
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error("cannot open '" + path.string() + "' for writing the SVG");
  f.write(svg.data(), static_cast<std::streamsize>(svg.size()));
  f.close();
  if (!f) throw std::runtime_error("error writing the SVG to '" + path.string() + "'");
}

std::optional<std::filesystem::path> find_rsvg_convert() {
  const char* env = std::getenv("PATH");
  std::string_view path = env ? env : "/usr/local/bin:/usr/bin:/bin";
  while (!path.empty()) {
    const std::size_t colon = path.find(':');
    std::string dir(path.substr(0, colon));
    path = colon == std::string_view::npos ? std::string_view{} : path.substr(colon + 1);
    if (dir.empty()) dir.push_back('.');
    const std::filesystem::path cand = std::filesystem::path(dir) / "rsvg-convert";
    if (::access(cand.c_str(), X_OK) == 0) return cand;
  }
  return std::nullopt;
}

std::string svg_to_png(const std::filesystem::path& svg, const std::filesystem::path& png, double zoom) {
  const auto exe = find_rsvg_convert();
  if (!exe) return "rsvg-convert not found on PATH (Debian package librsvg2-bin)";
  char zbuf[32];
  std::snprintf(zbuf, sizeof zbuf, "%.3g", (zoom > 0.0 && std::isfinite(zoom)) ? zoom : 1.0);
  std::vector<std::string> args{exe->string(), "-u", "-b", "white", "-z", zbuf, "-o", png.string(), svg.string()};
  std::vector<char*> argv;
  for (auto& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = ::posix_spawn(&pid, exe->c_str(), nullptr, nullptr, argv.data(), environ);
  if (rc != 0) return "cannot start " + exe->string() + ": error " + std::to_string(rc);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return "waitpid on rsvg-convert failed";
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    return "rsvg-convert failed on '" + svg.string() + "' (status " + std::to_string(status) + ")";
  }
  return {};
}

SaveResult Figure::save(const std::filesystem::path& svg_path, bool png, double png_zoom) const {
  SaveResult r;
  write_svg(svg_path);
  r.svg = svg_path;
  if (!png) {
    r.note = "wrote " + svg_path.string();
    return r;
  }
  std::filesystem::path png_path = svg_path;
  png_path.replace_extension(".png");
  const std::string err = svg_to_png(svg_path, png_path, png_zoom);
  if (err.empty()) {
    r.png = png_path;
    r.note = "wrote " + svg_path.string() + " and " + png_path.string();
  } else {
    r.note = "wrote " + svg_path.string() + " only (no PNG: " + err + ")";
  }
  return r;
}

}  // namespace pedalwave::toolkit
