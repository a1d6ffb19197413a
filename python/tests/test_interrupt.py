"""A run releases the GIL, and Ctrl-C (SIGINT) stops it cleanly: KeyboardInterrupt, the file it
was to write untouched, and the interpreter ready for the next run."""

import _thread
import signal
import threading
import time

import numpy as np
import pytest

import sysid_mpf as sm


@pytest.fixture(scope="module")
def long_data():
    # The whole El Centro record (3119 steps): several seconds per run at these particles.
    return sm.simulate(seed=3)


def test_ctrl_c_stops_a_run_and_leaves_the_record_file_intact(long_data, tmp_path):
    # Python's own Ctrl-C handler, as in an interactive session: a runner started in the
    # background (no job control) starts Python with SIGINT ignored, and then
    # `interrupt_main` does nothing.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    out = tmp_path / "run.json"
    first = sm.identify(sm.simulate(duration=0.5, seed=3), particles=20, seed=1, out=out)
    before = out.read_bytes()
    timer = threading.Timer(0.3, _thread.interrupt_main)
    start = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        sm.identify(long_data, algorithm="bootstrap", particles=20000, seed=1, out=out)
    elapsed = time.monotonic() - start
    timer.join()
    assert elapsed < 5.0, f"the run took {elapsed:.1f} s to stop"
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.json"]
    assert sm.read_record(out).to_json() == first.to_json()
    # The interpreter and the package work as before.
    again = sm.identify(sm.simulate(duration=0.5, seed=3), particles=20, seed=1)
    assert np.array_equal(again.theta_val, first.theta_val)


def test_a_run_releases_the_gil(long_data):
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(1)
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        sm.identify(long_data, algorithm="mln-rbpf", particles=400, seed=1)
    finally:
        done.set()
        t.join()
    assert len(ticks) > 20
