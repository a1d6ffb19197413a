"""Bad input raises SysidError (a ValueError) with the message `sysid` prints for the same
input; nothing crashes the interpreter."""

import math

import numpy as np
import pytest

import sysid_mpf as sm
from conftest import cli_error


def raises(fn, *args, match=None, **kw):
    with pytest.raises(sm.SysidError, match=match) as e:
        fn(*args, **kw)
    assert isinstance(e.value, ValueError)
    return str(e.value)


@pytest.mark.parametrize(
    "py_kw, cli_args",
    [
        (dict(algorithm="mpf-ekf2", particles=0), ["--algorithm", "mpf-ekf2", "--particles", "0"]),
        (dict(algorithm="storvik", fix={"k9": 1.0}), ["--algorithm", "storvik", "--fix", "k9=1"]),
        (dict(algorithm="bootstrap", fix={"k1": math.inf}), ["--algorithm", "bootstrap", "--fix", "k1=inf"]),
        (dict(algorithm="mln-rbpf", ess_threshold=1.5), ["--algorithm", "mln-rbpf", "--ess-threshold", "1.5"]),
        (dict(algorithm="mln-rbpf", substeps=4), ["--algorithm", "mln-rbpf", "--substeps", "4"]),
        (dict(algorithm="bootstrap", building=sm.Building(storeys=5)), ["--algorithm", "bootstrap", "--storeys", "5"]),
    ],
)
def test_run_errors_have_the_cli_message(sysid, tmp_path, short_dir, py_kw, cli_args):
    data = sm.load_dataset(short_dir)
    building = py_kw.pop("building", None)
    msg = raises(sm.identify, data, None, None, building, **py_kw)
    p = sysid("filter", "--data", short_dir, "--out", tmp_path / "r.json", *cli_args, check=False)
    assert msg == cli_error(p)
    assert not (tmp_path / "r.json").exists()


def test_field_data_without_its_building_is_refused_by_name(sysid, tmp_path, short_data):
    sm.field_data(short_data.ug, short_data.acc, short_data.dt, [1, 2, 3]).write(tmp_path / "f")
    msg = raises(sm.identify, sm.load_dataset(tmp_path / "f"), algorithm="mpf-ekf2")
    p = sysid("filter", "--algorithm", "mpf-ekf2", "--data", tmp_path / "f", "--out", tmp_path / "r.json", check=False)
    assert msg == cli_error(p)
    assert "--masses" in msg and "--measurement" in msg
    # A sensor above the stated top storey, named as the CLI names it.
    msg = raises(
        sm.identify, sm.load_dataset(tmp_path / "f"), None, None,
        sm.Building(storeys=2, hysteretic=[1], masses=1.0, measurement="relative"),
    )
    p = sysid(
        "filter", "--algorithm", "mpf-ekf2", "--data", tmp_path / "f", "--out", tmp_path / "r.json",
        "--storeys", 2, "--hysteretic", 1, "--masses", 1, "--measurement", "relative", check=False,
    )
    assert msg == cli_error(p) and "above the top" in msg


def test_files_errors_have_the_cli_message(sysid, tmp_path, short_dir):
    missing = tmp_path / "nowhere"
    msg = raises(sm.load_dataset, missing)
    p = sysid("filter", "--algorithm", "mpf-ekf2", "--data", missing, "--out", tmp_path / "r.json", check=False)
    assert msg == cli_error(p)
    bad = tmp_path / "bad.toml"
    bad.write_text("particles = -3\n")
    msg = raises(sm.identify, sm.load_dataset(short_dir), config=bad)
    p = sysid("filter", "--algorithm", "mpf-ekf2", "--data", short_dir, "--config", bad, "--out", tmp_path / "r.json", check=False)
    assert msg == cli_error(p)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("particle = 30\n")
    msg = raises(sm.identify, sm.load_dataset(short_dir), config=unknown)
    p = sysid("filter", "--algorithm", "mpf-ekf2", "--data", short_dir, "--config", unknown, "--out", tmp_path / "r.json", check=False)
    assert msg == cli_error(p)


def test_simulate_errors_have_the_cli_message(sysid, tmp_path):
    cases = [
        (dict(building=sm.Building(storeys=0)), ["--storeys", "0"]),
        (dict(building=sm.Building(storeys=3, hysteretic=[4])), ["--storeys", "3", "--hysteretic", "4"]),
        (dict(building=sm.Building(sensors=[2, 1])), ["--sensors", "2,1"]),
        (dict(scale=math.nan), ["--scale", "NaN"]),
        (dict(noise_fraction=-1.0), ["--noise-fraction=-1"]),
        (dict(duration=0.0), ["--duration", "0"]),
        (dict(preset="paper-9dof"), ["--preset", "paper-9dof"]),
        (dict(excitation=str(tmp_path / "none.csv")), ["--excitation", tmp_path / "none.csv"]),
    ]
    for kw, args in cases:
        building = kw.pop("building", None)
        msg = raises(sm.simulate, building, **kw)
        p = sysid("simulate", "--out", tmp_path / "d", *args, check=False)
        assert msg == cli_error(p), (kw, args)


def test_bad_arrays_and_options_are_named():
    ug = np.zeros(50)
    acc = np.zeros((50, 3))
    b = sm.Building(storeys=3, hysteretic=[1], masses=1.0, measurement="absolute")
    raises(sm.identify, ug, acc[:40], 0.01, b, match="acc has 40 rows, ug has 50 samples")
    raises(sm.identify, ug, acc[:, :2], 0.01, b, match="acc has 2 columns, 3 sensors")
    raises(sm.identify, ug, acc, -0.01, b, match="^dt: ")
    raises(sm.identify, ug, acc, math.nan, b, match="^dt: ")
    bad = acc.copy()
    bad[7, 2] = math.nan
    raises(sm.identify, ug, bad, 0.01, b, match="acc column 2: sample 7")
    bad[7, 2] = 1e300
    raises(sm.identify, ug, bad, 0.01, b, match="acc column 2: sample 7")
    raises(sm.identify, ug, np.zeros((50, 2, 2)), 0.01, b, match="shape")
    raises(sm.identify, ug, acc, 0.01, sm.Building(storeys=3, sensors=[0, 1, 2]), match="sensors")
    raises(sm.identify, ug, acc, 0.01, b, algorithm="kalman", match="unknown algorithm `kalman`")
    raises(sm.identify, ug, acc, 0.01, b, resampling="greedy", match="^--resampling: ")
    raises(sm.identify, ug, acc, 0.01, b, discretisation="rk2", match="^--discretisation: ")
    raises(sm.identify, ug, acc, 0.01, b, storvik_update="fast", match="^--storvik-update: ")
    raises(sm.identify, ug, acc, 0.01, sm.Building(storeys=3, measurement="sideways"), match="sideways")
    damped = sm.Building(3, [], 1.0, None, "absolute", "rayleigh")
    raises(sm.identify, ug, acc, 0.01, damped, match="^--damping: unknown damping form `rayleigh`")
    raises(sm.identify, ug, acc, 0.01, sm.Building(3, [1], [1.0, -2.0, 1.0], None, "absolute"), match="--masses")
    raises(sm.identify, ug, acc, 0.01, b, config={"particles": 10, "no_such_key": 1}, match="no_such_key")
    raises(sm.identify, ug[:1], acc[:1], 0.01, b, match="at least 2")
    raises(sm.identify, ug, match="arrays need acc, dt and the building")
    with pytest.raises(ValueError, match="many"):
        sm.identify(ug, acc, 0.01, b, particles="many")


def test_corrupt_records_are_refused(tmp_path):
    r = sm.identify(sm.simulate(duration=0.5, seed=1), particles=20, seed=1)
    text = r.to_json()
    cut = tmp_path / "cut.json"
    cut.write_text(text[: len(text) // 2])
    raises(sm.read_record, cut, match="cut short")
    raises(sm.parse_record, text.replace('"loglik"', '"logl1k"'), match="not a valid run record")
    raises(sm.read_record, tmp_path / "absent.json", match="reading")


def test_the_storey_mass_form_is_refused_by_name_where_unsupported():
    rng = np.random.default_rng(4)
    ug, acc = rng.normal(size=400), rng.normal(size=(400, 3))
    mass = sm.Building(3, [], 1.0, None, "absolute", "storey+mass")
    raises(sm.identify, ug, acc, 0.01, mass, algorithm="storvik", match="storey\\+mass damping form")
    raises(sm.identify, ug, acc, 0.01, mass, algorithm="mln-rbpf", match="MLN-RBPF/Storvik")


def test_outputs_are_refused_over_inputs_links_and_directories(tmp_path, short_data):
    d = tmp_path / "d"
    short_data.write(d)
    measured = (d / "measured.csv").read_bytes()
    data = sm.load_dataset(d)
    raises(sm.identify, data, particles=20, seed=1, out=d / "measured.csv", match="which this command reads")
    assert (d / "measured.csv").read_bytes() == measured
    target = tmp_path / "target.json"
    target.write_text("keep\n")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    raises(sm.identify, data, particles=20, seed=1, out=link, match="symbolic link")
    assert link.is_symlink() and target.read_text() == "keep\n"
    # A directory where a data-set file belongs is refused, not deleted with its contents.
    o = tmp_path / "o"
    (o / "truth.csv").mkdir(parents=True)
    (o / "truth.csv" / "precious.txt").write_text("keep\n")
    raises(short_data.write, o, match="truth.csv")
    assert (o / "truth.csv" / "precious.txt").read_text() == "keep\n"
    raises(sm.loglik, data, truth=True, particles=20, seeds=10**9, match="--seeds 1000000000: at most 10000")


@pytest.mark.parametrize(
    "k, sensors, match",
    [
        (0, [1], "at least 2 are needed"),
        (1, [1], "at least 2 are needed"),
        (5, [2**63], "beyond the 200 storeys"),
        (5, [3, 201], "beyond the 200 storeys"),
    ],
)
def test_field_data_that_would_not_load_back_is_refused(tmp_path, k, sensors, match):
    # The package wrote these, and read back a storey 2**63 beyond the 200-storey limit.
    ug = np.zeros(k)
    acc = np.ones((k, len(sensors)))
    raises(sm.field_data, ug, acc, 0.01, sensors, match=match)
    # What is written loads back, at both ends of the storey range.
    d = sm.field_data(np.zeros(2), np.ones((2, 2)), 0.01, [1, 200])
    d.write(tmp_path / "ok")
    assert sm.load_dataset(tmp_path / "ok").sensors == [1, 200]
