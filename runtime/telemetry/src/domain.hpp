// Internal: one Cyclone domain instance per (process, domain id), shared by every participant of
// this library in the process (Cyclone refuses to create the same domain id twice in a process),
// and RAII for entity handles. Topic names and QoS of every topic live here too, so the writer and
// reader sides can never disagree.
#pragma once

#include <dds/dds.h>

#include <memory>
#include <string>

#include "pedalwave/telemetry/config.hpp"

namespace pedalwave::telemetry::detail {

// Owns a dds_entity_t; dds_delete on destruction (deleting children with it).
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t e) : e_(e) {}
  ~Entity() { reset(); }
  Entity(Entity&& o) noexcept : e_(o.e_) { o.e_ = 0; }
  Entity& operator=(Entity&& o) noexcept {
    if (this != &o) {
      reset();
      e_ = o.e_;
      o.e_ = 0;
    }
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  void reset() noexcept {
    if (e_ > 0) dds_delete(e_);
    e_ = 0;
  }
  dds_entity_t get() const noexcept { return e_; }

 private:
  dds_entity_t e_ = 0;
};

// The process-wide domain instance for d.domain_id, created with cyclone_config_xml(d) on first
// use. A second user with a different interface/peers throws (one process, one configuration).
class Domain {
 public:
  ~Domain();
  Domain(const Domain&) = delete;
  Domain& operator=(const Domain&) = delete;
  std::uint32_t id() const noexcept { return id_; }
  // A participant on this domain with the process's DDS Security identity (if any): its QoS
  // carries the dds.sec.* properties. Throws std::runtime_error, naming the enclave when
  // security is on, if Cyclone refuses it.
  dds_entity_t create_participant() const;

 private:
  friend std::shared_ptr<Domain> acquire_domain(const DomainConfig& d);
  Domain() = default;
  std::uint32_t id_ = 0;
  dds_entity_t handle_ = 0;
  std::string xml_;
  SecurityConfig security_;
};
std::shared_ptr<Domain> acquire_domain(const DomainConfig& d);

// Checks a DDS return code; throws std::runtime_error naming `what` on error.
dds_entity_t check(dds_entity_t rc, const char* what);

// DDS topic names of one robot (ROS 2 convention: DDS name = "rt" + ROS name). `ns` is the
// robot's ROS namespace ("/snake1", or "" for the root). Per-robot topics live under it; the
// operator command topics and /diagnostics, /tf are shared by all robots of a domain.
struct TopicNames {
  explicit TopicNames(const std::string& ns);
  std::string joint_state, controller_state, observer_state, loop_timing;   // rt<ns>/pedalwave/...
  std::string mode_event, fault_event, description;
  std::string command, command_ack;                  // rt/pedalwave/command, rt/pedalwave/command_ack
  // rt/pedalwave/emergency_stop: OperatorCommand with kind e-stop only. A separate topic so DDS
  // Security permissions can grant e-stop to more identities than the command topic.
  std::string emergency_stop;
  std::string joint_states, robot_description_urdf;  // rt<ns>/joint_states, rt<ns>/robot_description
  std::string diagnostics, tf;                        // rt/diagnostics, rt/tf
};

// QoS classes (README.md "QoS"):
//   state:       best-effort, volatile, keep-last(depth)
//   event:       reliable, transient-local, keep-last(100)
//   description: reliable, transient-local, keep-last(1)
//   command:     reliable, volatile, keep-last(16)   (commands and acks)
inline constexpr int kStateWriterDepth = 4;
inline constexpr int kEventDepth = 100;
inline constexpr int kCommandDepth = 16;
//   ros:         reliable, volatile, keep-last(10; a reader max(10, state_depth))   (ROS 2's default profile: what
//                robot_state_publisher, RViz and `ros2 topic echo` match; max blocking 10 ms)
// Every class asks for XCDR1, the data representation rmw_cyclonedds uses.
enum class QosClass { kState, kEvent, kDescription, kCommand, kRos };
// A new dds_qos_t (caller deletes with dds_delete_qos). `state_depth` only for kState.
dds_qos_t* make_qos(QosClass c, int state_depth = kStateWriterDepth);

}  // namespace pedalwave::telemetry::detail
