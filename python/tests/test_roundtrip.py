"""numpy in and out: arrays round-trip through the package, its directories and its records bit
for bit; the result carries every output of a run as arrays of the documented shapes."""

import numpy as np
import pytest

import sysid_mpf as sm


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.uint64)


def test_field_arrays_round_trip_through_a_directory(tmp_path):
    rng = np.random.default_rng(0)
    k = 257
    ug = rng.normal(size=k) * np.array([1e-7, 1.0, 3.3e5] * 86)[:k]
    acc = rng.normal(size=(k, 2))
    acc[3, 1] = -0.0
    acc[5, 0] = 1e-300
    d = sm.field_data(ug, acc, 0.005, [1, 3])
    assert np.array_equal(bits(d.ug), bits(ug))
    assert np.array_equal(bits(d.acc), bits(acc))
    assert d.acc.shape == (k, 2) and d.sensors == [1, 3] and len(d) == k
    assert d.building is None and d.theta_true is None and d.states is None
    # Non-contiguous and other-dtype input is converted, not refused.
    d2 = sm.field_data(ug.astype(np.float32), np.asfortranarray(acc), 0.005, [1, 3])
    assert np.array_equal(bits(d2.acc), bits(acc))
    d.write(tmp_path / "field")
    assert sorted(p.name for p in (tmp_path / "field").iterdir()) == ["measured.csv"]
    back = sm.load_dataset(tmp_path / "field")
    assert np.array_equal(bits(back.ug), bits(ug))
    assert np.array_equal(bits(back.acc), bits(acc))
    assert np.array_equal(bits(back.t), bits(d.t))
    assert back.sensors == [1, 3]
    # One channel as a 1-D array.
    one = sm.field_data(ug, acc[:, 0], 0.005, [2])
    assert one.acc.shape == (k, 1)


def test_simulated_data_round_trips_and_carries_its_truth(tmp_path):
    b = sm.Building(storeys=4, hysteretic=[1, 3], sensors=[2, 4], measurement="absolute")
    d = sm.simulate(b, duration=2.0, seed=2)
    assert d.building == {
        "storeys": 4, "masses": d.building["masses"], "hysteretic": [1, 3],
        "sensors": [2, 4], "measurement": "absolute",
    }
    assert d.acc.shape == (len(d), 2)
    assert d.states.shape == (len(d), 4 + 4 + 2)
    assert d.state_names[:2] == ["x1", "x2"] and d.state_names[-2:] == ["r1", "r3"]
    assert len(d.theta_true) == len(d.theta_names)
    d.write(tmp_path / "sim")
    back = sm.load_dataset(tmp_path / "sim")
    for name in ("t", "ug", "acc", "ug_clean", "states", "theta_true"):
        assert np.array_equal(bits(getattr(back, name)), bits(getattr(d, name))), name
    assert back.dt == d.dt and back.building == d.building
    # Writing its measurements alone would make it field data: refused by name.
    with pytest.raises(sm.SysidError, match="copy that directory"):
        back.write(tmp_path / "again")
    assert not (tmp_path / "again").exists()


def test_record_round_trips_and_has_every_output(tmp_path):
    d = sm.simulate(duration=2.0, seed=4)
    # 250 particles: two pooled filters of 125 by the recommended settings.
    r = sm.identify(d, algorithm="mpf-ekf2", particles=250, seed=2)
    p = len(r.param_names)
    assert r.theta_val.shape == r.theta_sd.shape == r.theta_true.shape == (p,)
    assert r.credible.shape == (p, 3, 3)
    assert np.array_equal(r.credible[0, :, 0], [0.5, 0.9, 0.95])
    assert np.all(r.credible[:, :, 1] <= r.credible[:, :, 2])
    n = len(r.trace_t)
    assert n > 0 and r.trace_mean.shape == r.trace_sd.shape == (n, p)
    assert r.trace_ess.shape == (n,)
    # Pooled (the recommended settings): θ_val comes with its Monte-Carlo s.e.
    assert np.all(np.isfinite(r.mc_se))
    res = r.residuals
    assert res["channels"] == ["a1", "a2", "a3"]
    # From the second step on: the first has no previous posterior to predict from.
    assert res["measured"].shape == res["predicted"].shape == (len(d) - 2, 3)
    assert res["t"][0] == 2 * d.dt
    assert r.validation["error"] is None
    # Simulated data are validated against their truth, not by a free run against the floors.
    assert r.free_run is None and r.modal is None
    assert isinstance(r.warnings, list) and r.loglik == r.to_dict()["loglik"]
    path = tmp_path / "r.json"
    r.write(path)
    back = sm.read_record(path)
    assert back.to_json() == r.to_json()
    assert np.array_equal(bits(back.theta_val), bits(r.theta_val))
    assert np.array_equal(bits(back.trace_mean), bits(r.trace_mean))
    assert sm.parse_record(r.to_json()).to_json() == r.to_json()
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_table1_is_computed():
    rows = sm.table1()
    exact = {r["nx"]: r for r in rows if r["method"] == "exact"}
    assert exact[3]["mean"] == 3 and exact[3]["variance"] == 6
    t1 = [r for r in rows if r["method"] == "T1"]
    assert all(r["mean"] == 0.0 for r in t1)
