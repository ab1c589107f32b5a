// DDS Security (OMG DDS Security 1.1, Cyclone's plugins) with an SROS2 keystore: which identity a
// process uses, where it comes from (command line, configuration file, ROS 2 environment), the
// checks a keystore passes before a participant is created, and the Cyclone participant QoS
// properties that switch the plugins on. README.md "Securing a robot (DDS Security, SROS2)".
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace pedalwave::telemetry {

// One process's identity. Off by default (no security, as before).
struct SecurityConfig {
  bool enabled = false;
  std::string keystore;   // SROS2 keystore folder (ROS_SECURITY_KEYSTORE)
  std::string enclave;    // enclave path in it, e.g. "/pedalwave/snake1" (ROS_SECURITY_ENCLAVE_OVERRIDE)
  // <keystore>/enclaves<enclave>: cert.pem, key.pem, identity_ca.cert.pem,
  // permissions_ca.cert.pem, governance.p7s, permissions.p7s.
  std::string enclave_dir() const;
  bool operator==(const SecurityConfig&) const = default;
};

// Where the settings come from, highest first: the command line, the file's `security:` section,
// the ROS 2 environment (ROS_SECURITY_ENABLE=true, ROS_SECURITY_KEYSTORE,
// ROS_SECURITY_ENCLAVE_OVERRIDE, ROS_SECURITY_STRATEGY=Enforce|Permissive), the default enclave.
struct SecurityRequest {
  const std::string* cli_keystore = nullptr;   // --security-keystore (turns security on)
  const std::string* cli_enclave = nullptr;    // --security-enclave
  bool config_present = false;                 // the file has a security: section
  bool config_enable = true;                   // its `enable` (default true)
  std::string config_keystore, config_enclave; // its `keystore`, `enclave` (empty: not given)
  std::string config_strategy;                 // its `strategy` ("enforce"/"permissive", empty)
  std::string default_enclave;                 // the daemon: /pedalwave/<robot name>; "" none
};
struct SecurityChoice {
  SecurityConfig security;
  std::string source;    // "--security-keystore", "config", "ROS_SECURITY_ENABLE=true", "off"
  std::string warning;   // non-empty: Permissive strategy fell back to no security, and why
};
// Throws std::invalid_argument naming the item and value (a missing keystore or enclave, a bad
// strategy). Permissive (ROS 2's default strategy) with an enclave folder that does not exist
// runs without security and says so in `warning`; Enforce refuses.
SecurityChoice resolve_security(const SecurityRequest& req,
                                const std::function<const char*(const char*)>& getenv);

// Checks the enclave before DDS sees it (Cyclone's own refusal names no file): every file exists
// and parses; cert.pem is within its validity and issued by identity_ca.cert.pem; key.pem is its
// key; governance.p7s and permissions.p7s are S/MIME signed by permissions_ca.cert.pem;
// permissions.p7s has a grant for the certificate's subject, valid now, allowing `domain_id`;
// the governance covers `domain_id`. Throws std::invalid_argument "security: <file>: <what is
// wrong>".
void check_keystore(const SecurityConfig& s, std::uint32_t domain_id);

// One line for the start line: "DDS Security ON: enclave /pedalwave/snake1 (CN=...,
// certificate valid until ...), keystore /etc/...; governance: <protection>".
std::string describe_security(const SecurityConfig& s);

// Cyclone's participant QoS properties (dds.sec.auth.*, dds.sec.access.*, dds.sec.crypto.*) for
// `s`, with the plugin libraries Debian's libddsc0debian ships. Empty when !s.enabled.
std::vector<std::pair<std::string, std::string>> security_properties(const SecurityConfig& s);

// Whether Cyclone's three security plugins are installed (tests SKIP without them).
bool security_plugins_available();

}  // namespace pedalwave::telemetry
