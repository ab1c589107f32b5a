# npm packages as independent test peers (the official MCAP readers and writer, Foxglove's decoders
# and client): sourced by the tests that use them. The packages are installed, pinned, into a
# folder of the build tree (never the system), once per package list; a test without node/npm or
# without the registry skips loudly (ctest SKIP_RETURN_CODE 77), it does not fail.
#
#   source "$repo/tests/support/npm_peers.sh"
#   if why=$(npm_peers_node_problem); then skip "$why"; fi
#   why=$(npm_peers_install "$work" NAME pkg@version …) || skip "$why"
#
# npm_peers_node_problem: prints why node/npm cannot be used and succeeds; fails when they can.
npm_peers_node_problem() {
  if ! command -v node >/dev/null 2>&1; then
    echo "node not found (the test's independent peers are npm packages)"
    return 0
  fi
  if ! command -v npm >/dev/null 2>&1; then
    echo "npm not found (the test's independent peers are npm packages)"
    return 0
  fi
  local major
  major=$(node -p 'process.versions.node.split(".")[0]')
  if ((major < 18)); then
    echo "node $(node --version) is older than 18"
    return 0
  fi
  return 1
}

# npm_peers_install WORK NAME PKG…: the packages installed into WORK/node_modules (an ES-module
# package.json beside them), unless WORK already holds exactly this list (the stamp
# WORK/node_modules/.pedalwave-NAME-packages). On failure prints why (and the end of WORK/npm.log
# on stderr) and fails.
npm_peers_install() {
  local work=$1 name=$2
  shift 2
  mkdir -p "$work"
  local stamp="$work/node_modules/.pedalwave-$name-packages"
  if [[ -f "$stamp" && "$(cat "$stamp")" == "$*" ]]; then
    return 0
  fi
  echo '{"private": true, "type": "module"}' >"$work/package.json"
  if ! npm install --prefix "$work" --no-audit --no-fund --loglevel=error "$@" >"$work/npm.log" 2>&1; then
    tail -5 "$work/npm.log" >&2
    echo "npm install of $* failed (registry unreachable?): see $work/npm.log"
    return 1
  fi
  echo "$*" >"$stamp"
}
