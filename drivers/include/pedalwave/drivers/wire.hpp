// Wire representation shared by the CAN and the serial module protocols (drivers/PROTOCOL.md §1):
// fixed-point scalings, saturation, little-endian byte access and the module status nibble.
// Pure, allocation-free, noexcept.
#pragma once

#include <cmath>
#include <cstdint>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::drivers::wire {

// Resolution (value of one LSB) of each quantity on the wire. Signed quantities are int16 in
// [-32767, 32767] (−32768 is never sent), gains are uint16 in [0, 65535].
inline constexpr double kBetaLsb = 1e-4;        // motor angle β [rad]; range ±3.2767 rad
inline constexpr double kBetaDotLsb = 1e-3;     // motor rate β̇ [rad/s]; range ±32.767 rad/s
inline constexpr double kDeflectionLsb = 2e-5;  // spring deflection β−α [rad]; range ±0.65534 rad
inline constexpr double kTauLsb = 1e-3;         // feed-forward torque [N·m]; range ±32.767 N·m
inline constexpr double kKpLsb = 1e-2;          // stiffness gain [N·m/rad]; range 0…655.35
inline constexpr double kKdLsb = 1e-3;          // damping gain [N·m·s/rad]; range 0…65.535

// Flags an encoder raises while quantizing (accumulated with |=).
enum QuantFlag : std::uint8_t {
  kQuantOk = 0,
  kQuantClamped = 1u << 0,    // value outside the representable range: saturated
  kQuantNotFinite = 1u << 1,  // NaN/Inf: sent as 0
};

// round(v / lsb) saturated to [-32767, 32767]; NaN/Inf → 0.
inline std::int16_t to_i16(double v, double lsb, std::uint8_t& flags) noexcept {
  if (!std::isfinite(v)) {
    flags |= kQuantNotFinite;
    return 0;
  }
  const double r = std::nearbyint(v / lsb);
  if (r > 32767.0) {
    flags |= kQuantClamped;
    return 32767;
  }
  if (r < -32767.0) {
    flags |= kQuantClamped;
    return -32767;
  }
  return static_cast<std::int16_t>(r);
}

// round(v / lsb) saturated to [0, 65535]; NaN/Inf → 0.
inline std::uint16_t to_u16(double v, double lsb, std::uint8_t& flags) noexcept {
  if (!std::isfinite(v)) {
    flags |= kQuantNotFinite;
    return 0;
  }
  const double r = std::nearbyint(v / lsb);
  if (r > 65535.0) {
    flags |= kQuantClamped;
    return 65535;
  }
  if (r < 0.0) {
    flags |= kQuantClamped;
    return 0;
  }
  return static_cast<std::uint16_t>(r);
}

inline double from_i16(std::int16_t raw, double lsb) noexcept { return raw * lsb; }
inline double from_u16(std::uint16_t raw, double lsb) noexcept { return raw * lsb; }

// Little-endian access.
inline void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v & 0xFFu);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_i16(std::uint8_t* p, std::int16_t v) noexcept {
  put_u16(p, static_cast<std::uint16_t>(v));
}
inline std::uint16_t get_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::int16_t get_i16(const std::uint8_t* p) noexcept {
  return static_cast<std::int16_t>(get_u16(p));
}

// A JointSample's three values as both module protocols lay them out (the CAN feedback frame's and
// the DYNAMIXEL feedback block's bytes 0…5): β, β̇, deflection, int16 each at the resolutions
// above. The status travels in each protocol's own place (pack_module_status below).
inline void put_sample_values(std::uint8_t* p, const JointSample& s, std::uint8_t& flags) noexcept {
  put_i16(p + 0, to_i16(s.beta, kBetaLsb, flags));
  put_i16(p + 2, to_i16(s.beta_dot, kBetaDotLsb, flags));
  put_i16(p + 4, to_i16(s.deflection, kDeflectionLsb, flags));
}
inline void get_sample_values(const std::uint8_t* p, JointSample& s) noexcept {
  s.beta = from_i16(get_i16(p + 0), kBetaLsb);
  s.beta_dot = from_i16(get_i16(p + 2), kBetaDotLsb);
  s.deflection = from_i16(get_i16(p + 4), kDeflectionLsb);
}

// Module status nibble (4 bits) ↔ StatusBit mask. Bit 0 saturated, 1 over-temperature,
// 2 encoder fault, 3 torque off. Other StatusBits are the host's and never go on the wire.
inline std::uint8_t pack_module_status(std::uint16_t status) noexcept {
  std::uint8_t n = 0;
  if (status & kStatusSaturated) n |= 1u << 0;
  if (status & kStatusOverTemp) n |= 1u << 1;
  if (status & kStatusEncoderFault) n |= 1u << 2;
  if (status & kStatusTorqueOff) n |= 1u << 3;
  return n;
}
inline std::uint16_t unpack_module_status(std::uint8_t nibble) noexcept {
  std::uint16_t s = 0;
  if (nibble & (1u << 0)) s |= kStatusSaturated;
  if (nibble & (1u << 1)) s |= kStatusOverTemp;
  if (nibble & (1u << 2)) s |= kStatusEncoderFault;
  if (nibble & (1u << 3)) s |= kStatusTorqueOff;
  return s;
}
// The StatusBits a module may report itself.
inline constexpr std::uint16_t kModuleStatusMask =
    kStatusSaturated | kStatusOverTemp | kStatusEncoderFault | kStatusTorqueOff;

// A module's timing record (PROTOCOL.md §1.1), carried next to its feedback on every bus: when
// it sampled, by its own free-running microsecond clock, and which command it applied last and
// how long before the sample.
inline constexpr std::uint16_t kAgeMaxUs = 0x7FFF;     // ages saturate here [µs]
inline constexpr std::uint16_t kAgeNoCommand = 0x8000;  // flag: output runs on no command
struct ModuleTiming {
  std::uint32_t sample_us = 0;     // module clock at the sample [µs], wraps every 2³² µs
  std::uint16_t applied_age_us = 0;  // sample − application of the last command [µs], ≤ kAgeMaxUs
  bool no_command = false;         // never commanded, or its command lifetime expired (output off)
  std::uint8_t applied_tag = 0;    // counter c of the command applied last (mod 16 on classic CAN)
};
inline std::uint16_t pack_age(const ModuleTiming& t) noexcept {
  return static_cast<std::uint16_t>((t.applied_age_us > kAgeMaxUs ? kAgeMaxUs : t.applied_age_us) |
                                    (t.no_command ? kAgeNoCommand : 0));
}
inline void unpack_age(std::uint16_t raw, ModuleTiming& t) noexcept {
  t.applied_age_us = static_cast<std::uint16_t>(raw & kAgeMaxUs);
  t.no_command = (raw & kAgeNoCommand) != 0;
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  put_u16(p, static_cast<std::uint16_t>(v & 0xFFFFu));
  put_u16(p + 2, static_cast<std::uint16_t>(v >> 16));
}
inline std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(get_u16(p)) | (static_cast<std::uint32_t>(get_u16(p + 2)) << 16);
}

}  // namespace pedalwave::drivers::wire
