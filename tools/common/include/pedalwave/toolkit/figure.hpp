// Self-contained SVG plotting (no gnuplot, no matplotlib): a Figure is a grid of Axes panels;
// each panel holds line series, scatter markers, reference lines, shaded rectangles, text
// annotations, an optional colour bar and a legend, on linear or log10 axes.
//
// Usage:
//   Figure fig(1, 1);                                   // one panel, 1000 × 600 px
//   auto& ax = fig.axes();
//   ax.xscale(Scale::log10).yscale(Scale::log10).xlabel("wall time [s]").ylabel("error [m]");
//   ax.line(cost, err, {.label = "RK4", .marker = Marker::circle});
//   ax.hline(1e-3, {.label = "1 mm"});
//   SaveResult r = fig.save("out/work_precision.svg");  // also .png when rsvg-convert exists
//   std::cerr << r.note << '\n';
//
// Data are copied into the figure. Points whose x or y is NaN or ±Inf (or ≤ 0 on a log axis)
// break a line: the series is drawn as separate pieces on either side and the point is skipped.
// All sizes are in SVG user units, which are pixels at the default PNG zoom.
#pragma once

#include <cstddef>
#include <filesystem>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pedalwave/toolkit/color.hpp"

namespace pedalwave::toolkit {

enum class Scale { linear, log10 };
enum class Dash { solid, dashed, dotted, dash_dot };
enum class Marker { none, circle, square, triangle, diamond, cross, plus };
// Legend placement: inside a corner of the panel (best = the corner covering the least data,
// reference lines and patches), to the right of the panel (and of its colour bar), or none.
enum class LegendPos { best, upper_right, upper_left, lower_left, lower_right, outside_right, none };
enum class Anchor { start, middle, end };

// Style of a line or scatter series. Designated initializers: {.label = "RK4", .width_px = 2}.
struct LineStyle {
  std::string label{};             // legend text; empty = not in the legend
  std::optional<Color> color{};    // default: the panel's next colour of cycle_color()
  double width_px = 1.8;         // stroke width [px]; line() only
  Dash dash = Dash::solid;       // stroke pattern; line() only
  Marker marker = Marker::none;  // marker at every valid point (scatter() defaults to circle)
  double marker_px = 6.0;        // marker size (diameter) [px]
  bool hollow_markers = false;   // white-filled markers with a coloured outline
  double opacity = 1.0;          // stroke/fill opacity [0..1]
};

// Style of a horizontal or vertical reference line across the whole panel.
struct RefLineStyle {
  std::string label{};             // drawn as small text at the line's end (not in the legend)
  Color color = colors::gray;    // stroke colour
  double width_px = 1.3;         // stroke width [px]
  Dash dash = Dash::dashed;      // stroke pattern
};

// Style of a shaded rectangle (obstacle, surface patch, time window).
struct RectStyle {
  std::string label{};             // legend text (as a filled patch); empty = not in the legend
  Color fill = colors::light_gray;
  double opacity = 0.35;         // fill opacity [0..1]
  std::optional<Color> edge{};     // outline colour; none = no outline
  double edge_px = 1.0;          // outline width [px]
};

// Style of a text annotation placed at a data point.
struct TextStyle {
  double size_px = 12.0;         // font size [px]
  Color color = colors::dark_gray;
  Anchor anchor = Anchor::start; // horizontal anchoring at the point
  bool bold = false;
  double dx_px = 0.0;            // offset right of the point [px]
  double dy_px = 0.0;            // offset below the point [px] (SVG y grows downwards)
};

// One panel of a Figure. Every method returns *this for chaining. Methods taking data throw
// std::invalid_argument naming the series label and both sizes when x and y differ in length.
class Axes {
 public:
  // Line through (x[i], y[i]) in order; non-finite points break it.
  Axes& line(std::span<const double> x, std::span<const double> y, LineStyle style = {});
  // Markers only at (x[i], y[i]); marker defaults to a circle when style.marker is none.
  Axes& scatter(std::span<const double> x, std::span<const double> y, LineStyle style = {});
  // Reference lines across the panel at y (horizontal) or x (vertical), included in autoscale.
  Axes& hline(double y, RefLineStyle style = {});
  Axes& vline(double x, RefLineStyle style = {});
  // Rectangle [x0, x1] × [y0, y1] in data units, drawn beneath the series. ±Inf bounds extend
  // to the panel's edge (e.g. ground below z = 0: rect(-inf, inf, -inf, 0)); finite bounds are
  // included in autoscale.
  Axes& rect(double x0, double x1, double y0, double y1, RectStyle style = {});
  // Text at data point (x, y).
  Axes& text(double x, double y, std::string text, TextStyle style = {});
  // Vertical colour bar right of the panel mapping [lo, hi] through `map` (e.g. time of snapshots).
  Axes& colorbar(Colormap map, double lo, double hi, std::string label = "");

  Axes& title(std::string text);
  Axes& xlabel(std::string text);
  Axes& ylabel(std::string text);
  Axes& xscale(Scale s);
  Axes& yscale(Scale s);
  // Fixed limits; pass NaN for a side that should stay automatic. Throws std::invalid_argument
  // naming the value when a bound is ±Inf (or ≤ 0 on a log axis, checked when rendering).
  Axes& xlim(double lo, double hi);
  Axes& ylim(double lo, double hi);
  // Automatic range padding as a fraction of the data span on each side (default 0.04; log
  // axes pad in decades). 0 = the data touch the frame (time series).
  Axes& xmargin(double fraction);
  Axes& ymargin(double fraction);
  // One data unit has the same length on x and y: the axis with room to spare shows a wider
  // data range (centred); if both its limits are fixed the plot box shrinks instead.
  Axes& equal_aspect(bool on = true);
  Axes& legend(LegendPos pos);
  Axes& grid(bool on);

  [[nodiscard]] std::size_t series_count() const { return series_.size(); }

  struct SeriesData {
    std::vector<double> x{};  // abscissae [x unit], (n)
    std::vector<double> y{};  // ordinates [y unit], (n)
    LineStyle style;        // colour resolved at insertion
    bool draw_line = true;  // false for scatter()
  };
  struct RefLine {
    bool horizontal = true;
    double value = 0.0;     // y (horizontal) or x (vertical) [data unit]
    RefLineStyle style;
  };
  struct RectData {
    double x0, x1, y0, y1;  // bounds [data units]; ±Inf = panel edge
    RectStyle style;
  };
  struct TextData {
    double x, y;            // anchor point [data units]
    std::string text{};
    TextStyle style;
  };
  struct ColorbarData {
    Colormap map = Colormap::viridis;
    double lo = 0.0, hi = 1.0;  // values at the bottom and top of the bar
    std::string label{};
  };
  struct AxisSpec {
    std::string label{};
    Scale scale = Scale::linear;
    double lo, hi;          // NaN = automatic
    double margin = 0.04;   // padding fraction of the span (or of the decades on log)
  };

 private:
  friend class Figure;
  friend struct FigureRenderer;
  std::vector<SeriesData> series_{};
  std::vector<RefLine> ref_lines_{};
  std::vector<RectData> rects_{};
  std::vector<TextData> texts_{};
  std::optional<ColorbarData> colorbar_{};
  AxisSpec x_{"", Scale::linear, kAuto, kAuto, 0.04};
  AxisSpec y_{"", Scale::linear, kAuto, kAuto, 0.04};
  std::string title_{};
  bool equal_aspect_ = false;
  bool grid_ = true;
  LegendPos legend_ = LegendPos::best;
  std::size_t next_color_ = 0;
  static constexpr double kAuto = std::numeric_limits<double>::quiet_NaN();
};

// What Figure::save wrote.
struct SaveResult {
  std::filesystem::path svg;                 // always written
  std::optional<std::filesystem::path> png{};  // set when the PNG conversion succeeded
  std::string note{};                          // one line for the user: what was written, or why
                                             // only the SVG was
};

class Figure {
 public:
  // A rows × cols grid of panels on a width × height canvas [px]. Throws std::invalid_argument
  // when rows or cols < 1 or a size is not in [100, 20000] px.
  explicit Figure(int rows = 1, int cols = 1, double width_px = 1000.0, double height_px = 600.0);

  // The panel at (row, col), row 0 at the top. Throws std::out_of_range naming the index.
  Axes& axes(int row = 0, int col = 0);
  const Axes& axes(int row, int col) const;

  Figure& title(std::string text);           // figure title above all panels
  Figure& share_x(bool on = true);           // panels of a column share the x range; only the
                                             // bottom row shows x tick labels and x label
  Figure& size(double width_px, double height_px);

  [[nodiscard]] int rows() const { return rows_; }
  [[nodiscard]] int cols() const { return cols_; }
  [[nodiscard]] double width_px() const { return width_; }
  [[nodiscard]] double height_px() const { return height_; }

  // The complete SVG document. Throws std::invalid_argument for a fixed log-axis limit ≤ 0.
  [[nodiscard]] std::string to_svg() const;
  // Writes the SVG; creates missing parent folders. Throws std::runtime_error naming the file.
  void write_svg(const std::filesystem::path& path) const;
  // Writes `svg_path`, then (if png) the same name with ".png" through rsvg-convert, at
  // png_zoom × the canvas size. A missing or failing converter is not an error: the result's
  // note says that only the SVG was written and why.
  SaveResult save(const std::filesystem::path& svg_path, bool png = true,
                  double png_zoom = 1.0) const;

 private:
  friend struct FigureRenderer;
  int rows_;
  int cols_;
  double width_;
  double height_;
  std::string title_{};
  bool share_x_ = false;
  std::vector<Axes> axes_{};
};

// Path of rsvg-convert found on $PATH, if any.
[[nodiscard]] std::optional<std::filesystem::path> find_rsvg_convert();
// Converts an SVG file to PNG with rsvg-convert (white background). Returns an empty string on
// success, otherwise the reason (converter missing, exit status).
[[nodiscard]] std::string svg_to_png(const std::filesystem::path& svg,
                                     const std::filesystem::path& png, double zoom = 1.0);

}  // namespace pedalwave::toolkit
