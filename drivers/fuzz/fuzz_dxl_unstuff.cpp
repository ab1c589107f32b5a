// Fuzzes DYNAMIXEL byte (un)stuffing. Properties: never crashes; unstuff(stuff(x)) == x;
// stuff(unstuff(y)) == y whenever y unstuffs successfully (stuffing is a bijection on valid
// streams); the stuffed size never exceeds n + ⌊n/3⌋ (the bus budget's worst case).
#include <cstdint>
#include <cstring>
#include <vector>

#include "fuzz_common.hpp"
#include "pedalwave/drivers/dynamixel.hpp"

namespace dxl = pedalwave::drivers::dxl;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::span<const std::uint8_t> in(data, size);
  std::vector<std::uint8_t> a(size * 2 + 8), b(size * 2 + 8);
  std::size_t na = 0, nb = 0;

  PW_FUZZ_CHECK(dxl::stuff(in, a, na) == dxl::DxlStatus::kOk);
  PW_FUZZ_CHECK(na <= size + size / 3);
  PW_FUZZ_CHECK(dxl::unstuff(std::span<const std::uint8_t>(a.data(), na), b, nb) == dxl::DxlStatus::kOk);
  PW_FUZZ_CHECK(nb == size && (size == 0 || std::memcmp(b.data(), data, size) == 0));

  if (dxl::unstuff(in, a, na) == dxl::DxlStatus::kOk) {
    PW_FUZZ_CHECK(na <= size);
    PW_FUZZ_CHECK(dxl::stuff(std::span<const std::uint8_t>(a.data(), na), b, nb) == dxl::DxlStatus::kOk);
    PW_FUZZ_CHECK(nb == size && (size == 0 || std::memcmp(b.data(), data, size) == 0));
  }
  // Too small an output buffer is an error, never an overrun.
  if (size > 0) {
    std::vector<std::uint8_t> small(size / 2);
    std::size_t ns = 0;
    const dxl::DxlStatus s = dxl::stuff(in, small, ns);
    PW_FUZZ_CHECK(s == dxl::DxlStatus::kOverflow || ns <= small.size());
  }
  return 0;
}
