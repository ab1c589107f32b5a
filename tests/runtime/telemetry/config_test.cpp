// TelemetryConfig / SubscriberConfig validation and the Cyclone configuration XML.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "pedalwave/telemetry/config.hpp"

namespace pedalwave::telemetry {
namespace {

// Expects validate() to throw a message containing every fragment.
template <typename Config>
void expect_invalid(const Config& c, std::initializer_list<const char*> fragments) {
  try {
    c.validate();
    ADD_FAILURE() << "validate() accepted an invalid configuration";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    for (const char* f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << msg;
  }
}

TEST(TelemetryConfig, DefaultsAreValid) {
  EXPECT_NO_THROW(TelemetryConfig{}.validate());
  EXPECT_NO_THROW(SubscriberConfig{}.validate());
  EXPECT_EQ(TelemetryConfig{}.domain_id, 0u);
  EXPECT_EQ(TelemetryConfig{}.interface, "lo");
}

TEST(TelemetryConfig, ErrorsNameItemValueAndExpectation) {
  TelemetryConfig c;
  c.domain_id = 300;
  expect_invalid(c, {"domain_id", "300", "0..232"});

  c = {};
  c.interface = "nosuchif0";
  expect_invalid(c, {"interface", "nosuchif0", "existing network interface"});

  c = {};
  c.decimation.observer_state = 0;
  expect_invalid(c, {"decimation.observer_state", "= 0", ">= 1"});

  c = {};
  c.command_bounds.omega_min = 5.0;
  c.command_bounds.omega_max = 1.0;
  expect_invalid(c, {"command_bounds.omega_min", "5", "command_bounds.omega_max"});

  c = {};
  c.command_bounds.amplitude_max = std::nan("");
  expect_invalid(c, {"command_bounds.amplitude_max", "nan", "finite"});

  c = {};
  c.peers = {"10.0.0.1\"/><Evil"};
  expect_invalid(c, {"peers"});

  SubscriberConfig s;
  s.state_history_depth = 0;
  expect_invalid(s, {"state_history_depth", "0", "1..10000"});
  s = {};
  s.sender = std::string(40, 'x');
  expect_invalid(s, {"sender", "31"});
}

TEST(TelemetryConfig, LoopbackUsesUnicastDiscoveryToLocalhost) {
  DomainConfig d;
  d.interface = "lo";
  d.peers = {"192.0.2.7"};
  const std::string xml = cyclone_config_xml(d);
  EXPECT_NE(xml.find("<NetworkInterface name=\"lo\""), std::string::npos) << xml;
  EXPECT_NE(xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<Peer address=\"127.0.0.1\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<Peer address=\"192.0.2.7\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<ParticipantIndex>auto</ParticipantIndex>"), std::string::npos) << xml;
}

TEST(TelemetryConfig, OtherInterfacesKeepMulticastDiscovery) {
  DomainConfig d;
  d.interface = "eth0";
  const std::string xml = cyclone_config_xml(d);
  EXPECT_NE(xml.find("<NetworkInterface name=\"eth0\""), std::string::npos) << xml;
  EXPECT_EQ(xml.find("AllowMulticast"), std::string::npos) << xml;
  EXPECT_EQ(xml.find("<Peers>"), std::string::npos) << xml;
  d.interface = "";
  EXPECT_EQ(cyclone_config_xml(d).find("NetworkInterface"), std::string::npos);
}

}  // namespace
}  // namespace pedalwave::telemetry
