// SVG figures (tools/common/src/figure.cpp): document structure, one path per series, NaN
// breaks, log-axis decade ticks, legend entries, equal aspect, shared x, saving and PNG fallback.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/toolkit/figure.hpp"
#include "pedalwave/toolkit/ticks.hpp"
#include "svg_check.hpp"

namespace tk = pedalwave::toolkit;
using svgcheck::attr;
using svgcheck::elements;

namespace {

std::filesystem::path temp_dir(const std::string& name) {
  const auto d = std::filesystem::temp_directory_path() /
                 ("pedalwave_toolkit_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

std::vector<double> ramp(int n, double a, double b) {
  std::vector<double> v;
  for (int i = 0; i < n; ++i) v.push_back(a + (b - a) * i / (n - 1));
  return v;
}

// Pixel positions of tick marks of class `cls` ("xtick", "ytick"), along their axis.
std::vector<double> tick_px(const std::string& svg, const std::string& cls, bool x) {
  std::vector<double> out;
  for (const auto& e : elements(svg, "line", "class=\"" + cls + "\"")) out.push_back(std::stod(attr(e.tag, x ? "x1" : "y1")));
  return out;
}

std::vector<std::string> texts_of(const std::string& svg) {
  std::vector<std::string> out;
  for (const auto& e : elements(svg, "text")) out.push_back(e.text);
  return out;
}

bool has_text(const std::string& svg, const std::string& t) {
  for (const auto& s : texts_of(svg)) {
    if (s == t) return true;
  }
  return false;
}

}  // namespace

TEST(Figure, WellFormedWithOnePathPerLineSeries) {
  tk::Figure fig;
  auto& ax = fig.axes();
  const auto x = ramp(50, 0.0, 5.0);
  std::vector<double> y1, y2, y3;
  for (double v : x) {
    y1.push_back(std::sin(v));
    y2.push_back(std::cos(v));
    y3.push_back(0.1 * v);
  }
  ax.title("t").xlabel("x [m]").ylabel("y [m]");
  ax.line(x, y1, {.label = "sin"}).line(x, y2, {.label = "cos", .dash = tk::Dash::dashed}).line(x, y3);
  ax.scatter(x, y3, {.label = "samples"});
  ax.hline(0.5, {.label = "limit"}).vline(2.0).rect(1.0, 2.0, -1.0, 1.0, {.label = "patch"});
  ax.text(1.0, 0.0, "note");
  const std::string svg = fig.to_svg();
  EXPECT_EQ(svgcheck::well_formed(svg), "");
  EXPECT_NE(svg.find("<svg xmlns=\"http://www.w3.org/2000/svg\""), std::string::npos);
  // three line series → three paths; the scatter series has markers, no path
  const auto paths = elements(svg, "path", "class=\"series\"");
  EXPECT_EQ(paths.size(), 3u);
  for (const auto& p : paths) EXPECT_EQ(svgcheck::subpaths(attr(p.tag, "d")), 1u);
  EXPECT_EQ(elements(svg, "line", "class=\"refline\"").size(), 2u);
  EXPECT_EQ(elements(svg, "rect", "class=\"patch\"").size(), 1u);
  // legend: the patch, then the three labelled series, in that order
  const auto legend = elements(svg, "text", "class=\"legend-label\"");
  ASSERT_EQ(legend.size(), 4u);
  EXPECT_EQ(legend[0].text, "patch");
  EXPECT_EQ(legend[1].text, "sin");
  EXPECT_EQ(legend[2].text, "cos");
  EXPECT_EQ(legend[3].text, "samples");
  EXPECT_TRUE(has_text(svg, "limit"));
  EXPECT_TRUE(has_text(svg, "note"));
  EXPECT_TRUE(has_text(svg, "x [m]"));
  // one marker per valid point of the scatter series, plus its legend sample
  EXPECT_EQ(elements(svg, "circle").size(), x.size() + 1u);
}

TEST(Figure, NanAndInfBreakALineIntoPieces) {
  tk::Figure fig;
  auto& ax = fig.axes();
  const std::vector<double> x{0, 1, 2, 3, 4, 5, 6};
  const std::vector<double> y_nan{0, 1, 2, NAN, 4, 5, 6};
  const std::vector<double> y_two{0, 1, INFINITY, 3, 4, NAN, 6};  // last piece has one point
  const std::vector<double> x_nan{0, 1, 2, 3, NAN, 5, 6};
  ax.line(x, y_nan).line(x, y_two).line(x_nan, x);
  const std::string svg = fig.to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  const auto paths = elements(svg, "path", "class=\"series\"");
  ASSERT_EQ(paths.size(), 3u);
  EXPECT_EQ(svgcheck::subpaths(attr(paths[0].tag, "d")), 2u);
  EXPECT_EQ(svgcheck::subpaths(attr(paths[1].tag, "d")), 3u);
  EXPECT_EQ(svgcheck::subpaths(attr(paths[2].tag, "d")), 2u);
  EXPECT_EQ(svg.find("nan"), std::string::npos);
  EXPECT_EQ(svg.find("inf"), std::string::npos);
}

TEST(Figure, DenseSeriesAreReducedButKeepTheirExtremes) {
  tk::Figure fig;
  std::vector<double> t, y;
  for (int i = 0; i < 200000; ++i) {
    t.push_back(i * 1e-3);
    y.push_back(i == 123456 ? 1.0 : (i == 7777 ? -1.0 : 0.0));  // one-sample spikes
  }
  fig.axes().line(t, y).ylim(-1.0, 1.0).xmargin(0.0);
  const std::string svg = fig.to_svg();
  const auto paths = elements(svg, "path", "class=\"series\"");
  ASSERT_EQ(paths.size(), 1u);
  const std::string d = attr(paths[0].tag, "d");
  EXPECT_LT(svgcheck::count(d, "L"), 5000u);  // ≤ 4 points per pixel column
  // both spikes reach the frame's top and bottom edges
  const auto frame = elements(svg, "rect", "class=\"frame\"");
  const double top = std::stod(attr(frame[0].tag, "y"));
  const double bottom = top + std::stod(attr(frame[0].tag, "height"));
  double ymin = 1e9, ymax = -1e9;
  std::istringstream in(d);
  for (std::string tok; in >> tok;) {
    // tokens: "M<x>", "<y>L<x>", ..., "<y>": the number after each command letter is x
    const std::size_t l = tok.find_first_of("ML");
    if (l == std::string::npos || l == 0) {
      if (l == std::string::npos) {
        const double v = std::stod(tok);
        ymin = std::min(ymin, v), ymax = std::max(ymax, v);
      }
      continue;
    }
    const double v = std::stod(tok.substr(0, l));
    ymin = std::min(ymin, v), ymax = std::max(ymax, v);
  }
  EXPECT_NEAR(ymin, top, 0.01);
  EXPECT_NEAR(ymax, bottom, 0.01);
}

TEST(Figure, NonPositiveValuesBreakLinesOnLogAxes) {
  tk::Figure fig;
  auto& ax = fig.axes();
  ax.yscale(tk::Scale::log10);
  const std::vector<double> x{1, 2, 3, 4, 5};
  const std::vector<double> y{1e-3, 1e-2, 0.0, 1e-1, 1.0};
  ax.line(x, y);
  const std::string svg = fig.to_svg();
  const auto paths = elements(svg, "path", "class=\"series\"");
  ASSERT_EQ(paths.size(), 1u);
  EXPECT_EQ(svgcheck::subpaths(attr(paths[0].tag, "d")), 2u);
}

TEST(Figure, LogLogAxesHaveDecadeTicksWithMinorTicks) {
  tk::Figure fig;
  auto& ax = fig.axes();
  ax.xscale(tk::Scale::log10).yscale(tk::Scale::log10);
  const std::vector<double> cost{1e-4, 1e-3, 1e-2, 1e-1, 1.0};
  const std::vector<double> err{1e-2, 1e-4, 1e-6, 1e-8, 1e-11};
  ax.line(cost, err, {.label = "RK4", .marker = tk::Marker::circle});
  const std::string svg = fig.to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  for (int d = -11; d <= -2; ++d) EXPECT_TRUE(has_text(svg, tk::format_decade(d))) << "missing 10^" << d;
  for (int d = -4; d <= 0; ++d) EXPECT_TRUE(has_text(svg, tk::format_decade(d))) << "missing 10^" << d;
  // x: decades 1e-4..1e0 → 5 major ticks evenly spaced; minor ticks in between
  const auto xt = tick_px(svg, "xtick", true);
  ASSERT_EQ(xt.size(), 5u);
  for (std::size_t i = 2; i < xt.size(); ++i) EXPECT_NEAR(xt[i] - xt[i - 1], xt[1] - xt[0], 0.02);
  const auto xm = tick_px(svg, "xminor", true);
  EXPECT_GE(xm.size(), 32u);  // 2..9 in each of the four inner decades
  // the minor tick at 2 × 10^d sits log10(2) of a decade after the major tick
  const double dec = xt[1] - xt[0];
  bool found = false;
  for (double m : xm) found = found || std::abs(m - (xt[0] + std::log10(2.0) * dec)) < 0.02;
  EXPECT_TRUE(found);
  // y spans 10 decades: labelled at a stride, unlabelled decades as minor ticks
  const auto yt = tick_px(svg, "ytick", false);
  EXPECT_GE(yt.size(), 4u);
  EXPECT_LE(yt.size(), 14u);
}

TEST(Figure, ShortLogSpanLabelsOneTwoFive) {
  tk::Figure fig;
  const std::vector<double> x{0.02, 3.0};
  const std::vector<double> y{1.0, 1.0};
  fig.axes().xscale(tk::Scale::log10).line(x, y);
  const std::string svg = fig.to_svg();
  for (const char* t : {"0.02", "0.05", "0.1", "0.2", "0.5", "1", "2"}) EXPECT_TRUE(has_text(svg, t)) << t;
}

TEST(Figure, LinearTickLabelsMatchTheNiceTicks) {
  tk::Figure fig;
  auto& ax = fig.axes();
  const std::vector<double> x{0, 10};
  const std::vector<double> y{0, 1};
  ax.line(x, y).xmargin(0.0).ymargin(0.0);
  const std::string svg = fig.to_svg();
  for (const char* t : {"0", "2", "4", "6", "8", "10"}) EXPECT_TRUE(has_text(svg, t)) << t;
  // ticks at 0 and 10 sit on the frame's left and right edges
  const auto frame = elements(svg, "rect", "class=\"frame\"");
  ASSERT_EQ(frame.size(), 1u);
  const double fx = std::stod(attr(frame[0].tag, "x"));
  const double fw = std::stod(attr(frame[0].tag, "width"));
  const auto xt = tick_px(svg, "xtick", true);
  ASSERT_FALSE(xt.empty());
  EXPECT_NEAR(xt.front(), fx, 0.01);
  EXPECT_NEAR(xt.back(), fx + fw, 0.01);
}

TEST(Figure, EqualAspectGivesEqualPixelsPerUnit) {
  tk::Figure fig(1, 1, 1000, 600);
  auto& ax = fig.axes();
  std::vector<double> x, z;
  for (int i = 0; i <= 40; ++i) {
    x.push_back(4.0 * std::cos(i * 0.157));
    z.push_back(0.5 * std::sin(i * 0.157));
  }
  ax.line(x, z).equal_aspect();
  const std::string svg = fig.to_svg();
  const auto xt = tick_px(svg, "xtick", true);
  const auto yt = tick_px(svg, "ytick", false);
  ASSERT_GE(xt.size(), 2u);
  ASSERT_GE(yt.size(), 2u);
  // tick values: recover the steps from the labels' spacing in data units
  std::vector<double> xv, yv;
  const auto labels = elements(svg, "text", "text-anchor=\"middle\" fill=\"#222222\"");
  for (const auto& l : labels) xv.push_back(std::stod(l.text));
  const auto ylabels = elements(svg, "text", "text-anchor=\"end\" fill=\"#222222\"");
  for (const auto& l : ylabels) yv.push_back(std::stod(l.text));
  ASSERT_EQ(xv.size(), xt.size());
  ASSERT_EQ(yv.size(), yt.size());
  const double px_per_x = (xt.back() - xt.front()) / (xv.back() - xv.front());
  const double px_per_y = (yt.front() - yt.back()) / (yv.back() - yv.front());  // y grows upwards
  EXPECT_NEAR(px_per_x / px_per_y, 1.0, 1e-3);
}

TEST(Figure, SharedXShowsTickLabelsOnlyOnTheBottomPanel) {
  tk::Figure fig(3, 1);
  fig.share_x();
  const std::vector<double> t{0, 1, 2, 3};
  const std::vector<double> a{0, 1, 0, 1};
  const std::vector<double> t_long{0, 5};
  const std::vector<double> b{2, 3};
  fig.axes(0, 0).line(t, a).xlabel("time [s]");
  fig.axes(1, 0).line(t_long, b).xlabel("time [s]");
  fig.axes(2, 0).line(t, a).xlabel("time [s]");
  const std::string svg = fig.to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  std::size_t xlabels = 0;
  for (const auto& s : texts_of(svg)) xlabels += (s == "time [s]") ? 1 : 0;
  EXPECT_EQ(xlabels, 1u);
  // all panels show the same x range: tick positions identical in every panel
  const auto xt = tick_px(svg, "xtick", true);
  ASSERT_EQ(xt.size() % 3, 0u);
  const std::size_t n = xt.size() / 3;
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_DOUBLE_EQ(xt[i], xt[n + i]);
    EXPECT_DOUBLE_EQ(xt[i], xt[2 * n + i]);
  }
}

TEST(Figure, EscapesTextAndRejectsBadInput) {
  tk::Figure fig;
  const std::vector<double> x{0, 1};
  const std::vector<double> y{0, 1, 2};
  fig.axes().line(x, x, {.label = "a<b & \"c\""});
  const std::string svg = fig.to_svg();
  EXPECT_EQ(svgcheck::well_formed(svg), "");
  EXPECT_NE(svg.find("a&lt;b &amp; &quot;c&quot;"), std::string::npos);
  try {
    fig.axes().line(x, y, {.label = "bad"});
    FAIL() << "size mismatch accepted";
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("'bad'"), std::string::npos) << m;
    EXPECT_NE(m.find("2"), std::string::npos) << m;
    EXPECT_NE(m.find("3"), std::string::npos) << m;
  }
  EXPECT_THROW((void)fig.axes(1, 0), std::out_of_range);
  EXPECT_THROW(tk::Figure(0, 1), std::invalid_argument);
  EXPECT_THROW(fig.axes().xlim(0.0, INFINITY), std::invalid_argument);
  tk::Figure logfig;
  logfig.axes().xscale(tk::Scale::log10).xlim(-1.0, 10.0);
  EXPECT_THROW((void)logfig.to_svg(), std::invalid_argument);
}

TEST(Figure, EmptyPanelsAndConstantDataStillRender) {
  tk::Figure fig(1, 2);
  const std::vector<double> x{1, 1, 1};
  fig.axes(0, 1).line(x, x);
  const std::string svg = fig.to_svg();
  EXPECT_EQ(svgcheck::well_formed(svg), "");
  EXPECT_EQ(elements(svg, "rect", "class=\"frame\"").size(), 2u);
  EXPECT_EQ(svg.find("nan"), std::string::npos);
}

TEST(Figure, ColorbarHasGradientAndLabel) {
  tk::Figure fig;
  const std::vector<double> x{0, 1};
  fig.axes().line(x, x).colorbar(tk::Colormap::viridis, 0.0, 2.0, "time [s]");
  const std::string svg = fig.to_svg();
  EXPECT_EQ(svgcheck::well_formed(svg), "");
  EXPECT_EQ(elements(svg, "rect", "class=\"colorbar\"").size(), 1u);
  EXPECT_EQ(elements(svg, "linearGradient").size(), 1u);
  EXPECT_TRUE(has_text(svg, "time [s]"));
  EXPECT_EQ(svgcheck::count(svg, "stop-color=\"" + tk::colormap(tk::Colormap::viridis, 0.0).hex()), 1u);
  EXPECT_EQ(svgcheck::count(svg, "stop-color=\"" + tk::colormap(tk::Colormap::viridis, 1.0).hex()), 1u);
}

TEST(Figure, SaveWritesSvgAndPngOrSaysWhyNot) {
  const auto dir = temp_dir("save");
  tk::Figure fig;
  const std::vector<double> x{0, 1, 2};
  fig.axes().line(x, x, {.label = "x"});
  const auto r = fig.save(dir / "sub" / "plot.svg");
  ASSERT_TRUE(std::filesystem::exists(dir / "sub" / "plot.svg"));
  std::ifstream f(dir / "sub" / "plot.svg");
  std::ostringstream ss;
  ss << f.rdbuf();
  const std::string content = ss.str();
  EXPECT_EQ(content, fig.to_svg());
  if (!tk::find_rsvg_convert()) {
    EXPECT_FALSE(r.png.has_value());
    EXPECT_NE(r.note.find("only"), std::string::npos) << r.note;
    GTEST_SKIP() << "rsvg-convert (librsvg2-bin) is not installed: the PNG conversion was not tested";
  }
  ASSERT_TRUE(r.png.has_value()) << r.note;
  std::ifstream p(*r.png, std::ios::binary);
  char sig[8] = {};
  p.read(sig, 8);
  EXPECT_EQ(std::string(sig + 1, 3), "PNG");
  std::filesystem::remove_all(dir);
}

TEST(Figure, MissingConverterIsANoteNotAnError) {
  const auto dir = temp_dir("noconv");
  const char* old = std::getenv("PATH");
  const std::string saved = old ? old : "";
  ::setenv("PATH", dir.c_str(), 1);  // a folder without rsvg-convert
  tk::Figure fig;
  const std::vector<double> x{0, 1};
  fig.axes().line(x, x);
  tk::SaveResult r;
  EXPECT_NO_THROW(r = fig.save(dir / "a.svg"));
  ::setenv("PATH", saved.c_str(), 1);
  EXPECT_TRUE(std::filesystem::exists(dir / "a.svg"));
  EXPECT_FALSE(r.png.has_value());
  EXPECT_NE(r.note.find("only"), std::string::npos) << r.note;
  EXPECT_NE(r.note.find("rsvg-convert"), std::string::npos) << r.note;
  EXPECT_FALSE(std::filesystem::exists(dir / "a.png"));
  std::filesystem::remove_all(dir);
}

TEST(Figure, WriteToAnUnwritablePlaceNamesTheFile) {
  tk::Figure fig;
  try {
    fig.write_svg("/proc/pedalwave_cannot_write_here.svg");
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("pedalwave_cannot_write_here.svg"), std::string::npos) << e.what();
  }
}

TEST(Color, ColormapEndsAndHexRoundTrip) {
  const auto a = tk::colormap(tk::Colormap::viridis, 0.0);
  const auto b = tk::colormap(tk::Colormap::viridis, 1.0);
  EXPECT_EQ(tk::colormap(tk::Colormap::viridis, -3.0), a);  // clamped
  EXPECT_EQ(tk::colormap(tk::Colormap::viridis, NAN), a);
  EXPECT_EQ(tk::colormap(tk::Colormap::viridis, 7.0), b);
  // lightness grows along the map (dark purple → yellow)
  double last = -1.0;
  for (int i = 0; i <= 10; ++i) {
    const auto c = tk::colormap(tk::Colormap::viridis, i / 10.0);
    const double l = 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b;
    EXPECT_GT(l, last);
    last = l;
  }
  EXPECT_EQ(tk::Color::from_hex(b.hex()), b);
  EXPECT_THROW((void)tk::Color::from_hex("#12345"), std::invalid_argument);
  EXPECT_NE(tk::cycle_color(0), tk::cycle_color(1));
  EXPECT_EQ(tk::cycle_color(0), tk::cycle_color(8));
}
