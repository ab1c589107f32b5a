// Colours for the SVG plots: an RGB value type, a colour-blind-safe cycle for series, and a
// perceptually ordered colormap (viridis-like, from our own anchor table) for time or magnitude.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace pedalwave::toolkit {

// An opaque sRGB colour.
struct Color {
  std::uint8_t r = 0;  // red channel [0..255], scalar
  std::uint8_t g = 0;  // green channel [0..255], scalar
  std::uint8_t b = 0;  // blue channel [0..255], scalar

  // "#rrggbb" as SVG expects.
  [[nodiscard]] std::string hex() const;
  // Parses "#rrggbb" or "rrggbb"; throws std::invalid_argument naming the text otherwise.
  [[nodiscard]] static Color from_hex(const std::string& text);

  friend bool operator==(const Color&, const Color&) = default;
};

// Named colours used by the plots' defaults.
namespace colors {
inline constexpr Color black{0, 0, 0};
inline constexpr Color white{255, 255, 255};
inline constexpr Color gray{120, 120, 120};
inline constexpr Color light_gray{200, 200, 200};
inline constexpr Color dark_gray{60, 60, 60};
inline constexpr Color red{200, 30, 30};
inline constexpr Color ground{110, 85, 60};  // earth brown for ground lines and boxes
}  // namespace colors

// The i-th colour of the series cycle (Okabe–Ito colour-blind-safe set, 8 colours, wraps).
[[nodiscard]] Color cycle_color(std::size_t i);

enum class Colormap {
  viridis,  // dark purple → blue → green → yellow; monotone lightness, prints well in grey
  gray,     // dark grey → light grey
};

// Colour of the colormap at t ∈ [0, 1] (t is clamped; NaN gives the t = 0 colour).
[[nodiscard]] Color colormap(Colormap map, double t);

}  // namespace pedalwave::toolkit
