#include "pedalwave/telemetry/config.hpp"

#include <net/if.h>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pedalwave::telemetry {
namespace {

[[noreturn]] void fail(const std::string& item, const std::string& value,
                       const std::string& expected) {
  throw std::invalid_argument("telemetry config: " + item + " = " + value + ": expected " +
                              expected);
}

std::string num(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

void check_positive(const char* item, int v) {
  if (v < 1) fail(item, std::to_string(v), "an integer >= 1 (publish every k-th cycle)");
}

void check_interval(const char* lo_item, double lo, const char* hi_item, double hi) {
  if (!std::isfinite(lo)) fail(lo_item, num(lo), "a finite number");
  if (!std::isfinite(hi)) fail(hi_item, num(hi), "a finite number");
  if (lo > hi) fail(lo_item, num(lo), std::string("<= ") + hi_item + " (" + num(hi) + ")");
}

// Characters that could break out of the XML we build around peer addresses / interface names.
bool xml_safe(const std::string& s) {
  for (char c : s) {
    if (c == '<' || c == '>' || c == '&' || c == '"' || c == '\'') return false;
  }
  return true;
}

}  // namespace

void validate(const DomainConfig& d) {
  // Cyclone maps domain id d to UDP port 7400 + 250 d + offsets; above 232 the ports overflow.
  if (d.domain_id > 232) fail("domain_id", std::to_string(d.domain_id), "0..232");
  if (!xml_safe(d.interface)) fail("interface", d.interface, "a network interface name");
  if (!d.interface.empty() && if_nametoindex(d.interface.c_str()) == 0) {
    fail("interface", "\"" + d.interface + "\"",
         "an existing network interface on this machine (see `ip link`), e.g. \"lo\"");
  }
  for (const auto& p : d.peers) {
    if (p.empty() || !xml_safe(p)) fail("peers", "\"" + p + "\"", "an IPv4 address or host name");
  }
}

void TelemetryConfig::validate() const {
  telemetry::validate(domain());
  check_positive("decimation.joint_state", decimation.joint_state);
  check_positive("decimation.controller_state", decimation.controller_state);
  check_positive("decimation.observer_state", decimation.observer_state);
  check_positive("decimation.loop_timing", decimation.loop_timing);
  const auto& b = command_bounds;
  check_interval("command_bounds.amplitude_min", b.amplitude_min, "command_bounds.amplitude_max",
                 b.amplitude_max);
  check_interval("command_bounds.omega_min", b.omega_min, "command_bounds.omega_max", b.omega_max);
  check_interval("command_bounds.eta_min", b.eta_min, "command_bounds.eta_max", b.eta_max);
}

void SubscriberConfig::validate() const {
  telemetry::validate(domain());
  if (state_history_depth < 1 || state_history_depth > 10000) {
    fail("state_history_depth", std::to_string(state_history_depth), "1..10000");
  }
  if (sender.size() > 31) fail("sender", "\"" + sender + "\"", "at most 31 characters");
}

std::string cyclone_config_xml(const DomainConfig& d) {
  const bool loopback = d.interface == "lo";
  std::ostringstream x;
  x << "<CycloneDDS><Domain Id=\"any\"><General>";
  if (!d.interface.empty()) {
    x << "<Interfaces><NetworkInterface name=\"" << d.interface << "\"";
    if (loopback) x << " multicast=\"false\"";
    x << "/></Interfaces>";
  }
  // Linux's lo has no MULTICAST flag: discovery must go by unicast to known peers.
  if (loopback) x << "<AllowMulticast>false</AllowMulticast>";
  x << "</General><Discovery>";
  // Unicast discovery needs predictable ports: each process takes the next free participant index
  // and SPDP goes to the ports of indices 0..MaxAutoParticipantIndex at every peer.
  x << "<ParticipantIndex>auto</ParticipantIndex>"
    << "<MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>";
  if (loopback || !d.peers.empty()) {
    x << "<Peers>";
    if (loopback) x << "<Peer address=\"127.0.0.1\"/>";
    for (const auto& p : d.peers) x << "<Peer address=\"" << p << "\"/>";
    x << "</Peers>";
  }
  x << "</Discovery></Domain></CycloneDDS>";
  return x.str();
}

}  // namespace pedalwave::telemetry
