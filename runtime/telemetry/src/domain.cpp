#include "domain.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdlib>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <chrono>

namespace pedalwave::telemetry::detail {
namespace {

// Recursive: a Domain whose last reference dies inside acquire_domain (while the lock is held)
// locks it again in its destructor.
std::recursive_mutex g_mutex;
std::map<std::uint32_t, std::weak_ptr<Domain>> g_domains;

}  // namespace

dds_entity_t check(dds_entity_t rc, const char* what) {
  if (rc < 0) {
    throw std::runtime_error(std::string("telemetry: ") + what + " failed: " +
                             dds_strretcode(rc));
  }
  return rc;
}

Domain::~Domain() {
  // Under the registry lock, so acquire_domain never sees the id half-deleted.
  std::lock_guard lock(g_mutex);
  if (handle_ > 0) dds_delete(handle_);
}

std::shared_ptr<Domain> acquire_domain(const DomainConfig& d) {
  validate(d);
  const std::string xml = cyclone_config_xml(d, std::getenv("CYCLONEDDS_URI"));
  std::unique_lock lock(g_mutex);
  if (auto existing = g_domains[d.domain_id].lock()) {
    if (existing->security_ != d.security) {
      throw std::invalid_argument(
          "telemetry: domain " + std::to_string(d.domain_id) +
          " already open in this process with another DDS Security identity; expected one "
          "keystore and enclave per process");
    }
    if (existing->xml_ != xml) {
      throw std::invalid_argument(
          "telemetry: domain " + std::to_string(d.domain_id) +
          " already open in this process with another configuration (interface/peers); "
          "expected the same interface and peers for every participant of one process");
    }
    return existing;
  }
  // A bad keystore is refused here, naming the file, before Cyclone (whose refusal names none).
  check_keystore(d.security, d.domain_id);
  std::shared_ptr<Domain> dom(new Domain());
  dom->id_ = d.domain_id;
  dom->xml_ = xml;
  dom->security_ = d.security;
  dds_entity_t h = dds_create_domain(static_cast<dds_domainid_t>(d.domain_id), xml.c_str());
  // The previous instance of this id may be between its last reference and its dds_delete
  // (destructor waiting for the lock we hold): let it finish, then retry.
  for (int retry = 0; h == DDS_RETCODE_PRECONDITION_NOT_MET && retry < 200; ++retry) {
    lock.unlock();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    lock.lock();
    if (auto existing = g_domains[d.domain_id].lock()) {
      if (existing->xml_ == xml && existing->security_ == d.security) return existing;
    }
    h = dds_create_domain(static_cast<dds_domainid_t>(d.domain_id), xml.c_str());
  }
  if (h < 0) {
    throw std::runtime_error("telemetry: creating DDS domain " + std::to_string(d.domain_id) +
                             " on interface \"" + d.interface + "\" failed: " +
                             dds_strretcode(h) +
                             " (another library in this process may have opened that domain "
                             "id with a default configuration)");
  }
  dom->handle_ = h;
  g_domains[d.domain_id] = dom;
  spdlog::debug("telemetry: DDS domain {} created on interface \"{}\"", d.domain_id, d.interface);
  return dom;
}

dds_entity_t Domain::create_participant() const {
  dds_qos_t* q = dds_create_qos();
  for (const auto& [name, value] : security_properties(security_)) {
    dds_qset_prop(q, name.c_str(), value.c_str());
  }
  const dds_entity_t p = dds_create_participant(static_cast<dds_domainid_t>(id_), q, nullptr);
  dds_delete_qos(q);
  if (p < 0 && security_.enabled) {
    throw std::runtime_error(
        std::string("telemetry: DDS Security refused the participant of enclave ") +
        security_.enclave + " (" + security_.enclave_dir() + "): " + dds_strretcode(p) +
        " (the Cyclone security plugins could not load, or rejected the certificate, governance "
        "or permissions; CYCLONEDDS_URI with <Tracing><Verbosity>finest</Verbosity> shows why)");
  }
  return check(p, "dds_create_participant");
}

TopicNames::TopicNames(const std::string& ns) {
  const std::string p = "rt" + ns + "/pedalwave/";
  joint_state = p + "joint_state";
  controller_state = p + "controller_state";
  observer_state = p + "observer_state";
  loop_timing = p + "loop_timing";
  mode_event = p + "mode_event";
  fault_event = p + "fault_event";
  description = p + "robot_description";
  command = "rt/pedalwave/command";
  command_ack = "rt/pedalwave/command_ack";
  emergency_stop = "rt/pedalwave/emergency_stop";
  joint_states = "rt" + ns + "/joint_states";
  robot_description_urdf = "rt" + ns + "/robot_description";
  diagnostics = "rt/diagnostics";
  tf = "rt/tf";
}

dds_qos_t* make_qos(QosClass c, int state_depth) {
  dds_qos_t* q = dds_create_qos();
  switch (c) {
    case QosClass::kState:
      dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
      dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, state_depth);
      break;
    case QosClass::kEvent:
      // Bounded blocking: a reliable write waits at most 10 ms for history space; the
      // telemetry thread then drops the event (counted) rather than stalling.
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(10));
      dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, kEventDepth);
      // What a late joiner gets is the durability-service history (Cyclone's default keeps 1).
      dds_qset_durability_service(q, 0, DDS_HISTORY_KEEP_LAST, kEventDepth, DDS_LENGTH_UNLIMITED,
                                  DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
      break;
    case QosClass::kDescription:
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(10));
      dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
      dds_qset_durability_service(q, 0, DDS_HISTORY_KEEP_LAST, 1, DDS_LENGTH_UNLIMITED,
                                  DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
      break;
    case QosClass::kCommand:
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
      dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, kCommandDepth);
      break;
    case QosClass::kRos:
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(10));
      dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
      // ROS's default depth 10 for writers; a reader keeps its state_history_depth (history
      // depth is not matched between writer and reader).
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, std::max(state_depth, 10));
      break;
  }
  const dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(q, 1, &xcdr1);
  return q;
}

}  // namespace pedalwave::telemetry::detail
