#!/bin/sh
# beaconloc: PID 1 of the User-Mode Linux guest that hosts the test bus.
#
# tests/vm/run_in_vm.py boots Debian's UML kernel (package user-mode-linux)
# with the host's own root file system over hostfs and this script as init:
#   linux.uml mem=.. root=/dev/root rootfstype=hostfs rootflags=/ rw \
#             init=tests/vm/uml-init.sh bl_job=RESULTS/job.sh con=null con0=fd:0,fd:1
# The kernel hands `bl_job=...` to init as an environment variable. The guest
# sees the host's files read-write (hostfs), so results written by the job
# land directly in the host's results folder. This script mounts what a
# minimal system needs, runs the job (tests/vm/guest-init.sh with its
# arguments, written by the host) and powers the guest off: init must never
# exit, the kernel would panic.
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
# The guest's own /run and /dev/shm. /tmp stays the host's: a results
# folder may be there (the guest's HOME is a folder of its own in it).
mount -t tmpfs -o mode=755 tmpfs /run
mount -t tmpfs -o mode=1777 tmpfs /dev/shm 2>/dev/null
mkdir -p /dev/pts && mount -t devpts -o gid=5,mode=620,ptmxmode=666 devpts /dev/pts
ip link set lo up
# Scratch space in the guest's own memory for files written while a live
# case runs: hostfs writes are done by the guest kernel's one thread, so a
# slow host disk would stall the whole guest, bus and bridge included.
mkdir -p /run/bl-scratch
export BL_SCRATCH=/run/bl-scratch
echo "uml-init: $(uname -r), job ${bl_job:-none}"
if [ -n "${bl_job:-}" ] && [ -r "$bl_job" ]; then
  sh "$bl_job"
else
  echo "uml-init: no job (bl_job=${bl_job:-})"
fi
sync
poweroff -f
