#include "pedalwave/telemetry/config.hpp"

#include <net/if.h>

#include <cmath>
#include <cstdlib>
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

void validate_ros_namespace(const std::string& item, const std::string& ns) {
  if (ns.empty()) return;
  const auto bad = [&] {
    fail(item, "\"" + ns + "\"",
         "a ROS 2 namespace: \"/\" then names [A-Za-z_][A-Za-z0-9_]* separated by \"/\", no "
         "trailing \"/\" (e.g. \"/snake1\")");
  };
  if (ns.size() > 63 || ns.front() != '/' || ns.back() == '/') bad();
  bool token_start = true;
  for (std::size_t i = 1; i < ns.size(); ++i) {
    const char c = ns[i];
    if (c == '/') {
      if (token_start) bad();  // "//"
      token_start = true;
      continue;
    }
    const bool alpha = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
    const bool digit = c >= '0' && c <= '9';
    if (!alpha && !(digit && !token_start)) bad();
    token_start = false;
  }
}

std::string ros_namespace_for(const std::string& robot_name) {
  if (robot_name.empty()) return "";
  std::string ns = "/";
  if (robot_name.front() >= '0' && robot_name.front() <= '9') ns += '_';
  for (char c : robot_name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    ns += ok ? c : '_';
  }
  return ns.substr(0, 63);
}

std::string TelemetryConfig::effective_namespace() const {
  return ros_namespace.empty() ? ros_namespace_for(robot_name) : ros_namespace;
}
std::string SubscriberConfig::effective_namespace() const {
  return ros_namespace.empty() ? ros_namespace_for(robot) : ros_namespace;
}

DomainChoice resolve_domain(const DomainRequest& req,
                            const std::function<const char*(const char*)>& getenv) {
  DomainChoice c;
  DomainConfig& d = c.domain;
  if (req.cli_domain != nullptr) {
    d.domain_id = *req.cli_domain;
    c.domain_source = "--domain";
  } else if (req.config_domain != nullptr) {
    d.domain_id = *req.config_domain;
    c.domain_source = "config";
  } else if (const char* env = getenv("ROS_DOMAIN_ID"); env != nullptr && *env != '\0') {
    char* end = nullptr;
    const unsigned long v = std::strtoul(env, &end, 10);
    if (*end != '\0' || v > 232 || env[0] == '-') {
      throw std::invalid_argument(std::string("environment: ROS_DOMAIN_ID = \"") + env +
                                  "\": expected an integer 0..232");
    }
    d.domain_id = static_cast<std::uint32_t>(v);
    c.domain_source = std::string("ROS_DOMAIN_ID=") + env;
  } else {
    d.domain_id = 0;
    c.domain_source = "default";
  }
  d.peers = req.config_peers;
  if (req.config_localhost_only) {
    d.interface = "lo";
    c.discovery_source = "config (localhost_only)";
  } else if (req.config_interface != nullptr) {
    d.interface = *req.config_interface;
    c.discovery_source = "config (interface " + *req.config_interface + ")";
  } else if (const char* uri = getenv("CYCLONEDDS_URI"); uri != nullptr && *uri != '\0') {
    d.interface = "";
    c.discovery_source = std::string("CYCLONEDDS_URI=") + uri;
  } else if (const char* lo = getenv("ROS_LOCALHOST_ONLY"); lo != nullptr && std::string(lo) == "1") {
    d.interface = "lo";
    c.discovery_source = "ROS_LOCALHOST_ONLY=1";
  } else {
    d.interface = "";
    c.discovery_source = "default";
  }
  return c;
}

void TelemetryConfig::validate() const {
  telemetry::validate(domain());
  if (robot_name.empty() || robot_name.size() > 63) {
    fail("robot_name", "\"" + robot_name + "\"", "1..63 characters");
  }
  validate_ros_namespace("ros_namespace", effective_namespace());
  if (!(diagnostics_period_s > 0.0) || !std::isfinite(diagnostics_period_s)) {
    fail("diagnostics_period_s", num(diagnostics_period_s), "a number > 0 [s]");
  }
  if (!(command_outcome_timeout_s > 0.0) || !std::isfinite(command_outcome_timeout_s)) {
    fail("command_outcome_timeout_s", num(command_outcome_timeout_s), "a number > 0 [s]");
  }
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
  if (robot.empty() || robot.size() > 63) fail("robot", "\"" + robot + "\"", "1..63 characters");
  validate_ros_namespace("ros_namespace", effective_namespace());
}

std::string cyclone_config_xml(const DomainConfig& d, const char* cyclonedds_uri) {
  if (d.interface.empty()) {
    // Cyclone's own choice (a default ROS 2 participant): its URI, plus our peers if any.
    std::string cfg = cyclonedds_uri != nullptr ? cyclonedds_uri : "";
    if (!d.peers.empty()) {
      if (!cfg.empty()) cfg += ",";
      cfg += "<CycloneDDS><Domain Id=\"any\"><Discovery><Peers>";
      for (const auto& p : d.peers) cfg += "<Peer address=\"" + p + "\"/>";
      cfg += "</Peers></Discovery></Domain></CycloneDDS>";
    }
    return cfg;
  }
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
