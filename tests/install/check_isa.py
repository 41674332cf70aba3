#!/usr/bin/python3
"""Fails when an installed fastslam library has an AVX instruction outside the copies of the
random-stream kernels that the library only runs after checking the CPU (kernels_avx2,
kernels_avx512; parallel/internal/random_dispatch.h). Run by tests/install/run_install_test.cmake.

usage: check_isa.py OBJDUMP LIBRARY...

Disassembles each library and reads every instruction of every function: a VEX- or
EVEX-encoded one (mnemonic v..., the only encodings AVX, AVX2 and AVX-512 have) in any other
function would crash a CPU without AVX whenever that function runs. The qemu-user runs of the
install test only see the code a consumer executes; this sees all of it.
"""
import re
import subprocess
import sys

DISPATCHED = re.compile(r"fastslam::parallel::internal::kernels_(avx2|avx512)::")
FUNCTION = re.compile(r"^[0-9a-f]+ <(.*)>:$")
INSTRUCTION = re.compile(r"^\s+[0-9a-f]+:\s+(?:\{[a-z0-9]+\}\s+)?([a-z][a-z0-9.]*)")


def main() -> int:
    objdump, libraries = sys.argv[1], sys.argv[2:]
    failures = []
    dispatched = 0
    for library in libraries:
        text = subprocess.run([objdump, "-d", "--no-show-raw-insn", "-C", library],
                              check=True, capture_output=True, text=True).stdout
        function = None
        reported = set()
        for line in text.splitlines():
            m = FUNCTION.match(line)
            if m:
                function = m.group(1)
                continue
            m = INSTRUCTION.match(line)
            if not m or function is None or not m.group(1).startswith("v"):
                continue
            if DISPATCHED.search(function):
                dispatched += 1
            elif (library, function) not in reported:
                reported.add((library, function))
                failures.append(f"{library}: {function}: {line.strip()}")
    for failure in failures:
        print("AVX outside the dispatched kernels:", failure)
    print(f"{dispatched} AVX instructions, all in kernels_avx2 / kernels_avx512"
          if not failures else f"{len(failures)} functions with AVX outside them")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
