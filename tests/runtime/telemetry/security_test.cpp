// DDS Security settings: where they come from (command line > file > ROS 2 environment), what a
// missing keystore / enclave / bad strategy says, the Cyclone properties they turn into. The
// end-to-end behaviour with real certificates is security_test.sh.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <string>

#include "pedalwave/telemetry/security.hpp"

using namespace pedalwave::telemetry;
namespace fs = std::filesystem;

namespace {

struct Env {
  std::map<std::string, std::string> vars;
  std::function<const char*(const char*)> fn() const {
    return [this](const char* k) -> const char* {
      const auto it = vars.find(k);
      return it == vars.end() ? nullptr : it->second.c_str();
    };
  }
};

class Keystore : public ::testing::Test {
 protected:
  void SetUp() override {
    root = fs::temp_directory_path() / ("pw_sec_" + std::to_string(::getpid()));
    fs::create_directories(root / "enclaves/pedalwave/alice");
    fs::create_directories(root / "enclaves/pedalwave/snake1");
  }
  void TearDown() override { fs::remove_all(root); }
  std::string error_of(const SecurityRequest& r, const Env& e) {
    try {
      resolve_security(r, e.fn());
    } catch (const std::invalid_argument& x) {
      return x.what();
    }
    return "(no error)";
  }
  fs::path root;
};

}  // namespace

TEST_F(Keystore, OffUnlessAskedFor) {
  const SecurityChoice c = resolve_security({}, Env{}.fn());
  EXPECT_FALSE(c.security.enabled);
  EXPECT_EQ(c.source, "off");
  // ROS_SECURITY_KEYSTORE alone does not turn it on (ROS 2: ROS_SECURITY_ENABLE=true does).
  Env e{{{"ROS_SECURITY_KEYSTORE", root.string()}}};
  EXPECT_FALSE(resolve_security({}, e.fn()).security.enabled);
}

TEST_F(Keystore, Ros2EnvironmentThenFileThenCommandLine) {
  Env e{{{"ROS_SECURITY_ENABLE", "true"},
         {"ROS_SECURITY_KEYSTORE", root.string()},
         {"ROS_SECURITY_ENCLAVE_OVERRIDE", "/pedalwave/alice"}}};
  SecurityChoice c = resolve_security({}, e.fn());
  EXPECT_TRUE(c.security.enabled);
  EXPECT_EQ(c.source, "ROS_SECURITY_ENABLE=true");
  EXPECT_EQ(c.security.enclave_dir(), (root / "enclaves").string() + "/pedalwave/alice");

  SecurityRequest file;
  file.config_present = true;
  file.config_enclave = "/pedalwave/snake1";
  c = resolve_security(file, e.fn());
  EXPECT_EQ(c.source, "config");
  EXPECT_EQ(c.security.enclave, "/pedalwave/snake1") << "the file beats the environment";
  EXPECT_EQ(c.security.keystore, root.string()) << "the environment fills what the file leaves";

  const std::string cli_enclave = "/pedalwave/alice";
  file.cli_enclave = &cli_enclave;
  EXPECT_EQ(resolve_security(file, e.fn()).security.enclave, "/pedalwave/alice");

  // enable: false in the file turns it off whatever the environment says.
  SecurityRequest off;
  off.config_present = true;
  off.config_enable = false;
  EXPECT_FALSE(resolve_security(off, e.fn()).security.enabled);

  // The daemon's default enclave /pedalwave/<name>.
  SecurityRequest daemon;
  daemon.default_enclave = "/pedalwave/snake1";
  Env e2{{{"ROS_SECURITY_ENABLE", "true"}, {"ROS_SECURITY_KEYSTORE", root.string()}}};
  EXPECT_EQ(resolve_security(daemon, e2.fn()).security.enclave, "/pedalwave/snake1");
}

TEST_F(Keystore, MissingPiecesAreNamed) {
  Env no_keystore{{{"ROS_SECURITY_ENABLE", "true"}}};
  EXPECT_EQ(error_of({}, no_keystore).rfind("security: ROS_SECURITY_KEYSTORE is not set", 0), 0u)
      << error_of({}, no_keystore);
  Env no_enclave{{{"ROS_SECURITY_ENABLE", "true"}, {"ROS_SECURITY_KEYSTORE", root.string()}}};
  EXPECT_NE(error_of({}, no_enclave).find("enclave = \"\": expected an enclave path"),
            std::string::npos);
  Env bad_strategy = no_enclave;
  bad_strategy.vars["ROS_SECURITY_STRATEGY"] = "Lenient";
  EXPECT_EQ(error_of({}, bad_strategy),
            "security: ROS_SECURITY_STRATEGY = \"Lenient\": expected Enforce or Permissive");

  // An enclave folder that does not exist: Enforce refuses, Permissive runs without security.
  Env missing = no_enclave;
  missing.vars["ROS_SECURITY_ENCLAVE_OVERRIDE"] = "/pedalwave/nobody";
  const std::string folder = (root / "enclaves").string() + "/pedalwave/nobody";
  EXPECT_EQ(error_of({}, missing).rfind("security: " + folder + ": enclave folder missing", 0), 0u)
      << error_of({}, missing);
  missing.vars["ROS_SECURITY_STRATEGY"] = "Permissive";
  const SecurityChoice c = resolve_security({}, missing.fn());
  EXPECT_FALSE(c.security.enabled);
  EXPECT_NE(c.warning.find("running WITHOUT DDS Security"), std::string::npos) << c.warning;
}

TEST_F(Keystore, AnEmptyEnclaveIsRefusedNamingTheFirstMissingFile) {
  SecurityConfig s{true, root.string(), "/pedalwave/alice"};
  try {
    check_keystore(s, 0);
    FAIL() << "an empty enclave folder passed";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()).rfind("security: " + s.enclave_dir() +
                                              "/identity_ca.cert.pem: missing",
                                          0),
              0u)
        << e.what();
  }
  SecurityConfig off;
  EXPECT_NO_THROW(check_keystore(off, 0)) << "security off checks nothing";
}

TEST_F(Keystore, CycloneGetsThePluginsAndTheEnclaveFiles) {
  EXPECT_TRUE(security_properties(SecurityConfig{}).empty());
  const SecurityConfig s{true, root.string(), "/pedalwave/alice"};
  std::map<std::string, std::string> p;
  for (const auto& [k, v] : security_properties(s)) p[k] = v;
  EXPECT_EQ(p["dds.sec.auth.identity_certificate"], "file:" + s.enclave_dir() + "/cert.pem");
  EXPECT_EQ(p["dds.sec.auth.private_key"], "file:" + s.enclave_dir() + "/key.pem");
  EXPECT_EQ(p["dds.sec.auth.identity_ca"], "file:" + s.enclave_dir() + "/identity_ca.cert.pem");
  EXPECT_EQ(p["dds.sec.access.permissions_ca"],
            "file:" + s.enclave_dir() + "/permissions_ca.cert.pem");
  EXPECT_EQ(p["dds.sec.access.governance"], "file:" + s.enclave_dir() + "/governance.p7s");
  EXPECT_EQ(p["dds.sec.access.permissions"], "file:" + s.enclave_dir() + "/permissions.p7s");
  EXPECT_EQ(p["dds.sec.auth.library.init"], "init_authentication");
  EXPECT_EQ(p["dds.sec.access.library.init"], "init_access_control");
  EXPECT_EQ(p["dds.sec.crypto.library.init"], "init_crypto");
  for (const char* k : {"dds.sec.auth.library.path", "dds.sec.access.library.path",
                        "dds.sec.crypto.library.path"}) {
    EXPECT_FALSE(p[k].empty()) << k;
  }
}

// The OpenSSL checks on real files (keystore.sh, openssl): a good enclave passes, an expired one
// and permissions for another domain are refused naming the file (the daemon's refusals end to
// end: security_test.sh).
TEST_F(Keystore, RealEnclavesFromTheKeystoreTool) {
  if (std::system("command -v openssl >/dev/null 2>&1") != 0) GTEST_SKIP() << "SKIPPED: no openssl";
  const std::string ks = (root / "ks").string();
  const std::string tool = PEDALWAVE_KEYSTORE_SH;
  const std::string cmd = "'" + tool + "' init '" + ks + "' >/dev/null && '" + tool + "' robot '" +
                          ks + "' snake1 --domain 7 >/dev/null && '" + tool + "' robot '" + ks +
                          "' snake1 --enclave /old --days -1 --domain 7 >/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const SecurityConfig good{true, ks, "/pedalwave/snake1"};
  EXPECT_NO_THROW(check_keystore(good, 7));
  EXPECT_NE(describe_security(good).find("DDS Security ON: enclave /pedalwave/snake1 (CN=/pedalwave/snake1"),
            std::string::npos)
      << describe_security(good);
  const auto error = [](const SecurityConfig& s, std::uint32_t d) -> std::string {
    try {
      check_keystore(s, d);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "(no error)";
  };
  EXPECT_EQ(error(good, 8).rfind("security: " + good.enclave_dir() +
                                     "/permissions.p7s: grant for CN=/pedalwave/snake1 allows no "
                                     "topic on DDS domain 8 (it is for domain 7)",
                                 0),
            0u)
      << error(good, 8);
  const SecurityConfig old{true, ks, "/old"};
  EXPECT_EQ(error(old, 7).rfind("security: " + old.enclave_dir() + "/cert.pem: certificate expired on ", 0), 0u)
      << error(old, 7);
}
