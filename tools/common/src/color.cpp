#include "pedalwave/toolkit/color.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace pedalwave::toolkit {

std::string Color::hex() const {
  char buf[8];
  std::snprintf(buf, sizeof buf, "#%02x%02x%02x", r, g, b);
  return buf;
}

Color Color::from_hex(const std::string& text) {
  std::string s = (!text.empty() && text[0] == '#') ? text.substr(1) : text;
  auto nibble = [&](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  if (s.size() != 6) {
    throw std::invalid_argument("colour '" + text + "': expected \"#rrggbb\" (6 hex digits)");
  }
  std::array<int, 3> v{};
  for (std::size_t i = 0; i < 3; ++i) {
    const int hi = nibble(s[2 * i]);
    const int lo = nibble(s[2 * i + 1]);
    if (hi < 0 || lo < 0) {
      throw std::invalid_argument("colour '" + text + "': expected \"#rrggbb\" (6 hex digits)");
    }
    v[i] = hi * 16 + lo;
  }
  return Color{static_cast<std::uint8_t>(v[0]), static_cast<std::uint8_t>(v[1]),
               static_cast<std::uint8_t>(v[2])};
}

Color cycle_color(std::size_t i) {
  // Okabe & Ito's colour-blind-safe set, yellow replaced by a dark grey (yellow is unreadable
  // as a thin line on white).
  static constexpr std::array<Color, 8> kCycle{{
      {0, 114, 178},    // blue
      {213, 94, 0},     // vermillion
      {0, 158, 115},    // bluish green
      {204, 121, 167},  // reddish purple
      {230, 159, 0},    // orange
      {86, 180, 233},   // sky blue
      {60, 60, 60},     // dark grey
      {150, 110, 40},   // ochre
  }};
  return kCycle[i % kCycle.size()];
}

namespace {
Color lerp(const Color& a, const Color& b, double f) {
  auto mix = [f](std::uint8_t x, std::uint8_t y) {
    return static_cast<std::uint8_t>(std::lround(x + (static_cast<double>(y) - x) * f));
  };
  return Color{mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b)};
}
}  // namespace

Color colormap(Colormap map, double t) {
  if (!(t > 0.0)) t = 0.0;  // also catches NaN
  if (t > 1.0) t = 1.0;
  if (map == Colormap::gray) {
    return lerp(Color{40, 40, 40}, Color{210, 210, 210}, t);
  }
  // Nine evenly spaced anchors of a viridis-like map, linearly interpolated.
  static constexpr std::array<Color, 9> kViridis{{
      {68, 1, 84},
      {71, 44, 122},
      {59, 81, 139},
      {44, 113, 142},
      {33, 144, 141},
      {39, 173, 129},
      {92, 200, 99},
      {170, 220, 50},
      {253, 231, 37},
  }};
  const double u = t * static_cast<double>(kViridis.size() - 1);
  const auto i = static_cast<std::size_t>(std::floor(u));
  if (i + 1 >= kViridis.size()) return kViridis.back();
  return lerp(kViridis[i], kViridis[i + 1], u - static_cast<double>(i));
}

}  // namespace pedalwave::toolkit
