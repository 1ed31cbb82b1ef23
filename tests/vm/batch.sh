#!/bin/sh
# batch.sh COMMAND [ARG...]: COMMAND at the lowest CPU priority, for the work
# make test does beside the vcan suite (builds, unit and Python suites).
# Started by `setsid -w` it has a session, and so a scheduler autogroup
# (/proc/sys/kernel/sched_autogroup_enabled), of its own: with autogroups a
# process's nice only ranks it inside its session, so the group's nice is set
# too. The UML guests of the suite run at nice -10 in theirs
# (tests/vm/run_in_vm.py): a guest's real-time bursts never queue behind a
# compiler; the batch work takes the CPU they leave.
echo 19 > /proc/self/autogroup 2>/dev/null || true
exec nice -n 19 "$@"
