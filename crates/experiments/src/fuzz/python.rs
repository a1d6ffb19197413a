//! Probes of the Python package `sysid_mpf`: each runs a short script in a fresh interpreter
//! (`python -c SCRIPT PARAMS`), its hostile values in the JSON parameters, its files in the
//! probe's directory. A Python exception is a refusal (the script prints it as `Error: …` and
//! exits 1); a `PanicException` exits 101 (a crash, as a panic of `sysid`); a promise broken
//! without an exception (a data set written that does not load back) exits 3.

use rand::seq::IndexedRandom;
use rand::Rng;
use serde_json::{json, Value};

use super::mutate::FuzzRng;
use super::probe::{Probe, Program, Ref};
use super::seeds::Seeds;
use super::targets::Make;

/// The Python targets.
pub(crate) const TARGETS: &[(&str, Make)] = &[
    ("py load_dataset", load_dataset),
    ("py field_data", field_data),
    ("py identify", identify),
    ("py simulate", simulate),
    ("py loglik", loglik),
    ("py records", records),
];

/// Decodes the parameters (`{"$f": "nan"}` a float, `{"$i": "…"}` an integer of any size),
/// runs the body and maps how it ended to an exit status.
const PRELUDE: &str = r#"import json, sys
def _dec(v):
    if isinstance(v, dict):
        if set(v) == {"$f"}:
            return float(v["$f"])
        if set(v) == {"$i"}:
            return int(v["$i"])
        return {k: _dec(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_dec(x) for x in v]
    return v
P = _dec(json.loads(sys.argv[1]))
class Broken(Exception):
    pass
def body(np, sm):
"#;

const EPILOGUE: &str = r#"
try:
    import numpy
    import sysid_mpf
    body(numpy, sysid_mpf)
except Broken as e:
    print(f"Broken: {e}", file=sys.stderr)
    sys.exit(3)
except Exception as e:
    lines = str(e).splitlines()
    print(f"Error: {type(e).__name__}: {lines[0] if lines else ''}", file=sys.stderr)
    sys.exit(1)
except BaseException as e:
    if type(e).__name__ == "PanicException":
        print(f"panicked: {e}", file=sys.stderr)
        sys.exit(101)
    raise
"#;

/// The script of a probe whose body is `body` (lines indented by four spaces).
fn script(body: &str) -> String {
    format!("{PRELUDE}{body}{EPILOGUE}")
}

fn python(target: &'static str, body: &str) -> Probe {
    let mut p = Probe::new(target, Program::Python);
    p.args.push("-c".into());
    p.args.push(script(body).into());
    p
}

const DATASET: &[&str] = &["measured.csv", "truth.csv", "dataset.json"];

/// The data set `d` or `field` as parameter `data`.
fn data(p: &mut Probe, s: &Seeds, rng: &mut FuzzRng) {
    let name = *["d", "d", "field"].choose(rng).expect("names");
    p.params.insert("data".into(), name.into());
    p.input_dir(name, s.dataset(name), Ref::Param("data".into()));
}

const LOAD: &str = r#"    d = sm.load_dataset(P["data"])
    _ = (len(d), d.dt, d.t.sum(), d.ug.sum(), d.acc.sum(), d.sensors, d.states, d.theta_true,
         d.theta_names, d.state_names, d.building, d.meta_json, d.ug_clean)
    if P.get("out") is not None:
        d.write(P["out"])
        back = sm.load_dataset(P["out"])
        if len(back) != len(d):
            raise Broken(f"wrote {len(d)} samples, read back {len(back)}")
"#;

fn load_dataset(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py load_dataset", LOAD);
    data(&mut p, s, rng);
    if rng.random_bool(0.5) {
        p.py_output("out", "o", true, DATASET);
        // `Dataset.write` replaces a data-set directory with the data set it holds, as
        // `simulate --out` does: the one it was loaded from too.
        for slot in p.inputs.iter_mut() {
            slot.kept = false;
        }
    }
    p
}

const FIELD: &str = r#"    d = sm.field_data(np.asarray(P["ug"], dtype=float), np.asarray(P["acc"], dtype=float),
                      P["dt"], P["sensors"])
    d.write(P["out"])
    back = sm.load_dataset(P["out"])
    if len(back) != len(d) or list(back.sensors) != list(d.sensors):
        raise Broken(f"wrote {len(d)} samples at {d.sensors}, read back {len(back)} at {back.sensors}")
"#;

/// Arrays for `field_data`: a smooth record, or one with a hostile value or shape.
fn field_arrays(rng: &mut FuzzRng) -> (Value, Value, &'static str) {
    let k = 100;
    let ug: Vec<f64> = (0..k).map(|i| (0.3 * i as f64).sin()).collect();
    let acc: Vec<Vec<f64>> = (0..k)
        .map(|i| vec![(0.2 * i as f64).cos(), (0.1 * i as f64).sin()])
        .collect();
    let (mut ug, mut acc) = (json!(ug), json!(acc));
    let what = match rng.random_range(0..10) {
        0 => {
            ug[7] = json!({"$f": "nan"});
            "ug[7] = nan"
        }
        1 => {
            acc[3][1] = json!({"$f": "inf"});
            "acc[3][1] = inf"
        }
        2 => {
            ug[0] = json!(1e300);
            "ug[0] = 1e300"
        }
        3 => {
            (ug, acc) = (json!([0.5]), json!([[0.5, 0.5]]));
            "one sample"
        }
        4 => {
            (ug, acc) = (json!([]), json!([]));
            "no sample"
        }
        5 => {
            acc[4] = json!([1.0]);
            "a ragged row"
        }
        6 => {
            acc = json!([[[1.0, 2.0]]]);
            "acc of three dimensions"
        }
        7 => {
            acc = json!(vec![vec![0.5; k]; 2]);
            "acc transposed"
        }
        _ => "valid arrays",
    };
    (ug, acc, what)
}

fn field_data(_s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py field_data", FIELD);
    let (ug, acc, what) = field_arrays(rng);
    p.fixed_param("ug", ug);
    p.fixed_param("acc", acc);
    p.param("dt", json!(0.01));
    p.param("sensors", json!([1, 2]));
    p.py_output("out", "o", true, DATASET);
    p.what = what.into();
    p
}

const IDENTIFY: &str = r#"    kw = dict(algorithm=P["algorithm"], particles=P["particles"], seed=P["seed"],
              config=P.get("config"), fix=P.get("fix"), ess_threshold=P.get("ess_threshold"),
              substeps=P.get("substeps"), out=P.get("out"))
    if P.get("arrays"):
        b = sm.Building(storeys=P["storeys"], hysteretic=P["hysteretic"], masses=P["masses"],
                        measurement=P["measurement"], sensors=P["sensors"])
        r = sm.identify(np.asarray(P["ug"], dtype=float), np.asarray(P["acc"], dtype=float),
                        P["dt"], b, **kw)
    else:
        r = sm.identify(sm.load_dataset(P["data"]), **kw)
    _ = (r.theta_val, r.theta_sd, r.credible, r.trace_mean, r.residuals, r.to_json())
    if P.get("out") is not None:
        sm.read_record(P["out"])
"#;

fn identify(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py identify", IDENTIFY);
    // Field data from arrays (no file: nothing `out` could overwrite but the config), or a
    // data set loaded from its directory.
    let arrays = rng.random_bool(0.3);
    if arrays {
        let (ug, acc, what) = field_arrays(rng);
        p.fixed_param("arrays", json!(true));
        p.fixed_param("ug", ug);
        p.fixed_param("acc", acc);
        p.param("dt", json!(0.01));
        p.param("sensors", json!([1, 2]));
        p.param("storeys", json!(3));
        p.param("hysteretic", json!([1]));
        p.param("masses", json!(1.0));
        p.param("measurement", json!("relative"));
        p.what = what.into();
    } else {
        data(&mut p, s, rng);
    }
    let algorithm = *["mpf-ekf2", "bootstrap", "mln-rbpf", "storvik"]
        .choose(rng)
        .expect("algorithms");
    p.param("algorithm", json!(algorithm));
    p.param("particles", json!(20));
    p.param("seed", json!(1));
    let field = p.params.get("data") == Some(&json!("field"));
    match rng.random_range(0..4) {
        0 if arrays || field => {
            p.py_input("config", "fieldcfg.toml", s.get("fieldcfg.toml"));
        }
        0 => {
            p.py_input("config", "cfg.toml", s.get("cfg.toml"));
        }
        1 => {
            p.param(
                "config",
                json!({"particles": 20, "noise_fraction": 0.1, "window": 20, "pool": 1}),
            );
        }
        _ => {}
    }
    for (key, value) in [
        ("fix", json!({"k1": 8.0})),
        ("ess_threshold", json!(0.5)),
        ("substeps", json!(2)),
    ] {
        if rng.random_bool(0.2) {
            p.param(key, value);
        }
    }
    if rng.random_bool(0.5) {
        p.py_output("out", "run.json", false, &[]);
    }
    p
}

const SIMULATE: &str = r#"    b = sm.Building(storeys=P.get("storeys"), hysteretic=P.get("hysteretic"),
                    sensors=P.get("sensors"))
    d = sm.simulate(b, preset=P["preset"], excitation=P.get("excitation"), duration=P["duration"],
                    scale=P.get("scale"), noise_fraction=P["noise_fraction"], seed=P["seed"])
    if P.get("out") is not None:
        d.write(P["out"])
        back = sm.load_dataset(P["out"])
        if len(back) != len(d):
            raise Broken(f"wrote {len(d)} samples, read back {len(back)}")
"#;

fn simulate(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py simulate", SIMULATE);
    p.param("duration", json!(0.5));
    p.param("seed", json!(1));
    p.param("noise_fraction", json!(0.1));
    if rng.random_bool(0.4) {
        p.param("preset", json!("shear-chain"));
        p.param("storeys", json!(4));
        p.param("hysteretic", json!([1, 3]));
        p.param("sensors", json!([2, 4]));
    } else {
        p.param("preset", json!("paper-3dof"));
    }
    match rng.random_range(0..3) {
        0 => {
            p.py_input("excitation", "exc.csv", s.get("exc.csv"));
        }
        1 => {
            p.py_input("excitation", "rec.AT2", s.get("rec.AT2"));
            p.param("scale", json!(2.0));
        }
        _ => {}
    }
    if rng.random_bool(0.6) {
        p.py_output("out", "o", true, DATASET);
    }
    p
}

const LOGLIK: &str = r#"    d = sm.load_dataset(P["data"])
    r = sm.read_record(P["record"])
    out = sm.loglik(d, [r], particles=P["particles"], seeds=P["seeds"], truth=P["truth"])
    _ = out["table"]
"#;

fn loglik(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py loglik", LOGLIK);
    p.params.insert("data".into(), "d".into());
    p.input_dir("d", s.dataset("d"), Ref::Param("data".into()));
    p.py_input("record", "run.json", s.get("run.json"));
    p.param("particles", json!(20));
    p.param("seeds", json!(2));
    p.param("truth", json!(rng.random_bool(0.5)));
    p
}

const RECORDS: &str = r#"    if P.get("parse"):
        import os, stat
        # The script's own read (parse_record takes text): only of a regular file of a size
        # the reader of sysid_mpf would read.
        st = os.stat(P["record"])
        if not stat.S_ISREG(st.st_mode) or st.st_size > 1 << 26:
            raise ValueError(f"{P['record']}: not a regular file of text (the probe's own check)")
        with open(P["record"], "rb") as f:
            r = sm.parse_record(f.read().decode("utf-8", "replace"))
    else:
        r = sm.read_record(P["record"])
    _ = (r.to_dict(), r.theta_val, r.credible, r.residuals, r.validation, r.warnings)
    if P.get("out") is not None:
        r.write(P["out"])
        sm.read_record(P["out"])
"#;

fn records(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = python("py records", RECORDS);
    let record = *["run.json", "runcfg.json"].choose(rng).expect("records");
    p.py_input("record", record, s.get(record));
    // `Record.write` writes the record in memory, wherever asked, as a plain writer: over the
    // file it was read from too.
    p.inputs.last_mut().expect("the record").kept = false;
    p.param("parse", json!(rng.random_bool(0.3)));
    if rng.random_bool(0.5) {
        p.py_output("out", "copy.json", false, &[]);
    }
    p
}
