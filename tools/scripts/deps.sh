#!/usr/bin/env bash
# Installs (as root, from Debian 12 packages) what pedalwave needs to build, test and run.
# Skips apt entirely when everything is already there, so repeated runs are fast.
set -euo pipefail
pkgs=(cmake ninja-build g++ clang libeigen3-dev libspdlog-dev libfmt-dev libyaml-cpp-dev libcli11-dev
      libgtest-dev libgmock-dev libbenchmark-dev cyclonedds-dev cyclonedds-tools rt-tests
      can-utils libclang-rt-14-dev
      libzstd-dev liblz4-dev pkg-config  # pedalwave::mcap (MCAP chunk compression)
      slurm-wlm munge  # the campaign layer's Slurm tests (tests/tools/campaign: a one-node cluster)
      dpkg-dev file adduser systemd)  # the Debian package: dpkg-shlibdeps, CPack's ELF check,
                                      # the service user, systemd-analyze verify of the unit
# ROS 2 .msg -> IDL at build time (rosidl_adapter needs empy and lark), and the cross-host
# telemetry test's network namespaces (ip netns, veth).
pkgs+=(python3-rosidl rosidl-tools python3-empy python3-lark iproute2)
# The Foxglove WebSocket server of pedalwave_monitor --foxglove (WebSocket, its JSON messages).
pkgs+=(libwebsockets-dev nlohmann-json3-dev)
# DDS Security: the keystore checks (libssl-dev) and tools/scripts/keystore.sh (openssl); the
# Cyclone security plugins come with libddsc0debian.
pkgs+=(libssl-dev openssl)
# The sros2 interop test (tests/runtime/telemetry/sros2): sros2's keystore API runs on these.
pkgs+=(python3-cryptography python3-lxml)
# pedalwave_identify: NLopt's derivative-free optimizers (BOBYQA, Subplex).
pkgs+=(libnlopt-dev)
# The README's picture of the CMake targets (tools/scripts/targets-graph.sh).
pkgs+=(graphviz)
# The npm test peers (official readers/clients: @mcap/core, Foxglove's ws-protocol, …): node and
# npm from Debian, unless a node with npm is already on PATH (e.g. NodeSource's nodejs, which
# bundles npm and conflicts with Debian's npm package).
command -v npm >/dev/null 2>&1 && command -v node >/dev/null 2>&1 || pkgs+=(nodejs npm)
# The tools' figures: tools/figures/*.py run by /usr/bin/python3 with matplotlib.
pkgs+=(python3-matplotlib python3-numpy)
pkgs+=("$@")
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "[deps] installing: ${missing[*]}"
  if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; else SUDO=; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
echo "[deps] all present"
