import platform
import subprocess
import sys

import pytest

# a 40 MB tensor made, touched and freed twice; prints the page faults of the second time
PROBE = """
import resource, sys, torch
from gyrodenoise.cpu_memory import retain_freed_memory
if sys.argv[1] == "retain":
    assert retain_freed_memory()
def faults_of_a_fresh_tensor():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    torch.ones(10_000_000)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
faults_of_a_fresh_tensor()
print(faults_of_a_fresh_tensor())
"""


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's (Linux with glibc only)")
def test_retained_memory_is_reused_without_page_faults():
    pages = 40_000_000 // 4096
    assert _faults("default") > pages // 2  # glibc maps a 40 MB block afresh each time
    assert _faults("retain") < pages // 20  # kept in the heap: no new pages
