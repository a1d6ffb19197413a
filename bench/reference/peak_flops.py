"""Double-precision peak of one core: the nominal figure and a practical one from a numpy matmul.

Nominal: clock × flops per cycle, with 16 double-precision flops per cycle for AVX2 FMA code
(two FMA pipes × 4 lanes × 2 flops) and 32 where the core has two full-width 512-bit FMA pipes
and the code uses AVX-512. The clock used is the one the processor reports (`cpu MHz` of
/proc/cpuinfo, `--ghz` to override): on a virtual machine that is the nominal (TSC) frequency,
and the core may run faster under boost, which a practical figure above the nominal one shows.

Clock: estimated from a chain of dependent double-precision multiplies (compiled by numba,
which comes with `particles`), whose latency is 3 cycles on recent AMD and Intel cores
(`--mul-latency` to change), timed in CPU time of the process so that other jobs on a shared
host do not stretch it: clock ≈ 3 × multiplies per CPU-second.

Practical: the best of several C = A·B products of n × n doubles (2n³ flops) on one thread
(OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=1 are set before numpy loads), with the BLAS kernel
family that numpy's OpenBLAS picked for this processor.

OpenBLAS chooses its kernels by processor; one it does not know gets an older family's kernels
(`OPENBLAS_CORETYPE=SkylakeX` forces the AVX-512 ones, which shows what 512-bit FMA adds).

Usage: python3 peak_flops.py [--n 4096] [--repeats 5] [--ghz 2.6] [--mul-latency 3]
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


def clock_ghz(mul_latency, n=400_000_000, repeats=3):
    """Effective clock from a dependent multiply chain, or None without numba."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit
    def chain(n, x, y):
        for _ in range(n):
            x = x * y  # each multiply waits for the previous one: one latency per iteration
        return x

    chain(10, 1.0, 1.0000001)  # compile
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        chain(n, 1.0, 1.0000001)
        best = min(best, time.process_time() - start)
    return n * mul_latency / best / 1e9


def blas_kernel():
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "unknown (threadpoolctl not installed)"
    # numpy's own OpenBLAS (scipy, loaded by numba, brings another one).
    site = os.path.dirname(os.path.dirname(np.__file__))
    numpy_dirs = (os.path.join(site, "numpy.libs"), os.path.dirname(np.__file__))
    for lib in threadpool_info():
        path = lib.get("filepath", "")
        if lib.get("internal_api") == "openblas" and path.startswith(numpy_dirs):
            return f"OpenBLAS {lib.get('version')}, kernel {lib.get('architecture')}, {lib.get('num_threads')} thread(s)"
    return "not OpenBLAS, or not found"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=4096, help="matrix size")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--ghz", type=float, help="clock for the nominal peak (default: cpu MHz)")
    parser.add_argument(
        "--mul-latency", type=float, default=3.0, help="cycles per dependent multiply"
    )
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
    blas = blas_kernel()  # before numba loads a second BLAS build
    measured_ghz = clock_ghz(args.mul_latency)
    if measured_ghz:
        print(
            f"clock from a dependent multiply chain ({args.mul_latency:g} cycles each): "
            f"{measured_ghz:.2f} GHz; peak per core at that clock: AVX2 FMA {16 * measured_ghz:.1f} "
            f"GFLOP/s, 512-bit FMA {32 * measured_ghz:.1f} GFLOP/s"
        )
    print(f"BLAS: {blas}; numpy {np.__version__}")

    rng = np.random.default_rng(1)
    a = rng.standard_normal((args.n, args.n))
    b = rng.standard_normal((args.n, args.n))
    c = np.empty_like(a)
    np.matmul(a, b, out=c)  # warm-up: pages, caches, the BLAS's buffers
    best, best_cpu = float("inf"), float("inf")
    rates = []
    for _ in range(args.repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        np.matmul(a, b, out=c)
        wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
        best, best_cpu = min(best, wall), min(best_cpu, cpu)
        rates.append(2 * args.n**3 / wall / 1e9)
    practical = 2 * args.n**3 / best / 1e9
    per_cpu_second = 2 * args.n**3 / best_cpu / 1e9
    print(
        f"matmul {args.n}×{args.n}, one thread: best {practical:.1f} GFLOP/s "
        f"(all: {', '.join(f'{r:.1f}' for r in rates)}); per CPU-second of the process: "
        f"{per_cpu_second:.1f} GFLOP/s (the same when the core is not shared)"
    )
    if ghz:
        print(
            f"practical peak = {practical / (16 * ghz):.2f} × the AVX2 FMA nominal peak, "
            f"{practical / ghz:.1f} flops per nominal cycle"
        )
    if measured_ghz:
        print(
            f"per CPU-second: {per_cpu_second / measured_ghz:.1f} flops per measured cycle "
            f"({per_cpu_second / (16 * measured_ghz):.2f} of AVX2 FMA, "
            f"{per_cpu_second / (32 * measured_ghz):.2f} of 512-bit FMA)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
