#!/usr/bin/env bash
# Builds the SocketCAN test VM from Debian packages only:
#   - Debian's own kernel (the linux-image-<ver>-amd64 that linux-image-amd64 depends on), unpacked,
#     depmod'ed, with its uncompressed ELF vmlinux extracted (boots ~2x faster under TCG);
#   - an initramfs (cpio newc + gzip) holding busybox-static, the CAN modules (can, can-raw,
#     can-dev, vcan, ...), the virtio/9p modules for sharing host folders, and the can-utils
#     binaries with the libraries they need; /init is written by this script (see init_script).
#
# Usage: tools/scripts/vm/build.sh            (output under build/vm/, or $VM_DIR)
# Environment:
#   VM_DIR         cache/output folder (default <repo>/build/vm)
#   VM_KERNEL_PKG  kernel package to use (default: what linux-image-amd64 depends on)
#   VM_NO_INSTALL  1 = never call apt-get install (fail/skip if something is missing)
#
# Caching: the kernel is unpacked once per kernel version (build/vm/kernel/<ver>/); the initramfs
# is rebuilt only when its inputs change (kernel version, this script, busybox and can-utils
# package versions). A re-run with nothing changed takes well under a second.
# On success writes build/vm/vm.env (KVER, KERNEL, INITRD) for run.sh.
#
# Exit status: 0 built (or up to date); 77 the needed Debian packages cannot be obtained (no apt,
# no network to Debian): the caller must report a SKIP, never a pass; 1 any other failure.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../../.." && pwd)
VM_DIR=${VM_DIR:-$root/build/vm}
self="$here/build.sh"

log() { echo "[vm-build] $*"; }
die() { echo "[vm-build] ERROR: $*" >&2; exit 1; }
skip() {
  {
    echo "################################################################################"
    echo "### SKIPPED: SocketCAN VM cannot be built: $*"
    echo "################################################################################"
  } >&2
  exit 77
}

t_start=$(date +%s.%N)
if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; else SUDO=; fi

mkdir -p "$VM_DIR" || die "cannot create $VM_DIR"
# One build at a time per VM_DIR (several engineers or CI jobs may call this at once).
exec 9>"$VM_DIR/.lock"
if ! flock -n 9; then
  log "another build.sh is working in $VM_DIR; waiting for it"
  flock 9 || die "cannot lock $VM_DIR/.lock"
fi

# ---- 1. host packages ----------------------------------------------------------------------------
pkgs=(qemu-system-x86 busybox-static can-utils kmod cpio xz-utils)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  [ "${VM_NO_INSTALL:-0}" = 1 ] && skip "missing packages ${missing[*]} (VM_NO_INSTALL=1)"
  command -v apt-get >/dev/null || skip "missing packages ${missing[*]} and no apt-get"
  log "installing: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq || skip "apt-get update failed (no access to Debian mirrors?)"
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null ||
    skip "apt-get install ${missing[*]} failed"
fi
command -v qemu-system-x86_64 >/dev/null || skip "qemu-system-x86_64 not found after install"
for tool in busybox depmod modprobe cpio xz gzip ldd; do
  command -v "$tool" >/dev/null || die "'$tool' not found on PATH although its package is installed"
done
busybox_bin=$(command -v busybox)
file_is_static() { ! ldd "$1" >/dev/null 2>&1; }
file_is_static "$busybox_bin" || die "$busybox_bin is not static (need the busybox-static package)"

# ---- 2. which kernel -----------------------------------------------------------------------------
mkdir -p "$VM_DIR/kernel"
resolve_kernel_pkg() {
  apt-cache depends linux-image-amd64 2>/dev/null |
    sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n1
}
# apt-cache costs ~1.5 s of CPU: remember its answer until the apt lists change.
lists_stamp() { stat -c '%Y %n' /var/lib/apt/lists /var/lib/apt/lists/*Packages* 2>/dev/null | sort -n | tail -n1; }
kpkg=${VM_KERNEL_PKG:-}
if [ -z "$kpkg" ] && [ -f "$VM_DIR/kernel-pkg" ] &&
   [ "$(sed -n 2p "$VM_DIR/kernel-pkg")" = "$(lists_stamp)" ]; then
  kpkg=$(sed -n 1p "$VM_DIR/kernel-pkg")
fi
if [ -z "$kpkg" ]; then
  kpkg=$(resolve_kernel_pkg || true)
  [ -n "$kpkg" ] && printf '%s\n%s\n' "$kpkg" "$(lists_stamp)" >"$VM_DIR/kernel-pkg"
  if [ -z "$kpkg" ] && [ "${VM_NO_INSTALL:-0}" != 1 ]; then
    log "apt lists do not know linux-image-amd64; running apt-get update"
    $SUDO apt-get update -qq || true
    kpkg=$(resolve_kernel_pkg || true)
  fi
  if [ -z "$kpkg" ]; then
    # Offline: fall back to the newest kernel already unpacked in the cache.
    cached=$(ls -1 "$VM_DIR/kernel" 2>/dev/null | sort -V | tail -n1 || true)
    [ -n "$cached" ] || skip "cannot resolve linux-image-amd64 (apt-cache depends gave nothing) and no kernel is cached in $VM_DIR/kernel"
    kpkg="linux-image-$cached"
    log "apt cannot resolve linux-image-amd64; using the cached kernel $cached"
  fi
fi
kver=${kpkg#linux-image-}
[[ "$kver" =~ ^[0-9]+\.[0-9]+ ]] || die "kernel package name '$kpkg' does not look like linux-image-<version>"
kdir="$VM_DIR/kernel/$kver"
kroot="$kdir/root"

# ---- 3. unpack the kernel (once per version) -----------------------------------------------------
if [ ! -f "$kdir/.done" ]; then
  log "fetching $kpkg"
  rm -rf "$kdir"; mkdir -p "$kdir"
  (cd "$kdir" && chmod 755 "$kdir"; apt-get download -qq "$kpkg" >/dev/null 2>"$kdir/download.err") || {
    cat "$kdir/download.err" >&2
    skip "apt-get download $kpkg failed"
  }
  deb=$(ls "$kdir"/linux-image-*.deb 2>/dev/null | head -n1)
  [ -n "$deb" ] || die "apt-get download $kpkg produced no .deb in $kdir"
  log "unpacking $(basename "$deb")"
  dpkg-deb -x "$deb" "$kroot" || die "dpkg-deb -x $deb failed"
  vmlinuz="$kroot/boot/vmlinuz-$kver"
  [ -f "$vmlinuz" ] || die "$vmlinuz missing from $deb"
  [ -d "$kroot/lib/modules/$kver" ] || die "$kroot/lib/modules/$kver missing from $deb"
  depmod -b "$kroot" "$kver" || die "depmod -b $kroot $kver failed"

  # The uncompressed ELF vmlinux boots much faster under TCG than the bzImage (no decompression
  # by emulated code). Find the compressed payload inside the bzImage and decompress it.
  extract_vmlinux() {
    local magic=$1 cmd=$2 off
    for off in $(LC_ALL=C grep -obUaP "$magic" "$vmlinuz" 2>/dev/null | cut -d: -f1); do
      if tail -c +"$((off + 1))" "$vmlinuz" | $cmd >"$kdir/vmlinux.tmp" 2>/dev/null ||
         [ -s "$kdir/vmlinux.tmp" ]; then
        if [ "$(head -c 4 "$kdir/vmlinux.tmp" | od -An -tx1 | tr -d ' \n')" = 7f454c46 ]; then
          mv "$kdir/vmlinux.tmp" "$kdir/vmlinux"; return 0
        fi
      fi
    done
    rm -f "$kdir/vmlinux.tmp"; return 1
  }
  extract_vmlinux '\xFD\x37\x7A\x58\x5A\x00' 'xz -dc --single-stream' ||
  extract_vmlinux '\x1F\x8B\x08' 'gzip -dc' ||
  extract_vmlinux '\x28\xB5\x2F\xFD' 'zstd -dc' ||
    log "WARNING: could not extract an ELF vmlinux from $vmlinuz; booting the bzImage (slower)"
  rm -f "$deb"   # ~60 MB; the unpacked tree is what we use
  touch "$kdir/.done"
  log "kernel $kver ready"
fi
kernel="$kdir/vmlinux"; [ -f "$kernel" ] || kernel="$kroot/boot/vmlinuz-$kver"

# ---- 4. initramfs ---------------------------------------------------------------------------------
# Modules to load at boot, in this order (dependencies are resolved by modprobe below).
want_modules=(virtio_pci 9pnet_virtio 9p can can_raw can_bcm can_gw can_isotp can_dev vcan vxcan)

init_script() {
  cat <<'EOF'
#!/bin/busybox sh
# pedalwave SocketCAN test VM init (generated by tools/scripts/vm/build.sh).
# Mounts the control share (tag vmctl) at /vmctl, builds /newroot from the host shares listed in
# /vmctl/shares and /vmctl/links, creates vcan0/vcan1, runs /vmctl/job.sh in a chroot, writes
# /vmctl/output.log, /vmctl/times and finally /vmctl/exit, then powers off.
export PATH=/sbin:/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
exec </dev/console >/dev/console 2>&1
say() { echo "[vm-init] $*"; }
fail() { say "FATAL: $*"; [ -d /vmctl ] && echo "init: $*" >/vmctl/init-error; sync; poweroff -f; }
kver=$(uname -r)
while read -r m; do
  case "$m" in
    builtin*|"") ;;
    *) insmod "/lib/modules/$kver/$m" 2>/dev/null || grep -q "^$(basename "${m%%.ko*}" | tr - _) " /proc/modules || say "insmod $m failed" ;;
  esac
done </etc/vm-modules
msize=512000
mkdir -p /vmctl
mount -t 9p -o trans=virtio,version=9p2000.L,msize=$msize vmctl /vmctl || fail "cannot mount the vmctl share"
ip link set lo up
for dev in vcan0 vcan1; do
  # MTU 72 = CANFD_MTU: CAN FD capable (vcan's default, set explicitly all the same)
  ip link add dev $dev type vcan && ip link set $dev mtu 72 up || say "cannot create $dev"
done
case " $(cat /proc/cmdline) " in *" vm.shell=1 "*) shell=1 ;; *) shell=0 ;; esac
rwcache=none
for arg in $(cat /proc/cmdline); do
  case "$arg" in vm.rwcache=*) rwcache=${arg#vm.rwcache=} ;; esac
done
R=/newroot
mkdir -p $R/proc $R/sys $R/dev $R/tmp $R/run $R/vmctl $R/root $R/vmtools/bin
mount -t proc proc $R/proc
mount -t sysfs sysfs $R/sys
mount -t devtmpfs devtmpfs $R/dev
mkdir -p $R/dev/pts $R/dev/shm
mount -t devpts devpts $R/dev/pts
mount -t tmpfs -o mode=1777 tmpfs $R/dev/shm
mount -t tmpfs -o mode=1777 tmpfs $R/tmp
mount -t tmpfs tmpfs $R/run
mount -o bind /vmctl $R/vmctl
# shares: one line per share: "<tag> <ro|rw> <absolute path>" (path last: it may hold spaces)
while read -r tag mode path; do
  [ -n "$tag" ] || continue
  opts=trans=virtio,version=9p2000.L,msize=$msize
  # ro: the host does not change these during a run, so cache them (exec of host binaries and
  # libraries is several times faster). rw: cache mode from the kernel command line (vm.rwcache).
  if [ "$mode" = ro ]; then opts=$opts,ro,cache=loose; else opts=$opts,cache=$rwcache; fi
  mkdir -p "$R$path"
  mount -t 9p -o "$opts" "$tag" "$R$path" || fail "cannot mount share $tag at $path"
done </vmctl/shares
# links: "<name> <target>", e.g. "bin usr/bin" for a merged-/usr host
while read -r name target; do
  [ -n "$name" ] && ln -sfn "$target" "$R/$name"
done </vmctl/links
cp -a /vmtools/bin/. $R/vmtools/bin/
if [ "$shell" = 1 ]; then
  say "debug shell (host root in $R; exit to power off)"
  setsid cttyhack sh
  sync; poweroff -f
fi
t0=$(cut -d' ' -f1 /proc/uptime)
{
  # busybox's env and chroot: only bash itself is loaded from the host's /usr.
  env -i HOME=/root TERM=dumb LANG=C.UTF-8 \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin:/vmtools/bin \
    PEDALWAVE_IN_VM=1 PEDALWAVE_REQUIRE_VCAN=1 chroot $R /bin/bash /vmctl/job.sh
  echo $? >/vmctl/rc
} 2>&1 | tee /vmctl/output.log
t1=$(cut -d' ' -f1 /proc/uptime)
echo "boot_s=$t0 job_s=$t1" >/vmctl/times
sync
mv /vmctl/rc /vmctl/exit
sync
poweroff -f
EOF
}

key=$( {
  echo "kver=$kver"
  dpkg-query -W -f='${Package}=${Version}\n' busybox-static can-utils
  echo "modules=${want_modules[*]}"
  cat "$self"
} | sha256sum | cut -c1-16)
initrd="$VM_DIR/initrd-$kver.cpio.gz"
if [ ! -f "$initrd" ] || [ "$(cat "$initrd.key" 2>/dev/null)" != "$key" ]; then
  log "building initramfs for $kver"
  ir="$VM_DIR/initramfs.tmp"
  rm -rf "$ir"
  mkdir -p "$ir"/{bin,sbin,etc,proc,sys,dev,tmp,newroot,vmtools/bin,"lib/modules/$kver"}
  cp "$busybox_bin" "$ir/bin/busybox"
  # Applet links. `busybox --list` names "busybox" itself: linking that over the binary makes a
  # symlink loop ("Failed to execute /init (error -40)").
  for a in $("$busybox_bin" --list); do
    [ "$a" = busybox ] || ln -sf busybox "$ir/bin/$a"
  done
  for a in modprobe insmod rmmod lsmod ip poweroff reboot halt init; do
    ln -sf ../bin/busybox "$ir/sbin/$a"
  done

  # Modules with their dependencies, in load order.
  : >"$ir/etc/vm-modules"
  for m in "${want_modules[@]}"; do
    out=$(modprobe -d "$kroot" -S "$kver" --show-depends "$m" 2>&1) ||
      die "module '$m' not found in kernel $kver: $out"
    while read -r verb path _; do
      case "$verb" in
        builtin) echo "builtin $path" >>"$ir/etc/vm-modules" ;;
        insmod)
          rel=${path#"$kroot/lib/modules/$kver/"}
          dst_rel=${rel%.xz}; dst_rel=${dst_rel%.zst}
          grep -qxF "$dst_rel" "$ir/etc/vm-modules" && continue
          mkdir -p "$ir/lib/modules/$kver/$(dirname "$dst_rel")"
          case "$rel" in
            *.xz) xz -dc "$path" >"$ir/lib/modules/$kver/$dst_rel" ;;
            *.zst) zstd -qdc "$path" >"$ir/lib/modules/$kver/$dst_rel" ;;
            *) cp "$path" "$ir/lib/modules/$kver/$dst_rel" ;;
          esac
          echo "$dst_rel" >>"$ir/etc/vm-modules" ;;
        *) die "unexpected modprobe --show-depends line for $m: $verb $path" ;;
      esac
    done <<<"$out"
  done
  cp "$kroot/lib/modules/$kver/modules.order" "$kroot/lib/modules/$kver/modules.builtin" \
     "$kroot/lib/modules/$kver/modules.builtin.modinfo" \
     "$ir/lib/modules/$kver/" 2>/dev/null || true
  depmod -b "$ir" "$kver" || die "depmod on the initramfs tree failed"

  # can-utils with the libraries ldd names (for a shell in the VM without the host's /usr; in the
  # test chroot they are also on PATH as /vmtools/bin, after the host's own).
  copy_lib() {
    local lib=$1
    [ -e "$ir$lib" ] && return 0
    mkdir -p "$ir$(dirname "$lib")"
    cp -L "$lib" "$ir$lib"
  }
  for b in $(dpkg -L can-utils | grep -E '^/usr/bin/[^/]+$'); do
    [ -x "$b" ] || continue
    cp "$b" "$ir/bin/"
    cp "$b" "$ir/vmtools/bin/"
    # ldd lines: "libc.so.6 => /lib/x86_64-linux-gnu/libc.so.6 (0x...)" or "/lib64/ld-linux... (0x...)"
    while read -r lib; do copy_lib "$lib"; done < <(ldd "$b" 2>/dev/null |
      sed -n -e 's/^.*=> \(\/[^ ]*\) (.*$/\1/p' -e 's/^[[:space:]]*\(\/[^ ]*\) (.*$/\1/p')
  done
  # The loader path is /lib64/... : make sure the path (not only the target) exists.
  [ -e "$ir/lib64/ld-linux-x86-64.so.2" ] || die "loader /lib64/ld-linux-x86-64.so.2 not copied"

  init_script >"$ir/init"
  chmod 755 "$ir/init"
  (cd "$ir" && find . -print0 | cpio --null -o -H newc --quiet | gzip -6) >"$initrd.tmp" ||
    die "cpio/gzip of the initramfs failed"
  mv "$initrd.tmp" "$initrd"
  echo "$key" >"$initrd.key"
  rm -rf "$ir"
  log "initramfs $(du -h "$initrd" | cut -f1) at $initrd"
fi

cat >"$VM_DIR/vm.env.tmp" <<EOF
KVER=$kver
KERNEL=$kernel
INITRD=$initrd
EOF
mv "$VM_DIR/vm.env.tmp" "$VM_DIR/vm.env"
t_end=$(date +%s.%N)
log "ready: kernel $kver ($(basename "$kernel")), $(awk -v a="$t_start" -v b="$t_end" 'BEGIN{printf "%.1f", b-a}') s"
