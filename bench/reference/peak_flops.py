#!/usr/bin/env python3
"""Double-precision peak of one core: the nominal figure and a practical one from a numpy matmul.

Nominal: clock × flops per cycle, with 16 double-precision flops per cycle for AVX2 FMA code
(two FMA pipes × 4 lanes × 2 flops) and 32 where the core has two full-width 512-bit FMA pipes
and the code uses AVX-512. The clock used is the one the processor reports (`cpu MHz` of
/proc/cpuinfo, `--ghz` to override): on a virtual machine that is the nominal (TSC) frequency,
and the core may run faster under boost, which a practical figure above the nominal one shows.

Practical: the best of several C = A·B products of n × n doubles (2n³ flops) on one thread
(OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=1 are set before numpy loads), with the BLAS kernel
family that numpy's OpenBLAS picked for this processor.

Usage: python3 peak_flops.py [--n 4096] [--repeats 5] [--ghz 2.6]
"""

import argparse
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import numpy as np


def cpuinfo():
    """Model name, family, model, reported MHz and the SIMD flags of the first CPU."""
    info = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if not line.strip():
                    break
                key, _, value = line.partition(":")
                info[key.strip()] = value.strip()
    except OSError:
        pass
    flags = set(info.get("flags", "").split())
    return {
        "model": info.get("model name", "unknown"),
        "family": info.get("cpu family", "?"),
        "model_number": info.get("model", "?"),
        "mhz": float(info["cpu MHz"]) if "cpu MHz" in info else None,
        "avx2_fma": {"avx2", "fma"} <= flags,
        "avx512f": "avx512f" in flags,
    }


def blas_kernel():
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "unknown (threadpoolctl not installed)"
    for lib in threadpool_info():
        if lib.get("internal_api") == "openblas":
            return f"OpenBLAS {lib.get('version')}, kernel {lib.get('architecture')}, {lib.get('num_threads')} thread(s)"
    return "not OpenBLAS"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=4096, help="matrix size")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--ghz", type=float, help="clock for the nominal peak (default: cpu MHz)")
    args = parser.parse_args(argv)
    if args.n < 64 or args.repeats < 1:
        parser.error("--n must be at least 64 and --repeats at least 1")

    cpu = cpuinfo()
    ghz = args.ghz if args.ghz else (cpu["mhz"] / 1000 if cpu["mhz"] else None)
    print(
        f"CPU: {cpu['model']} (family {cpu['family']}, model {cpu['model_number']}); "
        f"AVX2+FMA: {cpu['avx2_fma']}, AVX-512F: {cpu['avx512f']}"
    )
    if ghz:
        print(
            f"nominal peak per core at {ghz:.3f} GHz: AVX2 FMA (16 flops/cycle) "
            f"{16 * ghz:.1f} GFLOP/s; two 512-bit FMA pipes (32 flops/cycle) {32 * ghz:.1f} GFLOP/s"
        )
    print(f"BLAS: {blas_kernel()}; numpy {np.__version__}")

    rng = np.random.default_rng(1)
    a = rng.standard_normal((args.n, args.n))
    b = rng.standard_normal((args.n, args.n))
    c = np.empty_like(a)
    np.matmul(a, b, out=c)  # warm-up: pages, caches, the BLAS's buffers
    best = float("inf")
    rates = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        np.matmul(a, b, out=c)
        wall = time.perf_counter() - start
        best = min(best, wall)
        rates.append(2 * args.n**3 / wall / 1e9)
    practical = 2 * args.n**3 / best / 1e9
    print(
        f"matmul {args.n}×{args.n}, one thread: best {practical:.1f} GFLOP/s "
        f"(all: {', '.join(f'{r:.1f}' for r in rates)})"
    )
    if ghz:
        print(
            f"practical peak = {practical / (16 * ghz):.2f} × the AVX2 FMA nominal peak, "
            f"{practical / ghz:.1f} flops per nominal cycle"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
