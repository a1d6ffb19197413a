"""The package computes what `sysid filter` computes: bit-identical θ_val and log-likelihood for
the same data, settings and seed, for every algorithm, from a data set in memory, from the same
directory, and from numpy arrays of field data."""

import json

import numpy as np
import pytest

import sysid_mpf as sm

SEED = 7
PARTICLES = 120


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.uint64).tolist()


def cli_record(sysid, tmp_path, data_dir, algorithm, *extra):
    out = tmp_path / f"{algorithm}.json"
    p = sysid(
        "filter", "--algorithm", algorithm, "--data", data_dir, "--particles", PARTICLES,
        "--seed", SEED, "--out", out, *extra, check=False,
    )
    # A run whose answer is implausible exits non-zero but still writes its record.
    assert out.is_file(), p.stderr
    return json.loads(out.read_text()), sm.read_record(out)


@pytest.mark.parametrize("algorithm", sm.ALGORITHMS)
def test_simulated_data_same_bits_as_cli(sysid, tmp_path, short_data, short_dir, algorithm):
    want, read = cli_record(sysid, tmp_path, short_dir, algorithm)
    for data in (short_data, sm.load_dataset(short_dir)):
        got = sm.identify(data, algorithm=algorithm, particles=PARTICLES, seed=SEED)
        assert got.param_names == want["param_names"]
        assert bits(got.theta_val) == bits(want["theta_val"])
        assert bits([got.loglik]) == bits([want["loglik"]])
        assert bits(got.theta_sd) == bits(want["theta_sd_final"])
        assert bits(got.trace_mean) == bits(read.trace_mean)
        # Generated data sets keep no correlation matrix (only field records' bands use one).
        assert got.theta_correlation is None and "theta_correlation" not in want
        assert got.steps_completed == want["steps_completed"] == len(short_data) - 1
        # Everything but the timings is the CLI's record.
        mine, theirs = got.to_dict(), read.to_dict()
        # Both timed the plan before the run, as the CLI does.
        assert mine["timing"]["plan_s"] >= 0.0 and theirs["timing"]["plan_s"] >= 0.0
        for r in (mine, theirs):
            r.pop("timing")
            r.pop("experiment")
            r["plan"].pop("experiment")
        assert mine == theirs


@pytest.mark.parametrize("algorithm", sm.ALGORITHMS)
def test_field_arrays_same_bits_as_cli(sysid, tmp_path, short_data, algorithm):
    # Field data: measured arrays only, the building stated by the user.
    field_dir = tmp_path / "field"
    sm.field_data(short_data.ug, short_data.acc, short_data.dt, short_data.sensors).write(field_dir)
    want, _ = cli_record(
        sysid, tmp_path, field_dir, algorithm,
        "--storeys", 3, "--hysteretic", 1, "--masses", 1, "--measurement", "relative",
    )
    loaded = sm.load_dataset(field_dir)
    assert loaded.building is None
    building = sm.Building(storeys=3, hysteretic=[1], masses=1.0, measurement="relative")
    got = sm.identify(
        loaded.ug, loaded.acc, loaded.dt, building,
        algorithm=algorithm, particles=PARTICLES, seed=SEED,
    )
    assert bits(got.theta_val) == bits(want["theta_val"])
    assert bits([got.loglik]) == bits([want["loglik"]])
    # Field data: the free run and the modes (with their shapes' MAC where peaks are paired),
    # the CLI's record's own.
    assert got.free_run == want.get("free_run")
    assert got.modal == want.get("modal")
    if algorithm == "mpf-ekf2":
        assert [c["channel"] for c in got.free_run["channels"]] == ["a1", "a2", "a3"]
        assert len(got.modal["pairs"]) == 3
    # Field data: the posterior's correlation matrix, the CLI's to the bit (a failed run has
    # none).
    if want.get("failure") is None:
        p = len(got.param_names)
        assert got.theta_correlation.shape == (p, p)
        assert bits(got.theta_correlation) == bits(want["theta_correlation"])
        assert np.all(np.diag(got.theta_correlation) == 1.0)


def test_config_file_and_dict_and_options_as_cli(sysid, tmp_path, short_dir):
    # The paper's settings by config, overridden by options, as `--config` and flags.
    cfg = tmp_path / "paper.toml"
    cfg.write_text('particles = 80\nnoise_fraction = 0.1\n[fix]\nn = 2.0\n')
    want, _ = cli_record(
        sysid, tmp_path, short_dir, "mln-rbpf", "--config", cfg, "--resampling", "residual",
        "--ess-threshold", "0.7", "--fix", "k1=9.5",
    )
    kw = dict(algorithm="mln-rbpf", particles=PARTICLES, seed=SEED, resampling="residual",
              ess_threshold=0.7, fix={"k1": 9.5})
    data = sm.load_dataset(short_dir)
    for config in (cfg, str(cfg), {"particles": 80, "noise_fraction": 0.1, "fix": {"n": 2.0}}):
        got = sm.identify(data, config=config, **kw)
        assert bits(got.theta_val) == bits(want["theta_val"])
        assert bits([got.loglik]) == bits([want["loglik"]])
    # Point-mass priors: the fixed parameters keep their values.
    theta = dict(zip(got.param_names, got.theta_val))
    assert theta["k1"] == 9.5 and theta["n"] == 2.0


def test_same_seed_same_bits_other_seed_other_bits(short_data):
    a = sm.identify(short_data, algorithm="storvik", particles=60, seed=3)
    b = sm.identify(short_data, algorithm="storvik", particles=60, seed=3)
    c = sm.identify(short_data, algorithm="storvik", particles=60, seed=4)
    da, db = a.to_dict(), b.to_dict()
    da.pop("timing"), db.pop("timing")
    assert da == db
    assert bits(a.theta_val) != bits(c.theta_val)
    s1 = sm.simulate(duration=1.0, seed=5)
    s2 = sm.simulate(duration=1.0, seed=5)
    assert bits(s1.acc) == bits(s2.acc) and bits(s1.ug) == bits(s2.ug)


def test_loglik_same_numbers_as_cli(sysid, tmp_path, short_data, short_dir):
    # `sysid loglik` and `loglik` score the same answers (a run's θ_val and the truth) with the
    # same estimates; a 40 %-low k1 is outside the record's 95 % likelihood region in both.
    _, rec = cli_record(sysid, tmp_path, short_dir, "mpf-ekf2")
    low = dict(rec.to_dict())
    i = low["param_names"].index("k1")
    low["theta_val"][i] *= 0.6
    low_path = tmp_path / "low.json"
    low_path.write_text(json.dumps(low))
    low_rec = sm.read_record(low_path)
    p = sysid(
        "loglik", "--data", short_dir, "--truth", "--particles", 60, "--seeds", 2,
        tmp_path / "mpf-ekf2.json", low_path,
    )
    cli_rows = {}
    for line in p.stdout.splitlines()[1:-1]:
        label, mean, se = line.split()[:3]
        cli_rows[label] = (mean, se)
    got = sm.loglik(
        short_data, {"run": rec, "low": low_rec}, truth=True, particles=60, seeds=2
    )
    rows = {a["label"]: a for a in got["answers"]}
    for mine, theirs in [
        ("run", str(tmp_path / "mpf-ekf2.json")),
        ("low", str(low_path)),
        ("truth", "truth"),
    ]:
        assert (f"{rows[mine]['mean']:.2f}", f"{rows[mine]['se']:.2f}") == cli_rows[theirs]
        assert len(rows[mine]["estimates"]) == 2
    assert rows["low"]["verdict"] == "outside"
    assert "OUTSIDE" in got["table"]
    assert got["params"] == len(rec.param_names)
    # Bad requests are refused by name, never run.
    with pytest.raises(sm.SysidError, match="--seeds"):
        sm.loglik(short_data, [rec], seeds=0)
    with pytest.raises(sm.SysidError, match="not a Record"):
        sm.loglik(short_data, [rec.to_dict()])
    other = sm.simulate(sm.Building(storeys=2, hysteretic=[1]), duration=1.0, seed=3)
    with pytest.raises(sm.SysidError, match="not those of the building"):
        sm.loglik(other, [rec])


def test_coloured_noise_by_config_as_cli(sysid, tmp_path, short_dir):
    # Coloured measurement noise is a settings key: a config file for the CLI, a dict here.
    cfg = tmp_path / "coloured.toml"
    cfg.write_text("noise_fraction = 0.1\n[coloured_noise]\nrho = 0.9\nshare = 0.5\n")
    want, _ = cli_record(sysid, tmp_path, short_dir, "mpf-ekf2", "--config", cfg)
    assert want["config"]["spec"]["coloured_noise"] == {"rho": 0.9, "share": 0.5}
    config = {"noise_fraction": 0.1, "coloured_noise": {"rho": 0.9, "share": 0.5}}
    data = sm.load_dataset(short_dir)
    got = sm.identify(data, algorithm="mpf-ekf2", particles=PARTICLES, seed=SEED, config=config)
    assert bits(got.theta_val) == bits(want["theta_val"])
    assert bits([got.loglik]) == bits([want["loglik"]])
    white = sm.identify(data, algorithm="mpf-ekf2", particles=PARTICLES, seed=SEED,
                        config={"noise_fraction": 0.1})
    assert bits([white.loglik]) != bits([got.loglik])
    # Only the MPF-EKF2 has a Gaussian part to carry it.
    with pytest.raises(sm.SysidError, match="coloured_noise.*MPF-EKF2"):
        sm.identify(data, algorithm="bootstrap", particles=PARTICLES, seed=SEED, config=config)


def test_learned_noise_same_bits_as_cli(sysid, tmp_path):
    # A linear building (one Gaussian filter): each channel's noise learned as `--learn-noise`
    # learns it, the same plan and numbers; a sampling run is refused by name.
    data = sm.simulate(sm.Building(hysteretic=[]), duration=3.0, seed=11)
    d = tmp_path / "linear"
    data.write(d)
    out = tmp_path / "learned.json"
    sysid("filter", "--algorithm", "mpf-ekf2", "--data", d, "--seed", SEED,
          "--learn-noise", "--out", out)
    want = json.loads(out.read_text())
    got = sm.identify(data, algorithm="mpf-ekf2", seed=SEED, learn_noise=True)
    assert bits(got.theta_val) == bits(want["theta_val"])
    assert bits([got.loglik]) == bits([want["loglik"]])
    mine = got.to_dict()
    learned = mine["plan"]["evidence"]["channel_noise"]
    assert learned == want["plan"]["evidence"]["channel_noise"]
    assert learned["learned_sd"] != learned["settled_sd"]
    with pytest.raises(sm.SysidError, match="--learn-noise needs a run that is one Gaussian"):
        sm.identify(data, algorithm="bootstrap", particles=50, seed=SEED, learn_noise=True)
