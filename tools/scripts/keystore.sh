#!/usr/bin/env bash
# keystore.sh: creates a DDS Security keystore for pedalwave robots, operators and monitors, with
# Debian's openssl only. Layout and documents follow SROS2 (`ros2 security create_keystore` /
# `create_enclave`), so a ROS 2 node started with ROS_SECURITY_KEYSTORE=<keystore> and
# ROS_SECURITY_ENCLAVE_OVERRIDE=<enclave> finds the files it expects (the permissions grant
# pedalwave's topics only; see the table below):
#
#   <keystore>/public/ca.cert.pem                  the CA (identity CA = permissions CA, as SROS2)
#   <keystore>/public/identity_ca.cert.pem         -> ca.cert.pem
#   <keystore>/public/permissions_ca.cert.pem      -> ca.cert.pem
#   <keystore>/private/ca.key.pem                  the CA's key (keep it OFF the robot)
#   <keystore>/private/{identity,permissions}_ca.key.pem -> ca.key.pem
#   <keystore>/enclaves/governance.xml, governance.p7s   (S/MIME signed by the permissions CA)
#   <keystore>/enclaves/<enclave>/cert.pem, key.pem      the identity (CN=<enclave>)
#   <keystore>/enclaves/<enclave>/permissions.xml, permissions.p7s
#   <keystore>/enclaves/<enclave>/{governance.p7s,identity_ca.cert.pem,permissions_ca.cert.pem}
#                                                        -> the shared ones
#
# Usage:
#   keystore.sh init     <keystore> [--protection ENCRYPT|SIGN|NONE] [--days N]
#   keystore.sh robot    <keystore> <robot name> [--enclave E] [--namespace NS] [common options]
#   keystore.sh operator <keystore> <enclave> [common options]   publish commands and e-stop
#   keystore.sh estop    <keystore> <enclave> [common options]   publish e-stop only
#   keystore.sh monitor  <keystore> <enclave> [common options]   subscribe only
#   common options: --domain N (default 0; the permissions grant that domain only)
#                   --days N (certificate and permissions validity, default 3650)
#                   --ca-dir DIR (sign with another keystore's CA: a wrong-CA identity, for tests)
#
# Permissions (DDS topic names; ROS name = DDS name without the leading "rt"):
#   robot <name>: publish rt<ns>/* (its telemetry), rt/diagnostics, rt/tf,
#                 rt/pedalwave/command_ack; subscribe rt/pedalwave/command,
#                 rt/pedalwave/emergency_stop. <ns> defaults to /<name> (the daemon's default).
#   operator:     publish rt/pedalwave/command, rt/pedalwave/emergency_stop; subscribe rt/*
#   estop:        publish rt/pedalwave/emergency_stop; subscribe rt/*
#   monitor:      subscribe rt/*
# Every role may also publish/subscribe ros_discovery_info (what rmw_cyclonedds's nodes use), so a
# ROS 2 tool given one of these enclaves works too. Anything else is denied (<default>DENY).
set -euo pipefail

die() { echo "keystore.sh: $*" >&2; exit 2; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 2; }

[ $# -ge 2 ] || usage
cmd=$1 ks=$2
shift 2
command -v openssl >/dev/null || die "openssl not found (apt-get install openssl)"

protection=ENCRYPT days=3650 domain=0 ca_dir="" enclave="" ns="" name=""
case "$cmd" in
  robot) [ $# -ge 1 ] || die "robot: expected a robot name"; name=$1; shift ;;
  operator|estop|monitor) [ $# -ge 1 ] || die "$cmd: expected an enclave path (e.g. /pedalwave/alice)"
    enclave=$1; shift ;;
  init) ;;
  *) usage ;;
esac
while [ $# -gt 0 ]; do
  case "$1" in
    --protection) protection=${2:?}; shift 2 ;;
    --days) days=${2:?}; shift 2 ;;
    --domain) domain=${2:?}; shift 2 ;;
    --ca-dir) ca_dir=${2:?}; shift 2 ;;
    --enclave) enclave=${2:?}; shift 2 ;;
    --namespace) ns=${2:?}; shift 2 ;;
    *) die "unknown option '$1'" ;;
  esac
done
case "$protection" in ENCRYPT|SIGN|NONE) ;; *) die "--protection $protection: expected ENCRYPT, SIGN or NONE" ;; esac
[[ "$domain" =~ ^[0-9]+$ ]] && [ "$domain" -le 230 ] || die "--domain $domain: expected 0..230 (the domain ids Cyclone's access control accepts)"
[[ "$days" =~ ^-?[0-9]+$ ]] || die "--days $days: expected an integer"

# Validity as ISO 8601 (permissions) from now to now + days.
iso() { date -u -d "$1" +%Y-%m-%dT%H:%M:%S; }

if [ "$cmd" = init ]; then
  [ -e "$ks/public/ca.cert.pem" ] && die "$ks already holds a keystore (public/ca.cert.pem)"
  mkdir -p "$ks/public" "$ks/private" "$ks/enclaves"
  chmod 700 "$ks/private"
  openssl ecparam -name prime256v1 -genkey -noout -out "$ks/private/ca.key.pem" 2>/dev/null
  openssl req -new -x509 -sha256 -key "$ks/private/ca.key.pem" -out "$ks/public/ca.cert.pem" \
    -days "$days" -subj "/CN=pedalwave_ca" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature"
  ln -sf ca.cert.pem "$ks/public/identity_ca.cert.pem"
  ln -sf ca.cert.pem "$ks/public/permissions_ca.cert.pem"
  ln -sf ca.key.pem "$ks/private/identity_ca.key.pem"
  ln -sf ca.key.pem "$ks/private/permissions_ca.key.pem"
  if [ "$protection" = NONE ]; then rtps=NONE; else rtps=SIGN; fi
  cat >"$ks/enclaves/governance.xml" <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- pedalwave governance (OMG DDS Security 1.1): every participant authenticated, join and
     read/write access control on every topic, data and discovery protected by $protection. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id_range><min>0</min><max>230</max></id_range>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>$protection</discovery_protection_kind>
      <liveliness_protection_kind>$protection</liveliness_protection_kind>
      <rtps_protection_kind>$rtps</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>$protection</metadata_protection_kind>
          <data_protection_kind>$protection</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
  openssl smime -sign -text -in "$ks/enclaves/governance.xml" -out "$ks/enclaves/governance.p7s" \
    -signer "$ks/public/permissions_ca.cert.pem" -inkey "$ks/private/permissions_ca.key.pem"
  echo "keystore $ks: CA $(openssl x509 -in "$ks/public/ca.cert.pem" -noout -subject), governance $protection"
  exit 0
fi

[ -f "$ks/public/ca.cert.pem" ] && [ -f "$ks/enclaves/governance.p7s" ] ||
  die "$ks is not a keystore (no public/ca.cert.pem or enclaves/governance.p7s): run 'keystore.sh init $ks' first"
[ -n "$ca_dir" ] || ca_dir=$ks
[ -f "$ca_dir/private/ca.key.pem" ] || die "$ca_dir/private/ca.key.pem: no CA key there"

if [ "$cmd" = robot ]; then
  [[ "$name" =~ ^[A-Za-z0-9_.-]{1,63}$ ]] || die "robot name '$name': expected 1..63 of [A-Za-z0-9_.-]"
  sane=$(printf '%s' "$name" | sed 's/[^A-Za-z0-9_]/_/g; s/^\([0-9]\)/_\1/')
  [ -n "$ns" ] || ns=/$sane                       # the daemon's default namespace
  [ -n "$enclave" ] || enclave=/pedalwave/$sane   # the daemon's default enclave
fi
[[ "$enclave" =~ ^(/[A-Za-z0-9_]+)+$ ]] || die "enclave '$enclave': expected /name[/name...] of [A-Za-z0-9_]"

dir=$ks/enclaves$enclave
mkdir -p "$dir"
openssl ecparam -name prime256v1 -genkey -noout -out "$dir/key.pem" 2>/dev/null
chmod 600 "$dir/key.pem"
openssl req -new -sha256 -key "$dir/key.pem" -out "$dir/req.pem" -subj "/CN=${enclave//\//\\/}"
# Negative --days (tests): a certificate that has already expired.
if [ "$days" -lt 0 ]; then
  start=$(date -u -d "$((2 * -days)) days ago" +%Y%m%d%H%M%SZ)
  end=$(date -u -d "$((-days)) days ago" +%Y%m%d%H%M%SZ)
  not_before=$(iso "$((2 * -days)) days ago") not_after=$(iso "$((-days)) days ago")
  # `openssl x509 -req` has no -not_before in OpenSSL 3.0: use `openssl ca` in a scratch folder.
  scratch=$(mktemp -d)
  touch "$scratch/index.txt"
  cat >"$scratch/ca.cnf" <<EOF
[ca]
default_ca = c
[c]
database = $scratch/index.txt
new_certs_dir = $scratch
serial = $scratch/serial
default_md = sha256
policy = p
copy_extensions = none
[p]
commonName = supplied
EOF
  openssl rand -hex 8 >"$scratch/serial"
  openssl ca -batch -config "$scratch/ca.cnf" -cert "$ca_dir/public/ca.cert.pem" \
    -keyfile "$ca_dir/private/ca.key.pem" -in "$dir/req.pem" -out "$dir/cert.pem" \
    -startdate "$start" -enddate "$end" -notext 2>/dev/null
  rm -rf "$scratch"
else
  not_before=$(iso now) not_after=$(iso "$days days")
  openssl x509 -req -sha256 -in "$dir/req.pem" -CA "$ca_dir/public/ca.cert.pem" \
    -CAkey "$ca_dir/private/ca.key.pem" -CAcreateserial -CAserial "$dir/ca.srl" \
    -days "$days" -out "$dir/cert.pem" 2>/dev/null
  rm -f "$dir/ca.srl"
fi
rm -f "$dir/req.pem"

topics() {  # <tag> <topic>... -> <topics><topic>..</topic></topics>
  local tag=$1; shift
  printf '        <%s>\n          <topics>\n' "$tag"
  for t in "$@"; do printf '            <topic>%s</topic>\n' "$t"; done
  printf '          </topics>\n        </%s>\n' "$tag"
}
case "$cmd" in
  robot) pub=("rt$ns/*" rt/diagnostics rt/tf rt/pedalwave/command_ack ros_discovery_info)
         sub=(rt/pedalwave/command rt/pedalwave/emergency_stop ros_discovery_info) ;;
  operator) pub=(rt/pedalwave/command rt/pedalwave/emergency_stop ros_discovery_info)
            sub=("rt/*" ros_discovery_info) ;;
  estop) pub=(rt/pedalwave/emergency_stop ros_discovery_info); sub=("rt/*" ros_discovery_info) ;;
  monitor) pub=(ros_discovery_info); sub=("rt/*" ros_discovery_info) ;;
esac
{
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- pedalwave permissions: role $cmd${name:+ (robot $name, namespace $ns)} -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$enclave">
      <subject_name>CN=$enclave</subject_name>
      <validity>
        <not_before>$not_before</not_before>
        <not_after>$not_after</not_after>
      </validity>
      <allow_rule>
        <domains>
          <id>$domain</id>
        </domains>
EOF
  topics publish "${pub[@]}"
  topics subscribe "${sub[@]}"
  cat <<EOF
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
} >"$dir/permissions.xml"
openssl smime -sign -text -in "$dir/permissions.xml" -out "$dir/permissions.p7s" \
  -signer "$ca_dir/public/permissions_ca.cert.pem" -inkey "$ca_dir/private/permissions_ca.key.pem"
# Relative links into the keystore's shared files, as SROS2 makes them.
up=$(printf '%s' "$enclave" | sed 's|/[^/]*|../|g')
ln -sf "${up}governance.p7s" "$dir/governance.p7s"
ln -sf "${up}../public/identity_ca.cert.pem" "$dir/identity_ca.cert.pem"
ln -sf "${up}../public/permissions_ca.cert.pem" "$dir/permissions_ca.cert.pem"
echo "enclave $enclave ($cmd${name:+ $name}, domain $domain, until $not_after): $dir"
