// CsvRecorder: one file per topic, header from the first message, values round-trip exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <limits>

#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/recorder.hpp"

namespace pedalwave::telemetry {
namespace {

namespace fs = std::filesystem;

// Splits one CSV line ("" inside quotes is a quote).
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        out.back() += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        out.back() += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      out.emplace_back();
    } else {
      out.back() += c;
    }
  }
  return out;
}

std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) rows.push_back(split(line));
  return rows;
}

struct RecorderTest : ::testing::Test {
  fs::path dir = fs::temp_directory_path() / ("pedalwave_rec_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(RecorderTest, WritesOneFilePerTopicWithHeaderAndExactValues) {
  const std::string base = (dir / "run.csv").string();
  {
    CsvRecorder rec(base);
    EXPECT_EQ(rec.file_for("joint_state"), (dir / "run.joint_state.csv").string());
    JointStateMsg j{42, 123456789, 0.042, {0.1, -0.2}, {1.0 / 3.0, 2.0}, {3.0, 4.0},
                    {5e-5, 6.0}, {7.0, 1e300}};
    rec.on_joint_state(j, MessageInfo{11, 22, 1});
    j.seq = 43;
    rec.on_joint_state(j, MessageInfo{12, 23, 1});
    FaultEventMsg f{7, 99, 3, "encoder_stuck", 2, "degrade", 1, 0.25, 0.1, 5,
                    "stuck, says \"module\""};
    f.event_seq = 17;
    rec.on_fault_event(f, MessageInfo{13, 24, 2});
    EXPECT_EQ(rec.rows("joint_state"), 2u);
    EXPECT_EQ(rec.rows("fault_event"), 1u);
    EXPECT_EQ(rec.rows("loop_timing"), 0u);
  }
  const auto js = read_csv((dir / "run.joint_state.csv").string());
  ASSERT_EQ(js.size(), 3u);
  const std::vector<std::string> header = {
      "recv_ns", "source_time_ns", "seq", "stamp_ns", "t", "beta_1", "beta_2", "beta_dot_1",
      "beta_dot_2", "alpha_1", "alpha_2", "deflection_1", "deflection_2", "tau_sea_1",
      "tau_sea_2"};
  EXPECT_EQ(js[0], header);
  ASSERT_EQ(js[1].size(), header.size());
  EXPECT_EQ(js[1][0], "11");
  EXPECT_EQ(js[1][2], "42");
  EXPECT_EQ(js[1][3], "123456789");
  EXPECT_EQ(std::stod(js[1][4]), 0.042);
  EXPECT_EQ(std::stod(js[1][7]), 1.0 / 3.0) << "doubles must round-trip exactly";
  EXPECT_EQ(std::stod(js[1][11]), 5e-5);
  EXPECT_EQ(std::stod(js[1][14]), 1e300);
  EXPECT_EQ(js[2][2], "43");

  const auto fe = read_csv((dir / "run.fault_event.csv").string());
  ASSERT_EQ(fe.size(), 2u);
  const auto col = [&](const std::string& name) {
    const auto it = std::find(fe[0].begin(), fe[0].end(), name);
    EXPECT_NE(it, fe[0].end()) << name;
    return static_cast<std::size_t>(it - fe[0].begin());
  };
  EXPECT_EQ(fe[1][col("text")], "stuck, says \"module\"") << "text with comma and quotes survives";
  EXPECT_EQ(fe[1][col("event_seq")], "17");
  EXPECT_EQ(fe[1][5], "encoder_stuck");

  // Topics with no message: file exists, empty.
  EXPECT_TRUE(fs::exists(dir / "run.loop_timing.csv"));
  EXPECT_EQ(fs::file_size(dir / "run.loop_timing.csv"), 0u);
  EXPECT_TRUE(fs::exists(dir / "run.command_ack.csv"));
}

TEST_F(RecorderTest, LaterWidthChangeIsPaddedToTheHeaderAndCounted) {
  const std::string base = (dir / "w").string();
  {
    CsvRecorder rec(base);
    ObserverStateMsg o;
    o.residual = {1.0, 2.0, 3.0};
    o.tau_ext = {4.0, 5.0, 6.0};
    rec.on_observer_state(o, {});
    o.residual = {1.0};
    o.tau_ext = {4.0};
    rec.on_observer_state(o, {});
    EXPECT_EQ(rec.width_mismatches(), 1u);
  }
  const auto rows = read_csv((dir / "w.observer_state.csv").string());
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[1].size(), rows[0].size());
  EXPECT_EQ(rows[2].size(), rows[0].size()) << "a row must keep the header's column count";
  EXPECT_EQ(rows[2][5], "") << "missing joints are empty cells";
}

// The exact bytes of every topic's file (per-joint columns 1-based: beta_1 is beta[0]): the tools reading recordings (pedalwave_plotrec,
// pedalwave_identify, the monitor) rely on this layout. Numbers are written as fmt's "{}" writes
// them (shortest round-trip digits, fixed from 1e-4 up to 1e16, exponent form outside);
// integers in decimal; free text always quoted, enum names as they are.
TEST_F(RecorderTest, WritesTheDocumentedBytes) {
  const std::string base = (dir / "b").string();
  {
    CsvRecorder rec(base);
    rec.on_joint_state(JointStateMsg{1, -5, 100000.0, {0.0001, -0.0}, {1e16, 1e15}, {5e-5, 1.0 / 3.0},
                                     {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()},
                                     {-std::numeric_limits<double>::infinity(), 123456.5}},
                       MessageInfo{11, 22, 1});
    ControllerStateMsg c;
    c.seq = 18446744073709551615ull;
    c.stamp_ns = -9223372036854775807ll;
    c.t = 0.5;
    c.mode = 4;
    c.mode_name = "RUNNING";
    c.alpha_d = {2.5};
    c.eta = {0.25};
    c.u = {-1e-7};
    rec.on_controller_state(c, MessageInfo{1, 2, 3});
    ObserverStateMsg o;
    o.seq = 3;
    o.residual = {0.1};
    o.tau_ext = {0.2};
    o.body = {1, 2, 3, 4, 5, 6};
    o.fault_flags = 3;
    o.fault_joint = -1;
    o.forward_speed = 0.012;
    rec.on_observer_state(o, MessageInfo{});
    rec.on_loop_timing(LoopTimingMsg{7, 8, -9, 10, 11, 12, 13, 14, 15, 0}, MessageInfo{});
    ModeEventMsg m;
    m.from = 1;
    m.to = 2;
    m.from_name = "CONFIGURED";
    m.to_name = "READY";
    m.text = "plain";
    m.value = 1e20;
    m.event_seq = 2;
    rec.on_mode_event(m, MessageInfo{});
    DescriptionMsg d;
    d.links = 3;
    d.link_length = 0.1;
    d.spring_stiffness = {3.0, 3.5};
    d.rate_hz = 1000;
    d.name = "snake";
    d.driver = "sim";
    rec.on_description(d, MessageInfo{});
    OperatorCommandMsg cmd;
    cmd.kind = 1;
    cmd.id = 9;
    cmd.amplitude = 0.7;
    cmd.sender = "op";
    cmd.target = "*";
    rec.on_command(cmd, MessageInfo{});
    CommandAckMsg ack;
    ack.id = 9;
    ack.kind = 1;
    ack.status = AckStatus::kExecuted;
    ack.reason = "";
    ack.robot = "a\"b";
    rec.on_command_ack(ack, MessageInfo{});
  }
  const auto bytes = [&](const char* topic) {
    std::ifstream in(dir / ("b." + std::string(topic) + ".csv"), std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  };
  EXPECT_EQ(bytes("joint_state"),
            "recv_ns,source_time_ns,seq,stamp_ns,t,beta_1,beta_2,beta_dot_1,beta_dot_2,alpha_1,alpha_2,"
            "deflection_1,deflection_2,tau_sea_1,tau_sea_2\n"
            "11,22,1,-5,100000,0.0001,-0,1e+16,1000000000000000,5e-05,0.3333333333333333,nan,inf,"
            "-inf,123456.5\n");
  EXPECT_EQ(bytes("controller_state"),
            "recv_ns,source_time_ns,seq,stamp_ns,t,mode,mode_name,alpha_d_1,eta_1,u_1\n"
            "1,2,18446744073709551615,-9223372036854775807,0.5,4,RUNNING,2.5,0.25,-1e-07\n");
  EXPECT_EQ(bytes("observer_state"),
            "recv_ns,source_time_ns,seq,stamp_ns,residual_1,tau_ext_1,theta_N,p_x,p_z,theta_N_dot,"
            "p_x_dot,p_z_dot,fault_flags,fault_names,fault_joint,forward_speed\n"
            "0,0,3,0,0.1,0.2,1,2,3,4,5,6,3,\"" + fault_flags_names(3) + "\",-1,0.012\n");
  EXPECT_EQ(bytes("loop_timing"),
            "recv_ns,source_time_ns,seq,stamp_ns,wake_latency_ns,t_read_ns,t_observe_ns,t_control_ns,"
            "t_write_ns,overruns,ring_drops\n"
            "0,0,7,8,-9,10,11,12,13,14,15\n");
  EXPECT_EQ(bytes("mode_event"),
            "recv_ns,source_time_ns,seq,stamp_ns,from,from_name,to,to_name,text,event_seq,value,"
            "severity\n"
            "0,0,0,0,1,CONFIGURED,2,READY,\"plain\",2,1e+20,0\n");
  EXPECT_EQ(bytes("robot_description"),
            "recv_ns,source_time_ns,links,link_length,link_mass,rotor_mass,rotor_inertia,gear_ratio,"
            "rate_hz,joint_state_rate_hz,controller_state_rate_hz,observer_state_rate_hz,"
            "loop_timing_rate_hz,name,driver,spring_stiffness_1,spring_stiffness_2\n"
            "0,0,3,0.1,0,0,0,0,1000,0,0,0,0,\"snake\",\"sim\",3,3.5\n");
  EXPECT_EQ(bytes("command"),
            "recv_ns,source_time_ns,id,kind,kind_name,amplitude,omega,eta,sender,target\n"
            "0,0,9,1," + std::string(command_kind_name(1)) + ",0.7,0,0,\"op\",\"*\"\n");
  EXPECT_EQ(bytes("command_ack"),
            "recv_ns,source_time_ns,id,kind,kind_name,status,stamp_ns,reason,robot\n"
            "0,0,9,1," + std::string(command_kind_name(1)) + ",executed,0,\"\",\"a\"\"b\"\n");
  EXPECT_EQ(bytes("fault_event"), "");
}

TEST_F(RecorderTest, UnwritablePathThrowsAtConstruction) {
  EXPECT_THROW(CsvRecorder((dir / "no/such/dir/run.csv").string()), std::runtime_error);
  EXPECT_THROW(CsvRecorder(".csv"), std::invalid_argument);
}

}  // namespace
}  // namespace pedalwave::telemetry
