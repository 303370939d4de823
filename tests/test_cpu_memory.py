import platform
import subprocess
import sys

import pytest

# 30 'steps' that each make and free three 40 MB tensors; prints the page faults of the last 10
PROBE = """
import resource, sys, torch
from gyrodenoise.cpu_memory import retain_freed_memory
if sys.argv[1] == "retain":
    assert retain_freed_memory()
def step():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = torch.ones(10_000_000)
    b = a * 2
    c = b + a
    del a, b, c
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
print(sum([step() for _ in range(30)][-10:]))
"""
PAGES = 40_000_000 // 4096  # of one 40 MB tensor


def _faults_of_last_steps(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's (Linux with glibc only)")
def test_retained_memory_is_reused_without_page_faults():
    assert _faults_of_last_steps("default") > 20 * PAGES  # glibc maps every 40 MB block afresh: 3 per step
    assert _faults_of_last_steps("retain") < 5 * PAGES  # served from the kept heap once it has grown
