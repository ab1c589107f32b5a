#include "pedalwave/telemetry/subscriber.hpp"

#include <algorithm>
#include <array>
#include <ctime>
#include <functional>
#include <thread>

#include <dds/ddsi/ddsi_serdata.h>

#include "convert.hpp"
#include "domain.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::telemetry {

using namespace detail;

namespace {

using pedalwave::monotonic_ns;

// One reader and how to dispatch its samples. Samples are taken serialized (dds_takecdr): the
// bytes go to the raw listeners as they are, then they are deserialized into `sample` (reused,
// its strings and sequences reallocated by Cyclone as needed) for the decoded listeners.
struct ReaderSlot {
  dds_entity_t reader = 0;
  dds_entity_t cond = 0;
  const dds_topic_descriptor_t* desc = nullptr;
  std::shared_ptr<void> sample;
  std::function<void(const void*, const MessageInfo&)> dispatch;
};

// "pedalwave::msg::dds_::JointState_" → "pedalwave/msg/JointState".
std::string ros_type_name(const char* dds_name) {
  std::string s = dds_name;
  std::string out;
  for (std::size_t i = 0; i < s.size();) {
    if (s.compare(i, 2, "::") == 0) {
      out += '/';
      i += 2;
    } else {
      out += s[i++];
    }
  }
  if (const auto k = out.find("/dds_/"); k != std::string::npos) out.erase(k, 5);
  if (!out.empty() && out.back() == '_') out.pop_back();
  return out;
}

TopicInfo topic_info(const char* dds_topic, const dds_topic_descriptor_t* desc, QosClass qc) {
  TopicInfo t;
  t.topic = std::string(dds_topic).substr(2);  // DDS "rt/x" = ROS "/x"
  t.type = ros_type_name(desc->m_typename);
  switch (qc) {
    case QosClass::kState: t = {t.topic, t.type, false, false, static_cast<unsigned>(kStateWriterDepth)}; break;
    case QosClass::kEvent: t = {t.topic, t.type, true, true, static_cast<unsigned>(kEventDepth)}; break;
    case QosClass::kDescription: t = {t.topic, t.type, true, true, 1}; break;
    case QosClass::kCommand: t = {t.topic, t.type, true, false, static_cast<unsigned>(kCommandDepth)}; break;
    case QosClass::kRos: t = {t.topic, t.type, true, false, 10}; break;
  }
  return t;
}

}  // namespace

struct TelemetrySubscriber::Impl {
  SubscriberConfig cfg;
  std::shared_ptr<Domain> domain;
  Entity participant;
  dds_entity_t waitset = 0;
  dds_entity_t w_cmd = 0, w_estop = 0;   // 0: this identity may not publish there (security)
  std::string cmd_refusal, estop_refusal;
  std::vector<ReaderSlot> readers;
  std::size_t joint_reader_index = 0;   // readers[] slot of joint_state
  std::size_t ack_reader_index = 0;     // readers[] slot of command_ack
  std::vector<TelemetryListener*> listeners;
  std::vector<RawMessageListener*> raw_listeners;
  std::vector<TopicInfo> topic_infos;   // readers[i]'s topic
  std::vector<std::byte> raw;           // one serialized sample
  TopicNames topics{""};

  template <typename Msg, typename Decoded>
  void add_reader(const dds_topic_descriptor_t* desc, const char* name, QosClass qc,
                  void (TelemetryListener::*method)(const Decoded&, const MessageInfo&)) {
    const dds_entity_t topic = check(
        dds_create_topic(participant.get(), desc, name, nullptr, nullptr), "dds_create_topic");
    dds_qos_t* q = make_qos(qc, cfg.state_history_depth);
    const dds_entity_t r = dds_create_reader(participant.get(), topic, q, nullptr);
    dds_delete_qos(q);
    check(r, "dds_create_reader");
    ReaderSlot slot;
    slot.reader = r;
    slot.desc = desc;
    slot.sample = std::shared_ptr<void>(dds_alloc(desc->m_size), [desc](void* p) {
      dds_sample_free(p, desc, DDS_FREE_ALL);
    });
    topic_infos.push_back(topic_info(name, desc, qc));
    slot.cond = check(dds_create_readcondition(r, DDS_ANY_STATE), "dds_create_readcondition");
    check(dds_waitset_attach(waitset, slot.cond, static_cast<dds_attach_t>(readers.size())),
          "dds_waitset_attach");
    slot.dispatch = [this, method](const void* sample, const MessageInfo& info) {
      const Decoded d = decode(*static_cast<const Msg*>(sample));
      for (TelemetryListener* l : listeners) (l->*method)(d, info);
    };
    readers.push_back(std::move(slot));
  }
};

TelemetrySubscriber::TelemetrySubscriber(const SubscriberConfig& config)
    : impl_(std::make_unique<Impl>()) {
  config.validate();
  Impl& m = *impl_;
  m.cfg = config;
  m.domain = acquire_domain(config.domain());
  m.participant = Entity(m.domain->create_participant());
  m.waitset = check(dds_create_waitset(m.participant.get()), "dds_create_waitset");

  using L = TelemetryListener;
  const TopicNames t(config.effective_namespace());
  m.topics = t;
  // Description first: within one poll a listener sees it before the rest.
  m.add_reader<pedalwave_msg_dds__RobotDescription_>(&pedalwave_msg_dds__RobotDescription__desc,
                                                     t.description.c_str(), QosClass::kDescription,
                                                     &L::on_description);
  m.joint_reader_index = m.readers.size();
  m.add_reader<pedalwave_msg_dds__JointState_>(&pedalwave_msg_dds__JointState__desc,
                                               t.joint_state.c_str(), QosClass::kState,
                                               &L::on_joint_state);
  m.add_reader<pedalwave_msg_dds__ControllerState_>(&pedalwave_msg_dds__ControllerState__desc,
                                                    t.controller_state.c_str(), QosClass::kState,
                                                    &L::on_controller_state);
  m.add_reader<pedalwave_msg_dds__ObserverState_>(&pedalwave_msg_dds__ObserverState__desc,
                                                  t.observer_state.c_str(), QosClass::kState,
                                                  &L::on_observer_state);
  m.add_reader<pedalwave_msg_dds__LoopTiming_>(&pedalwave_msg_dds__LoopTiming__desc,
                                               t.loop_timing.c_str(), QosClass::kState,
                                               &L::on_loop_timing);
  m.add_reader<pedalwave_msg_dds__ModeEvent_>(&pedalwave_msg_dds__ModeEvent__desc,
                                              t.mode_event.c_str(), QosClass::kEvent,
                                              &L::on_mode_event);
  m.add_reader<pedalwave_msg_dds__FaultEvent_>(&pedalwave_msg_dds__FaultEvent__desc,
                                               t.fault_event.c_str(), QosClass::kEvent,
                                               &L::on_fault_event);
  m.add_reader<pedalwave_msg_dds__OperatorCommand_>(&pedalwave_msg_dds__OperatorCommand__desc,
                                                    t.command.c_str(), QosClass::kCommand,
                                                    &L::on_command);
  m.add_reader<pedalwave_msg_dds__OperatorCommand_>(&pedalwave_msg_dds__OperatorCommand__desc,
                                                    t.emergency_stop.c_str(), QosClass::kCommand,
                                                    &L::on_command);
  m.ack_reader_index = m.readers.size();
  m.add_reader<pedalwave_msg_dds__CommandAck_>(&pedalwave_msg_dds__CommandAck__desc,
                                               t.command_ack.c_str(), QosClass::kCommand,
                                               &L::on_command_ack);
  if (config.standard_topics) {
    m.add_reader<std_msgs_msg_dds__String_>(&std_msgs_msg_dds__String__desc,
                                            t.robot_description_urdf.c_str(),
                                            QosClass::kDescription, &L::on_urdf);
    m.add_reader<sensor_msgs_msg_dds__JointState_>(&sensor_msgs_msg_dds__JointState__desc,
                                                   t.joint_states.c_str(), QosClass::kRos,
                                                   &L::on_joint_states);
    m.add_reader<diagnostic_msgs_msg_dds__DiagnosticArray_>(
        &diagnostic_msgs_msg_dds__DiagnosticArray__desc, t.diagnostics.c_str(), QosClass::kRos,
        &L::on_diagnostics);
    m.add_reader<tf2_msgs_msg_dds__TFMessage_>(&tf2_msgs_msg_dds__TFMessage__desc,
                                               t.tf.c_str(), QosClass::kRos, &L::on_tf);
  }

  // Command writers (same topic entities as the command readers: look them up by name). With
  // DDS Security the permissions may refuse either (a monitor-only or e-stop-only identity): the
  // subscriber still works, send_command() then refuses and says why (command_refusal()).
  const auto make_cmd_writer = [&](const std::string& topic, std::string& refusal) {
    const dds_entity_t tp =
        check(dds_create_topic(m.participant.get(), &pedalwave_msg_dds__OperatorCommand__desc,
                               topic.c_str(), nullptr, nullptr),
              "dds_create_topic(command)");
    dds_qos_t* q = make_qos(QosClass::kCommand);
    const dds_entity_t w = dds_create_writer(m.participant.get(), tp, q, nullptr);
    dds_delete_qos(q);
    if (w == DDS_RETCODE_NOT_ALLOWED_BY_SECURITY) {
      refusal = "the permissions of enclave " + config.security.enclave +
                " do not allow publishing on " + topic.substr(2);
      return dds_entity_t{0};
    }
    return check(w, "dds_create_writer(command)");
  };
  m.w_cmd = make_cmd_writer(t.command, m.cmd_refusal);
  m.w_estop = make_cmd_writer(t.emergency_stop, m.estop_refusal);
}

TelemetrySubscriber::~TelemetrySubscriber() { impl_->participant.reset(); }

void TelemetrySubscriber::add_listener(TelemetryListener& l) { impl_->listeners.push_back(&l); }

void TelemetrySubscriber::remove_listener(TelemetryListener& l) {
  auto& v = impl_->listeners;
  v.erase(std::remove(v.begin(), v.end(), &l), v.end());
}

void TelemetrySubscriber::add_raw_listener(RawMessageListener& l) {
  impl_->raw_listeners.push_back(&l);
}

void TelemetrySubscriber::remove_raw_listener(RawMessageListener& l) {
  auto& v = impl_->raw_listeners;
  v.erase(std::remove(v.begin(), v.end(), &l), v.end());
}

const std::vector<TopicInfo>& TelemetrySubscriber::topics() const { return impl_->topic_infos; }

std::size_t TelemetrySubscriber::poll(std::chrono::nanoseconds timeout) {
  Impl& m = *impl_;
  std::vector<dds_attach_t> triggered(m.readers.size());
  const dds_return_t n = dds_waitset_wait(m.waitset, triggered.data(), triggered.size(),
                                          static_cast<dds_duration_t>(timeout.count()));
  if (n <= 0) return 0;
  constexpr std::uint32_t kBatch = 64;
  std::size_t dispatched = 0;
  // Every reader, not only the triggered ones: keeps the topics in step within one poll.
  for (std::size_t r = 0; r < m.readers.size(); ++r) {
    const ReaderSlot& slot = m.readers[r];
    for (;;) {
      std::array<ddsi_serdata*, kBatch> buf{};
      std::array<dds_sample_info_t, kBatch> info{};
      const dds_return_t got = dds_takecdr(slot.cond, buf.data(), kBatch, info.data(), DDS_ANY_STATE);
      if (got <= 0) break;
      const std::int64_t now = monotonic_ns();
      for (dds_return_t i = 0; i < got; ++i) {
        const auto k = static_cast<std::size_t>(i);
        const auto& si = info[k];
        if (si.valid_data) {
          const MessageInfo mi{now, si.source_timestamp, si.publication_handle};
          if (!m.raw_listeners.empty()) {
            m.raw.resize(ddsi_serdata_size(buf[k]));
            ddsi_serdata_to_ser(buf[k], 0, m.raw.size(), m.raw.data());
            for (RawMessageListener* l : m.raw_listeners) l->on_raw(r, m.raw, mi);
          }
          if (ddsi_serdata_to_sample(buf[k], slot.sample.get(), nullptr, nullptr)) {
            slot.dispatch(slot.sample.get(), mi);
            ++dispatched;
          }
        }
        ddsi_serdata_unref(buf[k]);
      }
      if (static_cast<std::uint32_t>(got) < kBatch) break;
    }
  }
  return dispatched;
}

bool TelemetrySubscriber::send_command(const runtime::OperatorCommand& c) {
  return send_command(c, impl_->cfg.robot);
}

bool TelemetrySubscriber::send_command(const runtime::OperatorCommand& c,
                                       const std::string& target) {
  pedalwave_msg_dds__OperatorCommand_ msg{};
  fill(c, target.c_str(), impl_->cfg.sender.c_str(), msg);
  // An e-stop goes on its own topic (the robot reads both; permissions may grant only that one).
  const bool estop = c.kind == runtime::OperatorCommandKind::kEmergencyStop;
  const dds_entity_t w = estop ? impl_->w_estop : impl_->w_cmd;
  if (w == 0) return false;
  return dds_write(w, &msg) == DDS_RETCODE_OK;
}

bool TelemetrySubscriber::wait_for_robot(std::chrono::nanoseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  // Only a robot writes acks.
  const dds_entity_t ack_reader = impl_->readers[impl_->ack_reader_index].reader;
  for (;;) {
    dds_subscription_matched_status_t acks{};
    dds_publication_matched_status_t cmds{};
    // A robot's ack writer matched us, and our command writer matched a reader besides our own
    // participant's command reader.
    if (dds_get_subscription_matched_status(ack_reader, &acks) == DDS_RETCODE_OK &&
        dds_get_publication_matched_status(impl_->w_cmd ? impl_->w_cmd : impl_->w_estop,
                                           &cmds) == DDS_RETCODE_OK &&
        acks.current_count > 0 && cmds.current_count > 1) {
      return true;
    }
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

int TelemetrySubscriber::joint_state_writers() const {
  dds_subscription_matched_status_t st{};
  if (dds_get_subscription_matched_status(
          impl_->readers[impl_->joint_reader_index].reader, &st) < 0) return 0;
  return static_cast<int>(st.current_count);
}

std::string TelemetrySubscriber::command_refusal(runtime::OperatorCommandKind kind) const {
  return kind == runtime::OperatorCommandKind::kEmergencyStop ? impl_->estop_refusal
                                                              : impl_->cmd_refusal;
}

const SubscriberConfig& TelemetrySubscriber::config() const { return impl_->cfg; }

}  // namespace pedalwave::telemetry
