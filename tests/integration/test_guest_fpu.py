"""The test bus itself: guest tasks keep their AVX-512 registers.

On a host whose XSAVE area is larger than UML's buffer (AVX-512 with AMX:
11008 bytes against UML's 2696), UML 6.1 could not start a process at all;
tests/vm/uml_xstate.c, preloaded into every guest by run-in-vm, now passes
every FPU state UML saves and restores through a whole-area read and write.
If it mangled what it passes on, a program's vector registers would change
under it between two instructions: glibc's string functions use zmm16-31 on
such CPUs. tests/vm/fpu_check.c runs four threads of one process with their
own zmm31 and k7 while UML switches between them and timer ticks interrupt
them, and reads them back. (Checked against a shim that zeroes the AVX-512
part of what it passes on: every thread lost both.) Where the host runs the
suite without a guest, it checks the host kernel instead.
"""
import subprocess

import pytest

from harness import BUILD

FPU_CHECK = BUILD / "vm-shim" / "fpu_check"


@pytest.mark.live_s(4)
def test_tasks_keep_their_avx512_registers():
    assert FPU_CHECK.exists(), f"{FPU_CHECK} missing: build it with make"
    run = subprocess.run([str(FPU_CHECK), "3"], capture_output=True, text=True, timeout=60)
    if run.returncode == 77:
        pytest.skip("this CPU has no AVX-512F: nothing beyond what UML knows to keep")
    assert run.returncode == 0, f"fpu_check: exit {run.returncode}\n{run.stdout}{run.stderr}"
    lines = run.stdout.splitlines()
    assert lines[-1] == "bad=0", run.stdout
    kept = [ln for ln in lines if ln.startswith("thread ") and ln.endswith("zmm31 kept, k7 kept")]
    assert len(kept) == 4, run.stdout
