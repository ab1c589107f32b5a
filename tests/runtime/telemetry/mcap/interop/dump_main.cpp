// pedalwave_mcap_dump FILE.mcap: what pedalwave::mcap::Reader reads from a file, as a canonical
// listing (tests/runtime/telemetry/mcap/interop/write_mcap.mjs writes the same listing of what @mcap/core wrote):
//   header <profile hex> <library hex>
//   schema <id> <name hex> <encoding hex> <data hex>               (by id)
//   channel <id> <schema id> <topic hex> <encoding hex> <k hex>=<v hex>,… or -   (by id, keys sorted)
//   message <channel id> <sequence> <log_time> <publish_time> <data hex or ->   (log-time order)
// A file the reader refuses: its error on stderr, exit 1.
#include <cstdio>
#include <exception>
#include <string>

#include "pedalwave/mcap/reader.hpp"

namespace {
std::string hex(const void* p, std::size_t n) {
  static const char* d = "0123456789abcdef";
  std::string s;
  const auto* b = static_cast<const unsigned char*>(p);
  for (std::size_t i = 0; i < n; ++i) {
    s += d[b[i] >> 4];
    s += d[b[i] & 15];
  }
  return s;
}
std::string hex(const std::string& s) { return hex(s.data(), s.size()); }
}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: pedalwave_mcap_dump FILE.mcap\n");
    return 2;
  }
  try {
    const pedalwave::mcap::Reader r{std::filesystem::path(argv[1])};
    std::printf("header %s %s\n", hex(r.profile()).c_str(), hex(r.library()).c_str());
    for (const auto& [id, s] : r.schemas())
      std::printf("schema %u %s %s %s\n", static_cast<unsigned>(id), hex(s.name).c_str(), hex(s.encoding).c_str(),
                  hex(s.data).c_str());
    for (const auto& [id, c] : r.channels()) {
      std::string meta;
      for (const auto& [k, v] : c.metadata) {
        if (!meta.empty()) meta += ',';
        meta.append(hex(k)).append(1, '=').append(hex(v));
      }
      std::printf("channel %u %u %s %s %s\n", static_cast<unsigned>(id), static_cast<unsigned>(c.schema_id),
                  hex(c.topic).c_str(), hex(c.message_encoding).c_str(), meta.empty() ? "-" : meta.c_str());
    }
    for (const auto& m : r.messages()) {
      const std::string d = hex(m.data.data(), m.data.size());
      std::printf("message %u %u %llu %llu %s\n", static_cast<unsigned>(m.channel), m.sequence,
                  static_cast<unsigned long long>(m.log_time), static_cast<unsigned long long>(m.publish_time),
                  d.empty() ? "-" : d.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
