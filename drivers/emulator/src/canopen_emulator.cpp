#include "pedalwave/drivers/canopen_emulator.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/can_io.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers::canopen {
namespace {

using DT = DataType;
using AC = Access;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

// The module's object dictionary (drivers/PROTOCOL.md §7.2). Node-dependent defaults are given for
// node 0 with plus_node = true.
constexpr ObjectEntry kDictionary[] = {
    {0x1000, 0, 7, "Device type", "Device type", DT::kUnsigned32, AC::kRo, false, kDeviceType, false, nullptr},
    {0x1001, 0, 7, "Error register", "Error register", DT::kUnsigned8, AC::kRo, false, 0, false, nullptr},
    {0x1006, 0, 7, "Communication cycle period", "Communication cycle period", DT::kUnsigned32, AC::kRw, false, 0,
     false, nullptr},
    {0x1007, 0, 7, "Synchronous window length", "Synchronous window length", DT::kUnsigned32, AC::kRw, false, 0,
     false, nullptr},
    {0x1008, 0, 7, "Manufacturer device name", "Manufacturer device name", DT::kVisibleString, AC::kConst, false, 0,
     false, "pedalwave SEA module"},
    {0x1017, 0, 7, "Producer heartbeat time", "Producer heartbeat time", DT::kUnsigned16, AC::kRw, false, 0, false,
     nullptr},
    {0x1018, 0, 9, "Identity object", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 4, false, nullptr},
    {0x1018, 1, 9, "Identity object", "Vendor-ID", DT::kUnsigned32, AC::kRo, false, 0, false, nullptr},
    {0x1018, 2, 9, "Identity object", "Product code", DT::kUnsigned32, AC::kRo, false, 0x50570001, false, nullptr},
    {0x1018, 3, 9, "Identity object", "Revision number", DT::kUnsigned32, AC::kRo, false, 0x00010000, false, nullptr},
    {0x1018, 4, 9, "Identity object", "Serial number", DT::kUnsigned32, AC::kRo, false, 0, true, nullptr},
    {0x1400, 0, 9, "RPDO 1 communication parameter", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 2,
     false, nullptr},
    {0x1400, 1, 9, "RPDO 1 communication parameter", "COB-ID used by RPDO", DT::kUnsigned32, AC::kRw, false, 0x200, true,
     nullptr},
    {0x1400, 2, 9, "RPDO 1 communication parameter", "Transmission type", DT::kUnsigned8, AC::kRw, false, 0xFF, false,
     nullptr},
    {0x1401, 0, 9, "RPDO 2 communication parameter", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 2,
     false, nullptr},
    {0x1401, 1, 9, "RPDO 2 communication parameter", "COB-ID used by RPDO", DT::kUnsigned32, AC::kRw, false, 0x80000300,
     true, nullptr},
    {0x1401, 2, 9, "RPDO 2 communication parameter", "Transmission type", DT::kUnsigned8, AC::kRw, false, 0xFF, false,
     nullptr},
    {0x1600, 0, 9, "RPDO 1 mapping parameter", "Number of mapped objects", DT::kUnsigned8, AC::kRw, false, 1, false, nullptr},
    {0x1600, 1, 9, "RPDO 1 mapping parameter", "Mapped object 1", DT::kUnsigned32, AC::kRw, false, 0x60400010, false, nullptr},
    {0x1600, 2, 9, "RPDO 1 mapping parameter", "Mapped object 2", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1600, 3, 9, "RPDO 1 mapping parameter", "Mapped object 3", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1600, 4, 9, "RPDO 1 mapping parameter", "Mapped object 4", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1601, 0, 9, "RPDO 2 mapping parameter", "Number of mapped objects", DT::kUnsigned8, AC::kRw, false, 0, false, nullptr},
    {0x1601, 1, 9, "RPDO 2 mapping parameter", "Mapped object 1", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1601, 2, 9, "RPDO 2 mapping parameter", "Mapped object 2", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1601, 3, 9, "RPDO 2 mapping parameter", "Mapped object 3", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1601, 4, 9, "RPDO 2 mapping parameter", "Mapped object 4", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1800, 0, 9, "TPDO 1 communication parameter", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 2,
     false, nullptr},
    {0x1800, 1, 9, "TPDO 1 communication parameter", "COB-ID used by TPDO", DT::kUnsigned32, AC::kRw, false, 0x180, true,
     nullptr},
    {0x1800, 2, 9, "TPDO 1 communication parameter", "Transmission type", DT::kUnsigned8, AC::kRw, false, 0xFF, false,
     nullptr},
    {0x1801, 0, 9, "TPDO 2 communication parameter", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 2,
     false, nullptr},
    {0x1801, 1, 9, "TPDO 2 communication parameter", "COB-ID used by TPDO", DT::kUnsigned32, AC::kRw, false, 0x80000280,
     true, nullptr},
    {0x1801, 2, 9, "TPDO 2 communication parameter", "Transmission type", DT::kUnsigned8, AC::kRw, false, 0xFF, false,
     nullptr},
    {0x1A00, 0, 9, "TPDO 1 mapping parameter", "Number of mapped objects", DT::kUnsigned8, AC::kRw, false, 1, false, nullptr},
    {0x1A00, 1, 9, "TPDO 1 mapping parameter", "Mapped object 1", DT::kUnsigned32, AC::kRw, false, 0x60410010, false, nullptr},
    {0x1A00, 2, 9, "TPDO 1 mapping parameter", "Mapped object 2", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A00, 3, 9, "TPDO 1 mapping parameter", "Mapped object 3", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A00, 4, 9, "TPDO 1 mapping parameter", "Mapped object 4", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A01, 0, 9, "TPDO 2 mapping parameter", "Number of mapped objects", DT::kUnsigned8, AC::kRw, false, 0, false, nullptr},
    {0x1A01, 1, 9, "TPDO 2 mapping parameter", "Mapped object 1", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A01, 2, 9, "TPDO 2 mapping parameter", "Mapped object 2", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A01, 3, 9, "TPDO 2 mapping parameter", "Mapped object 3", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x1A01, 4, 9, "TPDO 2 mapping parameter", "Mapped object 4", DT::kUnsigned32, AC::kRw, false, 0, false, nullptr},
    {0x2010, 0, 7, "CSP position loop gain", "CSP position loop gain", DT::kReal32, AC::kRw, false, 0, false, nullptr},
    {0x2011, 0, 7, "CSP velocity loop gain", "CSP velocity loop gain", DT::kReal32, AC::kRw, false, 0, false, nullptr},
    {0x6001, 0, 7, "Measuring units per revolution", "Measuring units per revolution", DT::kUnsigned32, AC::kRo, false,
     1u << 20, false, nullptr},
    {0x6004, 0, 7, "Position value", "Position value", DT::kUnsigned32, AC::kRo, true, 0, false, nullptr},
    {0x603F, 0, 7, "Error code", "Error code", DT::kUnsigned16, AC::kRo, true, 0, false, nullptr},
    {0x6040, 0, 7, "Controlword", "Controlword", DT::kUnsigned16, AC::kRw, true, 0, false, nullptr},
    {0x6041, 0, 7, "Statusword", "Statusword", DT::kUnsigned16, AC::kRo, true, 0, false, nullptr},
    {0x6060, 0, 7, "Modes of operation", "Modes of operation", DT::kInteger8, AC::kRw, true, 0, false, nullptr},
    {0x6061, 0, 7, "Modes of operation display", "Modes of operation display", DT::kInteger8, AC::kRo, true, 0, false,
     nullptr},
    {0x6064, 0, 7, "Position actual value", "Position actual value", DT::kInteger32, AC::kRo, true, 0, false, nullptr},
    {0x606C, 0, 7, "Velocity actual value", "Velocity actual value", DT::kInteger32, AC::kRo, true, 0, false, nullptr},
    {0x6071, 0, 7, "Target torque", "Target torque", DT::kInteger16, AC::kRw, true, 0, false, nullptr},
    {0x6076, 0, 7, "Motor rated torque", "Motor rated torque", DT::kUnsigned32, AC::kRo, false, 2000, false, nullptr},
    {0x6077, 0, 7, "Torque actual value", "Torque actual value", DT::kInteger16, AC::kRo, true, 0, false, nullptr},
    {0x607A, 0, 7, "Target position", "Target position", DT::kInteger32, AC::kRw, true, 0, false, nullptr},
    {0x608F, 0, 9, "Position encoder resolution", "Highest sub-index supported", DT::kUnsigned8, AC::kConst, false, 2,
     false, nullptr},
    {0x608F, 1, 9, "Position encoder resolution", "Encoder increments", DT::kUnsigned32, AC::kRo, false, 1u << 20, false,
     nullptr},
    {0x608F, 2, 9, "Position encoder resolution", "Motor revolutions", DT::kUnsigned32, AC::kRo, false, 1, false, nullptr},
    {0x60B1, 0, 7, "Velocity offset", "Velocity offset", DT::kInteger32, AC::kRw, true, 0, false, nullptr},
    {0x60B2, 0, 7, "Torque offset", "Torque offset", DT::kInteger16, AC::kRw, true, 0, false, nullptr},
};
constexpr int kEntries = static_cast<int>(std::size(kDictionary));
static_assert(kEntries <= 64, "value_ holds 64 entries per node");

constexpr int find_entry(std::uint16_t index, std::uint8_t sub) noexcept {
  for (int i = 0; i < kEntries; ++i)
    if (kDictionary[i].index == index && kDictionary[i].sub == sub) return i;
  return -1;
}
constexpr bool has_index(std::uint16_t index) noexcept {
  for (const ObjectEntry& e : kDictionary)
    if (e.index == index) return true;
  return false;
}
// Entries the emulator uses by name.
constexpr int kE1001 = find_entry(0x1001, 0), kE1007 = find_entry(kObjSyncWindow, 0), kE1017 = find_entry(0x1017, 0),
              kE603F = find_entry(kObjErrorCode, 0), kE6040 = find_entry(cia402::kObjControlword, 0),
              kE6041 = find_entry(cia402::kObjStatusword, 0),
              kE6060 = find_entry(cia402::kObjModesOfOperation, 0),
              kE6061 = find_entry(cia402::kObjModesOfOperationDisplay, 0),
              kE6064 = find_entry(cia402::kObjPositionActual, 0),
              kE606C = find_entry(cia402::kObjVelocityActual, 0),
              kE6071 = find_entry(cia402::kObjTargetTorque, 0),
              kE6076 = find_entry(kObjRatedTorque, 0),
              kE6077 = find_entry(cia402::kObjTorqueActual, 0),
              kE607A = find_entry(cia402::kObjTargetPosition, 0),
              kE608F1 = find_entry(kObjEncoderResolution, 1), kE6001 = find_entry(kObjDeflectionResolution, 0),
              kE6004 = find_entry(kObjDeflection, 0), kE60B1 = find_entry(kObjVelocityOffset, 0),
              kE60B2 = find_entry(kObjTorqueOffset, 0), kE2010 = find_entry(kObjCspKp, 0),
              kE2011 = find_entry(kObjCspKd, 0);
static_assert(kE1001 >= 0 && kE1007 >= 0 && kE1017 >= 0 && kE603F >= 0 && kE6040 >= 0 && kE6041 >= 0 && kE6060 >= 0 &&
              kE6061 >= 0 && kE6064 >= 0 && kE606C >= 0 && kE6071 >= 0 && kE6076 >= 0 && kE6077 >= 0 &&
              kE607A >= 0 && kE608F1 >= 0 && kE6001 >= 0 && kE6004 >= 0 && kE60B1 >= 0 && kE60B2 >= 0 &&
              kE2010 >= 0 && kE2011 >= 0);

constexpr std::int64_t kPollSliceNs = 1'000'000;

std::int32_t sign_extend(std::uint32_t v, DataType t) noexcept {
  switch (t) {
    case DT::kInteger8: return static_cast<std::int8_t>(v & 0xFF);
    case DT::kInteger16: return static_cast<std::int16_t>(v & 0xFFFF);
    default: return static_cast<std::int32_t>(v);
  }
}
std::uint32_t mask(DataType t, std::uint32_t v) noexcept {
  const std::size_t n = size_of(t);
  return n >= 4 ? v : (v & ((1u << (8 * n)) - 1u));
}
std::int32_t clamp_i32(double v) noexcept {
  if (!(v == v)) return 0;
  return static_cast<std::int32_t>(std::clamp(std::llround(v), -2147483648LL, 2147483647LL));
}
float as_float(std::uint32_t bits) noexcept {
  float f = 0;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

}  // namespace

std::size_t size_of(DataType t) noexcept {
  switch (t) {
    case DT::kInteger8: case DT::kUnsigned8: return 1;
    case DT::kInteger16: case DT::kUnsigned16: return 2;
    case DT::kInteger32: case DT::kUnsigned32: case DT::kReal32: return 4;
    case DT::kVisibleString: return 0;
  }
  return 0;
}

const char* to_string(Access a) noexcept {
  switch (a) {
    case AC::kRo: return "ro";
    case AC::kRw: return "rw";
    case AC::kConst: return "const";
  }
  return "?";
}

std::span<const ObjectEntry> module_dictionary() noexcept { return kDictionary; }


std::string module_eds() {
  std::ostringstream o;
  auto hex = [](std::uint32_t v, int w) {
    char b[16];
    std::snprintf(b, sizeof b, "0x%0*X", w, v);
    return std::string(b);
  };
  auto idx = [](std::uint16_t v) {
    char b[8];
    std::snprintf(b, sizeof b, "%04X", v);
    return std::string(b);
  };
  o << "; pedalwave SEA module, CANopen personality of the module emulator (drivers/PROTOCOL.md §7).\n"
       "; Generated from canopen::module_dictionary(); tests/drivers/canopen_emulator_test.cpp checks\n"
       "; that this file and the emulator's dictionary agree.\n"
       "[FileInfo]\nFileName=pedalwave_module.eds\nFileVersion=1\nFileRevision=0\nEDSVersion=4.0\n"
       "Description=pedalwave SEA module (CiA 402 drive, CiA 406 deflection encoder)\n"
       "CreatedBy=pedalwave\n\n"
       "[DeviceInfo]\nVendorName=pedalwave\nVendorNumber=0x00000000\nProductName=pedalwave SEA module\n"
       "ProductNumber=0x50570001\nRevisionNumber=0x00010000\n"
       "BaudRate_10=0\nBaudRate_20=0\nBaudRate_50=0\nBaudRate_125=1\nBaudRate_250=1\nBaudRate_500=1\n"
       "BaudRate_800=0\nBaudRate_1000=1\nSimpleBootUpMaster=0\nSimpleBootUpSlave=1\nGranularity=8\n"
       "DynamicChannelsSupported=0\nGroupMessaging=0\nNrOfRXPDO=2\nNrOfTXPDO=2\nLSS_Supported=0\n\n"
       "[DummyUsage]\nDummy0001=0\nDummy0002=0\nDummy0003=0\nDummy0004=0\nDummy0005=0\nDummy0006=0\n"
       "Dummy0007=0\n\n";
  // The index lists.
  std::vector<std::uint16_t> mandatory, optional, manufacturer;
  for (const ObjectEntry& e : kDictionary) {
    std::vector<std::uint16_t>& v = (e.index == 0x1000 || e.index == 0x1001 || e.index == 0x1018) ? mandatory
                                    : (e.index >= 0x2000 && e.index < 0x6000)                     ? manufacturer
                                                                                                  : optional;
    if (v.empty() || v.back() != e.index) v.push_back(e.index);
  }
  auto list = [&](const char* name, const std::vector<std::uint16_t>& v) {
    o << "[" << name << "]\nSupportedObjects=" << v.size() << "\n";
    for (std::size_t i = 0; i < v.size(); ++i) o << i + 1 << "=0x" << idx(v[i]) << "\n";
    o << "\n";
  };
  list("MandatoryObjects", mandatory);
  list("OptionalObjects", optional);
  list("ManufacturerObjects", manufacturer);
  auto value = [&](const ObjectEntry& e) {
    if (e.type == DT::kVisibleString) return std::string(e.text ? e.text : "");
    if (e.plus_node) return e.default_value == 0 ? std::string("$NODEID") : hex(e.default_value, 1) + "+$NODEID";
    return hex(e.default_value, 1);
  };
  auto body = [&](const ObjectEntry& e) {
    o << "DataType=" << hex(static_cast<std::uint32_t>(e.type), 4) << "\nAccessType=" << to_string(e.access)
      << "\nDefaultValue=" << value(e) << "\nPDOMapping=" << (e.pdo ? 1 : 0) << "\n\n";
  };
  for (int i = 0; i < kEntries; ++i) {
    const ObjectEntry& e = kDictionary[i];
    if (e.object == 7) {
      o << "[" << idx(e.index) << "]\nParameterName=" << e.name << "\nObjectType=0x7\n";
      body(e);
      continue;
    }
    if (e.sub == 0) {
      int n = 0;
      for (const ObjectEntry& s : kDictionary) n += s.index == e.index ? 1 : 0;
      o << "[" << idx(e.index) << "]\nParameterName=" << e.index_name << "\nObjectType=0x" << int{e.object}
        << "\nSubNumber=" << n << "\n\n";
    }
    char sub[8];
    std::snprintf(sub, sizeof sub, "%X", e.sub);
    o << "[" << idx(e.index) << "sub" << sub << "]\nParameterName=" << e.name << "\nObjectType=0x7\n";
    body(e);
  }
  return o.str();
}

// ---- The dictionary of one node behind its SDO server ------------------------------------------
class CanOpenModuleEmulator::NodeDictionary final : public ObjectDictionary {
 public:
  NodeDictionary(CanOpenModuleEmulator& emu, int j) : emu_(emu), j_(j) {}
  std::size_t read(std::uint16_t index, std::uint8_t sub, std::span<std::uint8_t> out,
                   std::uint32_t& abort) noexcept override {
    const int e = find_entry(index, sub);
    if (e < 0) {
      abort = has_index(index) ? kAbortNoSubindex : kAbortNoObject;
      return 0;
    }
    const ObjectEntry& d = kDictionary[e];
    if (d.type == DT::kVisibleString) {
      const std::size_t n = std::min(out.size(), std::strlen(d.text));
      std::memcpy(out.data(), d.text, n);
      return n;
    }
    emu_.refresh(j_);
    const std::uint32_t v = emu_.value_[static_cast<std::size_t>(j_)][static_cast<std::size_t>(e)];
    const std::size_t n = std::min(out.size(), size_of(d.type));
    for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<std::uint8_t>(v >> (8 * i));
    return n;
  }
  std::uint32_t write(std::uint16_t index, std::uint8_t sub,
                      std::span<const std::uint8_t> data) noexcept override {
    const int e = find_entry(index, sub);
    if (e < 0) return has_index(index) ? kAbortNoSubindex : kAbortNoObject;
    const ObjectEntry& d = kDictionary[e];
    if (d.access != AC::kRw) return kAbortReadOnly;
    if (data.size() > size_of(d.type)) return kAbortLengthHigh;
    if (data.size() < size_of(d.type)) return kAbortLengthLow;
    if (j_ == emu_.co_.refuse_joint && index == emu_.co_.refuse_index) return kAbortValueRange;
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < data.size(); ++i) v |= std::uint32_t{data[i]} << (8 * i);
    return emu_.write_value(j_, e, v);
  }

 private:
  CanOpenModuleEmulator& emu_;
  int j_;
};

// Writes entry e of joint j's dictionary with CiA 301's checks (PDO procedure); 0 = done.
std::uint32_t CanOpenModuleEmulator::write_value(int j, int e, std::uint32_t v) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  auto& val = value_[ju];
  const ObjectEntry& d = kDictionary[e];
  const std::uint16_t index = d.index;
  const bool rpdo_map = index == 0x1600 || index == 0x1601, tpdo_map = index == 0x1A00 || index == 0x1A01;
  const bool rpdo_com = index == 0x1400 || index == 0x1401, tpdo_com = index == 0x1800 || index == 0x1801;
  if (rpdo_com || tpdo_com) {
    if (d.sub == 1) {
      const std::uint32_t old = val[static_cast<std::size_t>(e)];
      if ((v & 0x3FFFF800u) != 0) return kAbortValueRange;  // 11-bit ids only, no RTR / frame bits
      const bool old_valid = (old & 0x80000000u) == 0, new_valid = (v & 0x80000000u) == 0;
      if (old_valid && new_valid && (old & 0x7FF) != (v & 0x7FF)) return kAbortValueRange;
    } else if (d.sub == 2) {
      if (v > 240 && v != 254 && v != 255) return kAbortValueRange;
    }
  }
  if (rpdo_map || tpdo_map) {
    const std::uint16_t com = static_cast<std::uint16_t>(index - 0x200);  // 1600h → 1400h, 1A00h → 1800h
    if ((val[static_cast<std::size_t>(find_entry(com, 1))] & 0x80000000u) == 0) return kAbortDeviceState;
    const int e0 = find_entry(index, 0);
    if (d.sub != 0) {
      if (val[static_cast<std::size_t>(e0)] != 0) return kAbortDeviceState;
    } else {
      if (v > 4) return kAbortValueRange;
      int bits = 0;
      for (std::uint32_t k = 1; k <= v; ++k) {
        const std::uint32_t m = val[static_cast<std::size_t>(e0) + k];
        const int me = find_entry(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>(m >> 8));
        if (me < 0 || !kDictionary[me].pdo || size_of(kDictionary[me].type) * 8 != (m & 0xFF) ||
            (rpdo_map && kDictionary[me].access != AC::kRw))
          return kAbortNotMappable;
        bits += static_cast<int>(m & 0xFF);
      }
      if (bits > 64) return kAbortPdoLength;
    }
  }
  if (e == kE6060 && v != static_cast<std::uint8_t>(cia402::kModeCst) &&
      v != static_cast<std::uint8_t>(cia402::kModeCsp) && v != 0)
    return kAbortValueRange;
  val[static_cast<std::size_t>(e)] = mask(d.type, v);
  if (e == kE6060) val[kE6061] = val[kE6060];
  if (e == kE6040) set_controlword(j, static_cast<std::uint16_t>(v), detail::monotonic_ns());
  if (e == kE1017) node_[ju].next_heartbeat_ns = 0;
  return 0;
}

// ---- The emulator ----------------------------------------------------------------------------------
CanOpenModuleEmulator::CanOpenModuleEmulator(int fd, const EmulatorConfig& cfg,
                                             const CanOpenEmulatorConfig& co, ModulePlant& plant)
    : fd_(fd), co_(co), bank_(cfg, plant), wire_(cfg.bus.wire), host_wire_(cfg.bus.wire) {
  if (fd < 0 || !detail::set_nonblocking(fd))
    throw std::invalid_argument("CANopen module emulator: fd = " + std::to_string(fd) +
                                ", expected an open socket");
  const int one = 1;
  (void)::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);  // the frames' arrival times
  (void)::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one);     // frames lost before they were read
  if (co.encoder_increments == 0 || co.deflection_increments == 0 || co.rated_torque_mnm == 0)
    throw std::invalid_argument("CANopen module emulator: encoder_increments, deflection_increments and "
                                "rated_torque_mnm must be > 0");
  joint_of_node_.fill(-1);
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint8_t id = co.node[ju] == 0 ? static_cast<std::uint8_t>(j + 1) : co.node[ju];
    if (id < 1 || id > 127 || joint_of_node_[id] >= 0)
      throw std::invalid_argument("CANopen module emulator: node id " + std::to_string(id) + " of joint " +
                                  std::to_string(j + 1) + ": expected a unique id in 1 … 127");
    joint_of_node_[id] = static_cast<std::int8_t>(j);
    node_[ju].id = id;
    dict_.push_back(std::make_unique<NodeDictionary>(*this, j));
    sdo_.push_back(std::make_unique<SdoServer>(id, *dict_.back()));
    reset(j, true, 0, false);
    if (j == co.fault_at_boot_joint) {
      node_[ju].drive = cia402::State::kFault;
      value_[ju][kE1001] = 0x01;
      value_[ju][kE603F] = co.emcy_code;
    }
  }
  publish();
}

CanOpenModuleEmulator::~CanOpenModuleEmulator() = default;

void CanOpenModuleEmulator::publish() noexcept {
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    pub_nmt_[ju].store(static_cast<std::uint8_t>(node_[ju].nmt), std::memory_order_release);
    pub_drive_[ju].store(static_cast<std::uint8_t>(node_[ju].drive), std::memory_order_release);
  }
}

bool CanOpenModuleEmulator::node_silent(int j) const { return bank_.silent(j); }

std::int64_t CanOpenModuleEmulator::wire_ns(int len) const noexcept {
  return static_cast<std::int64_t>(std::llround(can_classic_frame_bits(len) / bank_.config().bus.bitrate * 1e9));
}

void CanOpenModuleEmulator::reset(int j, bool whole_node, std::int64_t now, bool announce) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  for (int e = 0; e < kEntries; ++e) {
    const ObjectEntry& d = kDictionary[e];
    if (!whole_node && (d.index < 0x1000 || d.index > 0x1FFF)) continue;
    value_[ju][static_cast<std::size_t>(e)] = d.default_value + (d.plus_node ? n.id : 0u);
  }
  if (whole_node) {
    value_[ju][kE608F1] = co_.encoder_increments;
    value_[ju][kE6001] = co_.deflection_increments;
    value_[ju][kE6076] = co_.rated_torque_mnm;
    if (n.drive != cia402::State::kFault) {
      n.drive = cia402::State::kSwitchOnDisabled;
      value_[ju][kE1001] = 0;
      value_[ju][kE603F] = 0;
    }
    n.controlword = 0;
  } else if (n.drive == cia402::State::kOperationEnabled || n.drive == cia402::State::kSwitchedOn ||
             n.drive == cia402::State::kReadyToSwitchOn) {
    n.drive = cia402::State::kSwitchOnDisabled;  // communication lost its settings: output off
  }
  n.rpdo_pending.fill(false);
  n.nmt = NmtState::kPreOperational;
  n.next_heartbeat_ns = 0;
  if (announce) {
    actuate(j, now);
    can_frame f{};
    encode_heartbeat(n.id, NmtState::kBootUp, f);
    send(f, now);
  }
}

void CanOpenModuleEmulator::send(const can_frame& f, std::int64_t now, bool pdo, std::int64_t window_end_ns) noexcept {
  const std::size_t next = (tail_ + 1) % queue_.size();
  if (next == head_) {
    bank_.stats().replies_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Pending& p = queue_[tail_];
  p.due_ns = wire_.occupy(now, wire_ns(f.len)) + (pdo ? bank_.latency_ns() : 0);
  p.frame = f;
  p.pdo = pdo;
  p.window_end_ns = window_end_ns;
  tail_ = next;
}

void CanOpenModuleEmulator::flush(std::int64_t now) noexcept {
  blocked_ = false;
  while (head_ != tail_ && queue_[head_].due_ns <= now) {
    const Pending& p = queue_[head_];
    // The window is checked against the clock at the send, not at the turn's start: a thread
    // held in between (a loaded machine) must not send an answer after its window, perhaps
    // after a newer SYNC, which the master would take for that one's.
    if (p.pdo && p.window_end_ns != 0 && std::max(now, detail::monotonic_ns()) > p.window_end_ns) {  // discarded
      window_dropped.fetch_add(1, std::memory_order_relaxed);
      head_ = (head_ + 1) % queue_.size();
      continue;
    }
    const Send s = send_frame(fd_, &p.frame, CAN_MTU);
    if (s == Send::kFull) {
      blocked_ = true;
      return;
    }
    if (s == Send::kSent && p.pdo) bank_.on_reply_sent(now);
    head_ = (head_ + 1) % queue_.size();
  }
}

void CanOpenModuleEmulator::run(const std::atomic<bool>& stop) {
  if (!booted_) {  // power-on: every node announces itself
    booted_ = true;
    const std::int64_t now = detail::monotonic_ns();
    for (int j = 0; j < bank_.joints(); ++j)
      if (!node_silent(j)) reset(j, true, now, true);
  }
  while (!stop.load(std::memory_order_acquire)) {
    std::int64_t now = detail::monotonic_ns();
    std::int64_t wait = kPollSliceNs;
    if (head_ != tail_ && !blocked_) wait = std::clamp<std::int64_t>(queue_[head_].due_ns - now, 0, kPollSliceNs);
    pollfd p{fd_, static_cast<short>(blocked_ ? POLLIN | POLLOUT : POLLIN), 0};
    const timespec ts = detail::to_timespec(wait);
    const int pr = ::ppoll(&p, 1, &ts, nullptr);
    if (const std::int64_t held = bank_.take_thread_stall(); held > 0) {
      const timespec hs = detail::to_timespec(held);
      ::clock_nanosleep(CLOCK_MONOTONIC, 0, &hs, nullptr);
    }
    bank_.on_turn(detail::monotonic_ns());
    bool got = false;
    const std::int64_t rt_off = rt_offset_.get();
    alignas(cmsghdr) std::array<char, 128> cbuf{};
    ReceivedFrame r;
    for (;;) {
      if (receive_frame(fd_, cbuf, rt_off, r) != Receive::kFrame) break;
      got = true;
      if (r.have_rxq_ovfl && r.rxq_ovfl != rxq_ovfl_) {  // a real drive's controller loses none
        bank_.stats().rx_lost.fetch_add(static_cast<std::uint32_t>(r.rxq_ovfl - rxq_ovfl_), std::memory_order_relaxed);
        rxq_ovfl_ = r.rxq_ovfl;
      }
      // A drive acts on a frame when it arrives, not when this thread gets to it: the kernel's
      // receive stamp (AF_UNIX: when the host sent it; CAN: when it came off the bus), so a
      // thread held by a loaded machine still samples the plant at the SYNC's time.
      std::int64_t t = detail::monotonic_ns();
      if (r.stamp_ns != 0 && r.stamp_ns < t && r.stamp_ns > t - 1'000'000'000LL) t = r.stamp_ns;
      if (r.bytes != CAN_MTU) {
        bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      can_frame c{};
      std::memcpy(&c, &r.frame, CAN_MTU);
      // The host's frames leave its FIFO transmit queue one after the other; the drives' own
      // frames (ids 080h + node and up) lose arbitration to them, so they do not delay a SYNC or
      // an RPDO beyond the frame already on the wire (not modelled: ≤ one frame time).
      handle(c, host_wire_.occupy(t, wire_ns(c.len)));
    }
    if (!got && pr > 0 && (p.revents & (POLLHUP | POLLERR))) {
      const timespec s = detail::to_timespec(kPollSliceNs);
      ::clock_nanosleep(CLOCK_MONOTONIC, 0, &s, nullptr);
    }
    now = detail::monotonic_ns();
    heartbeats(now);
    publish();
    flush(now);
    bank_.keep_up(now);
    bank_.end_turn(detail::monotonic_ns());
  }
}

void CanOpenModuleEmulator::heartbeats(std::int64_t now) noexcept {
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    Node& n = node_[ju];
    const std::int64_t period = static_cast<std::int64_t>(value_[ju][kE1017]) * 1'000'000;
    if (period <= 0) continue;
    if (n.next_heartbeat_ns == 0 || now - n.next_heartbeat_ns > period) n.next_heartbeat_ns = now;
    if (now < n.next_heartbeat_ns) continue;
    n.next_heartbeat_ns += period;
    if (node_silent(j)) continue;
    can_frame f{};
    encode_heartbeat(n.id, n.nmt, f);
    send(f, now);
    heartbeats_sent.fetch_add(1, std::memory_order_relaxed);
  }
}

void CanOpenModuleEmulator::handle(const can_frame& f, std::int64_t now) noexcept {
  if (f.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG | CAN_EFF_FLAG)) return;
  const canid_t id = f.can_id & CAN_SFF_MASK;
  if (id == kCobNmt) {
    NmtCommand cmd{};
    std::uint8_t target = 0;
    if (!decode_nmt(f, cmd, target)) {
      bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    for (int j = 0; j < bank_.joints(); ++j) {
      Node& n = node_[static_cast<std::size_t>(j)];
      if (target != 0 && target != n.id) continue;
      switch (cmd) {
        case NmtCommand::kStart: n.nmt = NmtState::kOperational; break;
        case NmtCommand::kStop: n.nmt = NmtState::kStopped; break;
        case NmtCommand::kEnterPreOperational: n.nmt = NmtState::kPreOperational; break;
        case NmtCommand::kResetNode: reset(j, true, now, !node_silent(j)); continue;
        case NmtCommand::kResetCommunication: reset(j, false, now, !node_silent(j)); continue;
      }
      actuate(j, now);
    }
    return;
  }
  if (id == kCobSync) {
    if (f.len <= 1) on_sync(now);
    else bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (id > kCobSdoRx && id <= kCobSdoRx + 127) {
    const int j = joint_of_node_[id - kCobSdoRx];
    if (j < 0) return;
    const Node& n = node_[static_cast<std::size_t>(j)];
    if (n.nmt == NmtState::kStopped || node_silent(j)) return;
    can_frame r{};
    if (sdo_[static_cast<std::size_t>(j)]->on_frame(f, r)) {
      sdo_served.fetch_add(1, std::memory_order_relaxed);
      send(r, now);
    }
    return;
  }
  // RPDOs: the COB-IDs the nodes' 1400h / 1401h hold.
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    for (int p = 0; p < 2; ++p) {
      const std::uint32_t cob = value_[ju][static_cast<std::size_t>(find_entry(static_cast<std::uint16_t>(0x1400 + p), 1))];
      if ((cob & 0x80000000u) != 0 || (cob & 0x7FF) != id) continue;
      receive_pdo(j, p, f, now);
    }
  }
}

void CanOpenModuleEmulator::receive_pdo(int j, int p, const can_frame& f, std::int64_t now) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  if (n.nmt != NmtState::kOperational) return;
  const std::uint32_t type =
      value_[ju][static_cast<std::size_t>(find_entry(static_cast<std::uint16_t>(0x1400 + p), 2))];
  if (type <= 240) {
    n.rpdo[static_cast<std::size_t>(p)] = f;
    n.rpdo_pending[static_cast<std::size_t>(p)] = true;
    return;
  }
  // Event-driven: acts on arrival.
  n.rpdo[static_cast<std::size_t>(p)] = f;
  n.rpdo_pending[static_cast<std::size_t>(p)] = true;
  apply_rpdos(j, now);
  actuate(j, now);
}

// Unpacks joint j's pending RPDOs into its dictionary.
void CanOpenModuleEmulator::apply_rpdos(int j, std::int64_t now) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  for (int p = 0; p < 2; ++p) {
    const auto pu = static_cast<std::size_t>(p);
    if (!n.rpdo_pending[pu]) continue;
    n.rpdo_pending[pu] = false;
    const can_frame& f = n.rpdo[pu];
    const int e0 = find_entry(static_cast<std::uint16_t>(0x1600 + p), 0);
    const std::uint32_t count = value_[ju][static_cast<std::size_t>(e0)];
    int bytes = 0;
    for (std::uint32_t k = 1; k <= count; ++k) bytes += static_cast<int>(value_[ju][static_cast<std::size_t>(e0) + k] & 0xFF) / 8;
    if (f.len < bytes) {  // CiA 301: a PDO shorter than its mapping is not processed
      bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    int at = 0;
    for (std::uint32_t k = 1; k <= count; ++k) {
      const std::uint32_t m = value_[ju][static_cast<std::size_t>(e0) + k];
      const int me = find_entry(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>(m >> 8));
      const int len = static_cast<int>(m & 0xFF) / 8;
      std::uint32_t v = 0;
      for (int i = 0; i < len; ++i) v |= std::uint32_t{f.data[at + i]} << (8 * i);
      at += len;
      if (me < 0) continue;
      value_[ju][static_cast<std::size_t>(me)] = v;
      if (me == kE6040) set_controlword(j, static_cast<std::uint16_t>(v), now);
    }
  }
}

void CanOpenModuleEmulator::set_controlword(int j, std::uint16_t cw, std::int64_t now) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  const cia402::State before = n.drive;
  n.drive = cia402::drive_transition(n.drive, cw, n.controlword);
  n.controlword = cw;
  value_[ju][kE6040] = cw;
  if (before == cia402::State::kFault && n.drive != cia402::State::kFault) {
    // Fault reset: the error is gone (CiA 301: EMCY "error reset").
    value_[ju][kE1001] = 0;
    value_[ju][kE603F] = 0;
    n.over_temp = n.encoder = false;
    if (!node_silent(j)) {
      can_frame f{};
      encode_emcy(n.id, Emcy{}, f);
      send(f, now);
      emcy_sent.fetch_add(1, std::memory_order_relaxed);
    }
  }
  if (before != n.drive) actuate(j, now);
}

void CanOpenModuleEmulator::fault(int j, std::uint16_t code, std::int64_t now) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  if (n.drive == cia402::State::kFault) return;
  n.drive = cia402::State::kFault;
  std::uint8_t reg = 0x01;                      // generic error
  if ((code >> 12) == 0x2) reg |= 0x02;         // current
  if ((code >> 12) == 0x3) reg |= 0x04;         // voltage
  if ((code >> 12) == 0x4) reg |= 0x08;         // temperature
  value_[ju][kE1001] = reg;
  value_[ju][kE603F] = code;
  actuate(j, now);
  if (node_silent(j)) return;
  Emcy e;
  e.code = code;
  e.error_register = reg;
  can_frame f{};
  encode_emcy(n.id, e, f);
  send(f, now);
  emcy_sent.fetch_add(1, std::memory_order_relaxed);
}

void CanOpenModuleEmulator::actuate(int j, std::int64_t now) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  Node& n = node_[ju];
  auto& val = value_[ju];
  const bool on = n.nmt == NmtState::kOperational && n.drive == cia402::State::kOperationEnabled;
  const auto mode = static_cast<std::int8_t>(val[kE6060] & 0xFF);
  const double per_mille = static_cast<double>(co_.rated_torque_mnm) * 1e-6;  // N·m per ‰
  const double rad_per_inc = kTwoPi / static_cast<double>(co_.encoder_increments);
  double tau = 0, ref = 0, vref = 0, kp = 0, kd = 0;
  if (mode == cia402::kModeCst) {
    tau = sign_extend(val[kE6071], DT::kInteger16) * per_mille;
  } else if (mode == cia402::kModeCsp) {
    tau = sign_extend(val[kE60B2], DT::kInteger16) * per_mille;
    ref = sign_extend(val[kE607A], DT::kInteger32) * rad_per_inc;
    vref = sign_extend(val[kE60B1], DT::kInteger32) * rad_per_inc;
    kp = as_float(val[kE2010]);
    kd = as_float(val[kE2011]);
  }
  const bool off = !on || (mode != cia402::kModeCst && mode != cia402::kModeCsp);
  u_tau_[ju] = off ? 0.0 : tau;
  u_kp_[ju] = off ? 0.0 : kp;
  u_kd_[ju] = off ? 0.0 : kd;
  u_ref_[ju] = ref;
  u_vref_[ju] = vref;
  if (!bank_.torque_off(j) || !off) bank_.latch(j, tau, ref, vref, true, kp, kd, off, static_cast<std::uint8_t>(syncs_), now);
}

void CanOpenModuleEmulator::refresh(int j) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  auto& val = value_[ju];
  const Feedback& s = bank_.sample();
  const double inc_per_rad = static_cast<double>(co_.encoder_increments) / kTwoPi;
  val[kE6064] = static_cast<std::uint32_t>(clamp_i32(s.beta[ju] * inc_per_rad));
  val[kE606C] = static_cast<std::uint32_t>(clamp_i32(s.beta_dot[ju] * inc_per_rad));
  val[kE6004] = static_cast<std::uint32_t>(
      clamp_i32(s.deflection[ju] * static_cast<double>(co_.deflection_increments) / kTwoPi));
  const double u = u_tau_[ju] + u_kp_[ju] * (u_ref_[ju] - s.beta[ju]) + u_kd_[ju] * (u_vref_[ju] - s.beta_dot[ju]);
  const double pm = std::clamp(u / (static_cast<double>(co_.rated_torque_mnm) * 1e-6), -32768.0, 32767.0);
  val[kE6077] = mask(DT::kInteger16, static_cast<std::uint32_t>(clamp_i32(pm)));
  const Node& n = node_[ju];
  std::uint16_t sw = cia402::statusword_bits(n.drive);
  sw |= 0x0200;  // bit 9 remote: the controlword is obeyed
  if (n.drive == cia402::State::kOperationEnabled) sw |= 0x0010;  // voltage enabled
  val[kE6041] = sw;
}

void CanOpenModuleEmulator::on_sync(std::int64_t now) noexcept {
  // A new SYNC closes the previous one's synchronous window: its TPDOs still queued are not sent.
  for (std::size_t i = head_; i != tail_; i = (i + 1) % queue_.size())
    if (queue_[i].pdo && queue_[i].window_end_ns != 0 && queue_[i].window_end_ns > now) queue_[i].window_end_ns = now;
  ++syncs_;
  bank_.on_sync(static_cast<std::uint8_t>(syncs_), now);
  const Feedback& s = bank_.sample();
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    Node& n = node_[ju];
    // Faults the drive detects: the plant's conditions, an injected one.
    if ((s.status[ju] & kStatusOverTemp) && !n.over_temp) {
      n.over_temp = true;
      fault(j, kEmcyOverTemperature, now);
    }
    if ((s.status[ju] & kStatusEncoderFault) && !n.encoder) {
      n.encoder = true;
      fault(j, kEmcyEncoder, now);
    }
    if (j == co_.emcy_joint && syncs_ == co_.emcy_at_sync) fault(j, co_.emcy_code, now);
    if (n.nmt != NmtState::kOperational) continue;
    apply_rpdos(j, now);    // synchronous RPDOs received since the previous SYNC
    actuate(j, now);
    refresh(j);             // this SYNC's sample and the drive's state into the TPDOs
  }
  // TPDOs in arbitration order: every node's TPDO 1, then every node's TPDO 2.
  for (int p = 0; p < 2; ++p) {
    for (int j = 0; j < bank_.joints(); ++j) {
      const auto ju = static_cast<std::size_t>(j);
      const Node& n = node_[ju];
      if (n.nmt != NmtState::kOperational) continue;
      const std::uint32_t cob = value_[ju][static_cast<std::size_t>(find_entry(static_cast<std::uint16_t>(0x1800 + p), 1))];
      const std::uint32_t type = value_[ju][static_cast<std::size_t>(find_entry(static_cast<std::uint16_t>(0x1800 + p), 2))];
      if ((cob & 0x80000000u) != 0 || type == 0 || type > 240 || syncs_ % type != 0) continue;
      if (node_silent(j) || bank_.lose()) {
        bank_.stats().replies_dropped.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      can_frame f{};
      f.can_id = cob & 0x7FF;
      const int e0 = find_entry(static_cast<std::uint16_t>(0x1A00 + p), 0);
      const std::uint32_t count = value_[ju][static_cast<std::size_t>(e0)];
      int at = 0;
      for (std::uint32_t k = 1; k <= count; ++k) {
        const std::uint32_t m = value_[ju][static_cast<std::size_t>(e0) + k];
        const int me = find_entry(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>(m >> 8));
        const int len = static_cast<int>(m & 0xFF) / 8;
        const std::uint32_t v = me >= 0 ? value_[ju][static_cast<std::size_t>(me)] : 0;
        for (int i = 0; i < len && at + i < 8; ++i) f.data[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
        at += len;
      }
      f.len = static_cast<std::uint8_t>(std::min(at, 8));
      const std::int64_t window_ns = static_cast<std::int64_t>(value_[ju][kE1007]) * 1000;
      send(f, now, true, window_ns > 0 ? now + window_ns : 0);
    }
  }
  publish();
  // Sent by run() once every frame received so far is handled: a newer SYNC among them closes
  // this one's window first (a thread held past it must not answer an old SYNC after a new one).
}

}  // namespace pedalwave::drivers::canopen
