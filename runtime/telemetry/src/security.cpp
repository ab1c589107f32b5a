#include "pedalwave/telemetry/security.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <algorithm>
#include <cctype>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <memory>
#include <sstream>
#include <stdexcept>

namespace pedalwave::telemetry {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& file, const std::string& what) {
  throw std::invalid_argument("security: " + file + ": " + what);
}

std::string openssl_error() {
  const unsigned long e = ERR_get_error();
  ERR_clear_error();
  if (e == 0) return "unknown OpenSSL error";
  char buf[256];
  ERR_error_string_n(e, buf, sizeof buf);
  return buf;
}

template <class T, void (*F)(T*)>
struct Free {
  void operator()(T* p) const { F(p); }
};
using X509Ptr = std::unique_ptr<X509, Free<X509, X509_free>>;
using KeyPtr = std::unique_ptr<EVP_PKEY, Free<EVP_PKEY, EVP_PKEY_free>>;
using BioPtr = std::unique_ptr<BIO, Free<BIO, BIO_free_all>>;
using StorePtr = std::unique_ptr<X509_STORE, Free<X509_STORE, X509_STORE_free>>;
using CtxPtr = std::unique_ptr<X509_STORE_CTX, Free<X509_STORE_CTX, X509_STORE_CTX_free>>;
using Pkcs7Ptr = std::unique_ptr<PKCS7, Free<PKCS7, PKCS7_free>>;

void require_file(const fs::path& p) {
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) {
    fail(p.string(), fs::exists(p, ec) ? "not a regular file"
                                       : "missing (expected in an SROS2 enclave folder; create "
                                         "it with tools/scripts/keystore.sh)");
  }
}

X509Ptr read_cert(const fs::path& p) {
  require_file(p);
  BioPtr bio(BIO_new_file(p.c_str(), "r"));
  if (!bio) fail(p.string(), "cannot be read");
  X509Ptr c(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (!c) fail(p.string(), "not a PEM X.509 certificate (" + openssl_error() + ")");
  return c;
}

std::string name_of(const X509_NAME* n) {
  BioPtr b(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(b.get(), n, 0, XN_FLAG_RFC2253);
  char* data = nullptr;
  const long len = BIO_get_mem_data(b.get(), &data);
  return std::string(data, static_cast<std::size_t>(len));
}

std::string time_of(const ASN1_TIME* t) {
  BioPtr b(BIO_new(BIO_s_mem()));
  ASN1_TIME_print(b.get(), t);
  char* data = nullptr;
  const long len = BIO_get_mem_data(b.get(), &data);
  return std::string(data, static_cast<std::size_t>(len));
}

StorePtr store_with(const X509* ca) {
  StorePtr s(X509_STORE_new());
  X509_STORE_add_cert(s.get(), const_cast<X509*>(ca));
  return s;
}

// The signed content of an S/MIME document, verified against `ca` (what Cyclone's access
// control plugin accepts: PKCS#7 signed by the permissions CA, text/plain content).
std::string verified_content(const fs::path& p, const X509* ca, const fs::path& ca_file) {
  require_file(p);
  BioPtr in(BIO_new_file(p.c_str(), "r"));
  if (!in) fail(p.string(), "cannot be read");
  BIO* content = nullptr;
  Pkcs7Ptr p7(SMIME_read_PKCS7(in.get(), &content));
  BioPtr content_owner(content);
  ERR_clear_error();
  if (!p7 || !PKCS7_type_is_signed(p7.get())) {
    fail(p.string(),
         "not an S/MIME signed document (unsigned? sign it with `openssl smime -sign -text "
         "-signer <keystore>/public/permissions_ca.cert.pem -inkey "
         "<keystore>/private/permissions_ca.key.pem`)");
  }
  StorePtr store = store_with(ca);
  BioPtr out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store.get(), content, out.get(), PKCS7_TEXT) != 1) {
    fail(p.string(), "signature does not verify against the permissions CA " + ca_file.string() +
                         " (" + name_of(X509_get_subject_name(ca)) + "): " + openssl_error() +
                         " (signed by another CA, or altered after signing)");
  }
  char* data = nullptr;
  const long len = BIO_get_mem_data(out.get(), &data);
  return std::string(data, static_cast<std::size_t>(len));
}

// Text between <tag> and </tag> after `from` (npos-safe); `pos` moves past it.
bool next_element(const std::string& s, const std::string& tag, std::size_t& pos,
                  std::string& inner, std::size_t end = std::string::npos) {
  const std::string open = "<" + tag + ">", close = "</" + tag + ">";
  const std::size_t a = s.find(open, pos);
  if (a == std::string::npos || (end != std::string::npos && a >= end)) return false;
  const std::size_t b = s.find(close, a);
  if (b == std::string::npos) return false;
  inner = s.substr(a + open.size(), b - a - open.size());
  pos = b + close.size();
  return true;
}

std::string trim(std::string s) {
  s.erase(std::remove_if(s.begin(), s.end(), [](unsigned char c) { return std::isspace(c); }),
          s.end());
  return s;
}

// Does a <domains> block allow `id`? Returns the list it grants, for the message.
bool domains_allow(const std::string& domains, std::uint32_t id, std::string& granted) {
  bool ok = false;
  std::size_t pos = 0;
  std::string v;
  while (next_element(domains, "id", pos, v)) {
    granted += (granted.empty() ? "" : ", ") + trim(v);
    if (trim(v) == std::to_string(id)) ok = true;
  }
  pos = 0;
  while (next_element(domains, "id_range", pos, v)) {
    std::size_t p2 = 0;
    std::string lo = "0", hi = "232";
    std::string t;
    if (next_element(v, "min", p2, t)) lo = trim(t);
    p2 = 0;
    if (next_element(v, "max", p2, t)) hi = trim(t);
    granted += (granted.empty() ? "" : ", ") + lo + ".." + hi;
    try {
      if (std::stoul(lo) <= id && id <= std::stoul(hi)) ok = true;
    } catch (const std::exception&) {
    }
  }
  return ok;
}

// "2026-12-06T01:17:27" (UTC; a trailing Z or offset ignored) -> time_t; -1 if unparseable.
std::time_t parse_iso(const std::string& s) {
  std::tm tm{};
  std::istringstream is(trim(s));
  is >> std::get_time(&tm, "%Y-%m-%dT%H:%M:%S");
  if (is.fail()) return -1;
  return timegm(&tm);
}

// A distinguished name as a sorted list of "key=value" (RFC 2253 from OpenSSL lists the RDNs
// last first; a permissions document may list them first first, with or without blanks).
std::string canonical_subject(const std::string& s) {
  std::vector<std::string> parts;
  std::string cur;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '\\' && i + 1 < s.size()) {
      cur += s[i];
      cur += s[++i];
    } else if (s[i] == ',') {
      parts.push_back(trim(cur));
      cur.clear();
    } else {
      cur += s[i];
    }
  }
  parts.push_back(trim(cur));
  std::sort(parts.begin(), parts.end());
  std::string out;
  for (const auto& p : parts) out += p + ",";
  return out;
}

}  // namespace

std::string SecurityConfig::enclave_dir() const {
  return (fs::path(keystore) / "enclaves").string() + enclave;
}

SecurityChoice resolve_security(const SecurityRequest& req,
                                const std::function<const char*(const char*)>& getenv) {
  SecurityChoice c;
  auto env = [&](const char* k) -> std::string {
    const char* v = getenv(k);
    return v ? std::string(v) : std::string();
  };
  const std::string env_enable = env("ROS_SECURITY_ENABLE");
  std::string strategy = req.config_strategy;
  if (strategy.empty()) strategy = env("ROS_SECURITY_STRATEGY");
  std::string strategy_lc = strategy;
  std::transform(strategy_lc.begin(), strategy_lc.end(), strategy_lc.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  if (!strategy_lc.empty() && strategy_lc != "enforce" && strategy_lc != "permissive") {
    throw std::invalid_argument(
        std::string("security: ") +
        (req.config_strategy.empty() ? "ROS_SECURITY_STRATEGY" : "security.strategy") + " = \"" +
        strategy + "\": expected Enforce or Permissive");
  }
  const bool enforce = strategy_lc != "permissive";  // ours: Enforce unless told otherwise

  if (req.cli_keystore) {
    c.source = "--security-keystore";
  } else if (req.config_present) {
    if (!req.config_enable) {
      c.source = "off (security.enable: false)";
      return c;
    }
    c.source = "config";
  } else if (env_enable == "true") {
    c.source = "ROS_SECURITY_ENABLE=true";
  } else {
    c.source = "off";
    return c;
  }
  SecurityConfig& s = c.security;
  s.enabled = true;
  std::string keystore_item;
  if (req.cli_keystore) {
    s.keystore = *req.cli_keystore;
    keystore_item = "--security-keystore";
  } else if (!req.config_keystore.empty()) {
    s.keystore = req.config_keystore;
    keystore_item = "security.keystore";
  } else {
    s.keystore = env("ROS_SECURITY_KEYSTORE");
    keystore_item = "ROS_SECURITY_KEYSTORE";
  }
  if (req.cli_enclave) {
    s.enclave = *req.cli_enclave;
  } else if (!req.config_enclave.empty()) {
    s.enclave = req.config_enclave;
  } else if (!env("ROS_SECURITY_ENCLAVE_OVERRIDE").empty()) {
    s.enclave = env("ROS_SECURITY_ENCLAVE_OVERRIDE");
  } else {
    s.enclave = req.default_enclave;
  }
  if (s.keystore.empty()) {
    throw std::invalid_argument("security: " + keystore_item +
                                " is not set: expected the keystore folder (security is on by " +
                                c.source + ")");
  }
  if (s.enclave.empty() || s.enclave.front() != '/' || s.enclave.back() == '/' ||
      s.enclave.find("..") != std::string::npos) {
    throw std::invalid_argument(
        "security: enclave = \"" + s.enclave +
        "\": expected an enclave path such as /pedalwave/alice (security.enclave, "
        "--security-enclave or ROS_SECURITY_ENCLAVE_OVERRIDE)");
  }
  std::error_code ec;
  if (!fs::is_directory(s.enclave_dir(), ec)) {
    if (!enforce) {
      c.warning = "security: enclave folder " + s.enclave_dir() +
                  " does not exist; strategy Permissive: running WITHOUT DDS Security";
      c.security = SecurityConfig{};
      c.source = "off (Permissive, no enclave)";
      return c;
    }
    throw std::invalid_argument("security: " + s.enclave_dir() +
                                ": enclave folder missing (strategy Enforce); create it with "
                                "tools/scripts/keystore.sh");
  }
  return c;
}

void check_keystore(const SecurityConfig& s, std::uint32_t domain_id) {
  if (!s.enabled) return;
  const fs::path dir = s.enclave_dir();
  const fs::path id_ca_file = dir / "identity_ca.cert.pem";
  const fs::path perm_ca_file = dir / "permissions_ca.cert.pem";
  const fs::path cert_file = dir / "cert.pem";
  const fs::path key_file = dir / "key.pem";
  const fs::path gov_file = dir / "governance.p7s";
  const fs::path perm_file = dir / "permissions.p7s";
  const X509Ptr id_ca = read_cert(id_ca_file);
  const X509Ptr perm_ca = read_cert(perm_ca_file);
  const X509Ptr cert = read_cert(cert_file);

  if (X509_cmp_current_time(X509_get0_notAfter(cert.get())) < 0) {
    fail(cert_file.string(), "certificate expired on " + time_of(X509_get0_notAfter(cert.get())));
  }
  if (X509_cmp_current_time(X509_get0_notBefore(cert.get())) > 0) {
    fail(cert_file.string(),
         "certificate not valid before " + time_of(X509_get0_notBefore(cert.get())));
  }
  {
    StorePtr store = store_with(id_ca.get());
    CtxPtr ctx(X509_STORE_CTX_new());
    X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr);
    if (X509_verify_cert(ctx.get()) != 1) {
      const int err = X509_STORE_CTX_get_error(ctx.get());
      fail(cert_file.string(),
           "not issued by the identity CA " + id_ca_file.string() + " (" +
               name_of(X509_get_subject_name(id_ca.get())) + "): " +
               X509_verify_cert_error_string(err) + "; the certificate's issuer is " +
               name_of(X509_get_issuer_name(cert.get())));
    }
  }
  {
    require_file(key_file);
    BioPtr bio(BIO_new_file(key_file.c_str(), "r"));
    KeyPtr key(bio ? PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr) : nullptr);
    if (!key) {
      fail(key_file.string(), "not a PEM private key without password (" + openssl_error() + ")");
    }
    if (X509_check_private_key(cert.get(), key.get()) != 1) {
      ERR_clear_error();
      fail(key_file.string(), "is not the key of " + cert_file.string());
    }
  }

  const std::string gov = verified_content(gov_file, perm_ca.get(), perm_ca_file);
  {
    std::size_t pos = 0;
    std::string rule, domains, granted;
    bool ok = false;
    while (next_element(gov, "domain_rule", pos, rule)) {
      std::size_t p2 = 0;
      if (next_element(rule, "domains", p2, domains) && domains_allow(domains, domain_id, granted)) {
        ok = true;
      }
    }
    if (!ok) {
      fail(gov_file.string(), "no domain_rule for DDS domain " + std::to_string(domain_id) +
                                  " (it covers domains " + (granted.empty() ? "none" : granted) +
                                  ")");
    }
  }

  const std::string perm = verified_content(perm_file, perm_ca.get(), perm_ca_file);
  const std::string subject = name_of(X509_get_subject_name(cert.get()));
  std::size_t pos = 0;
  std::string grant;
  std::vector<std::string> subjects;
  // <grant name="..."> carries an attribute: find each by hand.
  const auto next_grant = [&] {
    const std::size_t a = perm.find("<grant", pos);
    if (a == std::string::npos) return false;
    const std::size_t body = perm.find('>', a);
    const std::size_t b = perm.find("</grant>", body);
    if (body == std::string::npos || b == std::string::npos) return false;
    grant = perm.substr(body + 1, b - body - 1);
    pos = b + 8;
    return true;
  };
  while (next_grant()) {
    std::size_t p2 = 0;
    std::string subj;
    if (!next_element(grant, "subject_name", p2, subj)) continue;
    subjects.push_back(trim(subj));
    if (canonical_subject(subj) != canonical_subject(subject)) continue;
    std::string nb, na;
    p2 = 0;
    if (next_element(grant, "not_before", p2, nb) && parse_iso(nb) > std::time(nullptr)) {
      fail(perm_file.string(), "grant for " + subject + " not valid before " + trim(nb));
    }
    p2 = 0;
    if (next_element(grant, "not_after", p2, na) && parse_iso(na) >= 0 &&
        parse_iso(na) < std::time(nullptr)) {
      fail(perm_file.string(), "grant for " + subject + " expired on " + trim(na));
    }
    std::string granted, rule;
    bool allowed = false;
    p2 = 0;
    while (next_element(grant, "allow_rule", p2, rule)) {
      std::size_t p3 = 0;
      std::string domains;
      if (next_element(rule, "domains", p3, domains) &&
          domains_allow(domains, domain_id, granted)) {
        allowed = true;
      }
    }
    if (!allowed) {
      fail(perm_file.string(), "grant for " + subject + " allows no topic on DDS domain " +
                                   std::to_string(domain_id) + " (it is for domain " +
                                   (granted.empty() ? "none" : granted) +
                                   "): permissions for another domain");
    }
    return;
  }
  std::string list;
  for (const auto& x : subjects) list += (list.empty() ? "" : ", ") + x;
  fail(perm_file.string(), "no grant for the certificate's subject " + subject + " (grants: " +
                               (list.empty() ? "none" : list) + ")");
}

std::string describe_security(const SecurityConfig& s) {
  if (!s.enabled) return "DDS Security off";
  std::string subject = "?", until = "?", protection = "?";
  try {
    const X509Ptr cert = read_cert(fs::path(s.enclave_dir()) / "cert.pem");
    subject = name_of(X509_get_subject_name(cert.get()));
    until = time_of(X509_get0_notAfter(cert.get()));
    // The signed governance carries its XML as text (openssl smime -sign -text).
    std::ifstream in(fs::path(s.enclave_dir()) / "governance.p7s");
    std::stringstream ss;
    ss << in.rdbuf();
    std::size_t pos = 0;
    std::string v;
    if (next_element(ss.str(), "data_protection_kind", pos, v)) protection = trim(v);
  } catch (const std::exception&) {
  }
  return "DDS Security ON: enclave " + s.enclave + " (" + subject + ", certificate valid until " +
         until + "), keystore " + s.keystore + ", data protection " + protection;
}

namespace {
std::string plugin(const char* name) {
  // Debian's libddsc0debian keeps the plugins outside the loader's search path.
  const std::string debian = std::string("/usr/lib/x86_64-linux-gnu/libddsc0debian/lib") + name +
                             ".so";
  std::error_code ec;
  if (fs::exists(debian, ec)) return debian;
  return name;  // Cyclone resolves lib<name>.so on the library path
}
std::string file_uri(const fs::path& p) { return "file:" + fs::absolute(p).string(); }
}  // namespace

bool security_plugins_available() {
  for (const char* n : {"dds_security_auth", "dds_security_ac", "dds_security_crypto"}) {
    std::error_code ec;
    if (!fs::exists(plugin(n), ec)) return false;
  }
  return true;
}

std::vector<std::pair<std::string, std::string>> security_properties(const SecurityConfig& s) {
  if (!s.enabled) return {};
  const fs::path dir = s.enclave_dir();
  return {
      {"dds.sec.auth.library.path", plugin("dds_security_auth")},
      {"dds.sec.auth.library.init", "init_authentication"},
      {"dds.sec.auth.library.finalize", "finalize_authentication"},
      {"dds.sec.crypto.library.path", plugin("dds_security_crypto")},
      {"dds.sec.crypto.library.init", "init_crypto"},
      {"dds.sec.crypto.library.finalize", "finalize_crypto"},
      {"dds.sec.access.library.path", plugin("dds_security_ac")},
      {"dds.sec.access.library.init", "init_access_control"},
      {"dds.sec.access.library.finalize", "finalize_access_control"},
      {"dds.sec.auth.identity_ca", file_uri(dir / "identity_ca.cert.pem")},
      {"dds.sec.auth.identity_certificate", file_uri(dir / "cert.pem")},
      {"dds.sec.auth.private_key", file_uri(dir / "key.pem")},
      {"dds.sec.access.permissions_ca", file_uri(dir / "permissions_ca.cert.pem")},
      {"dds.sec.access.governance", file_uri(dir / "governance.p7s")},
      {"dds.sec.access.permissions", file_uri(dir / "permissions.p7s")},
  };
}

}  // namespace pedalwave::telemetry
