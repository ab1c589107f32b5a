#!/usr/bin/env bash
# Runs `ctest --output-on-failure CTEST_ARGS...` in BUILD_DIR inside the SocketCAN test VM
# (Debian's kernel under qemu, vcan0 and vcan1 up, CAN FD capable MTU 72) and exits with ctest's
# exit status.
#
# Usage: tools/scripts/vm/run.sh BUILD_DIR [CTEST_ARGS...]     (run build.sh first)
#
# The project folder, BUILD_DIR (and the source folder BUILD_DIR was configured from) are shared
# read-write over virtio-9p at the SAME absolute paths, so ctest's absolute paths work; the host's
# /usr and /etc are shared read-only so host-built test binaries, ctest and can-utils run inside
# (Debian 12 is merged-/usr: /bin, /lib, /lib64, /sbin become the same symlinks as on the host).
# Inside, the environment has PEDALWAVE_IN_VM=1 and PEDALWAVE_REQUIRE_VCAN=1 (tests that would
# skip for a missing vcan0 must fail instead), plus these host variables when set: GTEST_*,
# ASAN_OPTIONS, UBSAN_OPTIONS, TSAN_OPTIONS, LSAN_OPTIONS, CTEST_* except CTEST_PARALLEL_LEVEL
# (tests on vcan0 share one bus and see each other's frames: serial unless -j is passed).
#
# Environment:
#   VM_DIR       where build.sh put the VM (default <repo>/build/vm)
#   VM_TIMEOUT   whole boot + test + poweroff limit in seconds (default 300)
#   VM_MEM       guest memory in MiB (default 1024)
#   VM_SMP       guest CPUs (default: host CPU count, at most 4)
#   VM_MACHINE   qemu machine type (default q35: ~2 s faster boot under TCG than pc)
#   VM_APPEND    extra kernel command-line arguments (e.g. "loglevel=7" with VM_VERBOSE=1)
#   VM_ACCEL     tcg or kvm (default: kvm only if /proc/cpuinfo has vmx/svm and /dev/kvm is usable)
#   VM_VERBOSE   1 = stream the guest console (kernel messages, init, live ctest) to stdout
#   VM_SHELL     1 = interactive busybox shell instead of ctest (needs a terminal)
#   VM_JOB       a bash command to run in BUILD_DIR instead of ctest (debugging; exit status kept)
#   VM_KEEP      1 = keep the run folder (console.log, output.log) under $VM_DIR/runs/
#
# Exit status: ctest's; 77 SKIPPED (qemu or the VM missing/unusable: report a skip, never a
# pass); 124 the VM hit VM_TIMEOUT; 125 the VM died without writing an exit status.
set -uo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../../.." && pwd)
VM_DIR=${VM_DIR:-$root/build/vm}

log() { echo "[vm-run] $*"; }
die() { echo "[vm-run] ERROR: $*" >&2; exit 1; }
skip() {
  {
    echo "################################################################################"
    echo "### SKIPPED: SocketCAN VM tests not run: $*"
    echo "################################################################################"
  } >&2
  exit 77
}

[ $# -ge 1 ] || die "usage: $0 BUILD_DIR [CTEST_ARGS...]"
[ -d "$1" ] || die "build folder '$1' does not exist"
build_dir=$(cd "$1" && pwd)
shift
[ -f "$build_dir/CTestTestfile.cmake" ] || die "'$build_dir' is not a configured build folder (no CTestTestfile.cmake)"

command -v qemu-system-x86_64 >/dev/null ||
  skip "qemu-system-x86_64 is not installed (tools/scripts/vm/build.sh installs it)"
[ -f "$VM_DIR/vm.env" ] || die "no VM in $VM_DIR (run tools/scripts/vm/build.sh first)"
# shellcheck disable=SC1091
. "$VM_DIR/vm.env"
[ -f "$KERNEL" ] || die "kernel $KERNEL missing (re-run tools/scripts/vm/build.sh)"
[ -f "$INITRD" ] || die "initramfs $INITRD missing (re-run tools/scripts/vm/build.sh)"

accel=${VM_ACCEL:-}
if [ -z "$accel" ]; then
  accel=tcg
  if grep -qwE 'vmx|svm' /proc/cpuinfo && [ -r /dev/kvm ] && [ -w /dev/kvm ]; then accel=kvm; fi
fi
case "$accel" in
  kvm) cpu=host ;;
  tcg) cpu=max ;;
  *) die "VM_ACCEL must be tcg or kvm, not '$accel'" ;;
esac
# qemu usable at all? (a machine-less start that quits at once; catches a broken install)
if ! echo quit | timeout 20 qemu-system-x86_64 -accel "$accel" -machine none -nodefaults \
     -display none -monitor stdio >/dev/null 2>&1; then
  skip "qemu-system-x86_64 cannot start with -accel $accel on this machine"
fi

timeout_s=${VM_TIMEOUT:-300}
mem=${VM_MEM:-1024}
smp=${VM_SMP:-$(nproc)}
((smp > 4)) && smp=4

mkdir -p "$VM_DIR/runs"
ctl=$(mktemp -d "$VM_DIR/runs/run.XXXXXX") || die "cannot create a run folder in $VM_DIR/runs"
chmod 755 "$ctl"
cleanup() { [ "${VM_KEEP:-0}" = 1 ] || rm -rf "$ctl"; }
trap cleanup EXIT

# ---- shares ----------------------------------------------------------------------------------------
qemu_shares=()
: >"$ctl/shares"
nshare=0
add_share() {  # add_share PATH ro|rw
  local path=$1 mode=$2 tag="s$nshare" qpath
  nshare=$((nshare + 1))
  qpath=${path//,/,,}   # qemu option syntax: a literal comma is doubled
  local ro=""; [ "$mode" = ro ] && ro=",readonly=on"
  qemu_shares+=(-virtfs "local,path=$qpath,mount_tag=$tag,security_model=none,multidevs=remap$ro")
  printf '%s %s %s\n' "$tag" "$mode" "$path" >>"$ctl/shares"
}
# Folders shared read-write at their own paths: the project, the build folder and the source
# folder it was configured from; a folder inside another shared one is reached through that one.
rw=("$root" "$build_dir")
src=$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$build_dir/CMakeCache.txt" 2>/dev/null || true)
[ -n "$src" ] && [ -d "$src" ] && rw+=("$(cd "$src" && pwd -P)")
mapfile -t rw < <(printf '%s\n' "${rw[@]}" | sort -u)
for p in "${rw[@]}"; do
  inside=0
  for q in "${rw[@]}"; do
    [ "$p" != "$q" ] && [[ "$p/" == "$q/"* ]] && inside=1
  done
  [ $inside = 1 ] || add_share "$p" rw
done
# /usr is mounted first (others may live under it), then /etc.
add_share /usr ro
add_share /etc ro
: >"$ctl/links"
for d in bin sbin lib lib32 lib64 libx32; do
  if [ -L "/$d" ]; then
    printf '%s %s\n' "$d" "$(readlink "/$d")" >>"$ctl/links"
  elif [ -d "/$d" ]; then
    add_share "/$d" ro   # not a merged-/usr host
  fi
done
# /usr must come before the rw shares in the mount order only if a rw share lives under /usr.
# Mount order = file order; sort so a parent path is always mounted before its children.
LC_ALL=C sort -k3 -o "$ctl/shares" "$ctl/shares"

# ---- the job run inside (by the host's bash, in the chroot) ---------------------------------------
{
  echo '#!/bin/bash'
  echo 'set -u'
  while IFS='=' read -r name _; do
    case "$name" in
      CTEST_PARALLEL_LEVEL) ;;  # tests on vcan0 share one bus: parallelism only if asked (-j)
      GTEST_*|ASAN_OPTIONS|UBSAN_OPTIONS|TSAN_OPTIONS|LSAN_OPTIONS|CTEST_*|PEDALWAVE_VM_*)
        printf 'export %s=%q\n' "$name" "${!name}" ;;
    esac
  done < <(env)
  printf 'cd %q || exit 2\n' "$build_dir"
  # Builtins only (every exec of a host binary costs ~0.1 s under TCG over 9p).
  cat <<'EOS'
read -r up _ </proc/uptime; read -r kver </proc/sys/kernel/osrelease
echo "[vm] kernel $kver, job starts at $up s guest uptime; CAN interfaces:"
for d in /sys/class/net/*; do
  read -r type <"$d/type"; [ "$type" = 280 ] || continue
  read -r mtu <"$d/mtu"; read -r flags <"$d/flags"
  echo "[vm]   ${d##*/} mtu $mtu $( (( flags & 1 )) && echo up || echo DOWN)"
done
EOS
  if [ -n "${VM_JOB:-}" ]; then
    printf '%s\n' "$VM_JOB"
  else
    printf 'ctest --output-on-failure'; printf ' %q' "$@"; echo
  fi
} >"$ctl/job.sh"

# cryptomgr.notests: the crypto self-tests cost ~1 s of boot under TCG.
append="console=ttyS0 quiet loglevel=3 panic=-1 mitigations=off tsc=reliable cryptomgr.notests"
append="$append ${VM_APPEND:-}"
append="$append vm.rwcache=${VM_RW_CACHE:-loose}"
[ "${VM_SHELL:-0}" = 1 ] && append="$append vm.shell=1"
console=(-chardev "file,id=con,path=$ctl/console.log" -serial chardev:con)
if [ "${VM_VERBOSE:-0}" = 1 ] || [ "${VM_SHELL:-0}" = 1 ]; then
  console=(-serial stdio)
fi

log "booting $(basename "$KERNEL") $KVER ($accel, $smp CPUs, ${mem} MiB, timeout ${timeout_s} s): ctest $*"
t0=$(date +%s.%N)
timeout --kill-after=10 "$timeout_s" qemu-system-x86_64 \
  -accel "$accel" -cpu "$cpu" -smp "$smp" -m "$mem" \
  -machine "${VM_MACHINE:-q35}" ${VM_BIOS:+-bios "$VM_BIOS"} -nodefaults -display none -no-reboot -monitor none "${console[@]}" \
  -kernel "$KERNEL" -initrd "$INITRD" -append "$append" \
  -virtfs "local,path=${ctl//,/,,},mount_tag=vmctl,security_model=none" \
  "${qemu_shares[@]}" 2>"$ctl/qemu.err"
qrc=$?
t1=$(date +%s.%N)
wall=$(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.1f", b-a}')

if [ ! -f "$ctl/exit" ]; then
  [ -f "$ctl/output.log" ] && { log "---- partial test output ----"; cat "$ctl/output.log"; }
  [ -s "$ctl/qemu.err" ] && { log "---- qemu stderr ----"; cat "$ctl/qemu.err"; }
  [ -f "$ctl/init-error" ] && { log "---- init error ----"; cat "$ctl/init-error"; }
  [ -f "$ctl/console.log" ] && { log "---- last 60 console lines ----"; tail -n 60 "$ctl/console.log"; }
  if [ "$qrc" = 124 ] || [ "$qrc" = 137 ]; then
    echo "[vm-run] FAILED: the VM did not finish within ${timeout_s} s (VM_TIMEOUT); no exit status" >&2
    exit 124
  fi
  echo "[vm-run] FAILED: the VM stopped (qemu exit $qrc) after ${wall} s without writing an exit status (guest crash?)" >&2
  exit 125
fi
rc=$(cat "$ctl/exit")
[[ "$rc" =~ ^[0-9]+$ ]] || { echo "[vm-run] FAILED: garbled exit status '$rc'" >&2; exit 125; }
cat "$ctl/output.log"
boot_s=$(sed -n 's/.*boot_s=\([0-9.]*\).*/\1/p' "$ctl/times" 2>/dev/null)
job_s=$(sed -n 's/.*job_s=\([0-9.]*\).*/\1/p' "$ctl/times" 2>/dev/null)
if [ -n "$boot_s" ] && [ -n "$job_s" ]; then
  split=$(awk -v a="$boot_s" -v b="$job_s" -v w="$wall" \
    'BEGIN{printf "kernel boot %.1f s, job %.1f s, qemu start+firmware+poweroff %.1f s", a, b-a, w-b}')
else
  split="no guest times"
fi
log "exit status $rc; wall ${wall} s ($split)"
exit "$rc"
