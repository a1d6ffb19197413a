//! The development set of the discrepancy term's search (docs/validation.md, "A discrepancy
//! term"): five simulated three-storey structures of our own — none of them a case of the
//! foreign corpus, which judges and is not used here — identified with `sysid filter`'s minimal
//! flags on San Fernando 1971 and judged on Northridge 1994. For each variant of the search it
//! prints the modes chosen on the identifying record and the free-run fit of the other record
//! with them, beside the building alone.
//!
//! ```sh
//! cargo build --release -p experiments --bin sysid
//! cargo run --release -p experiments --example discrepancy_dev
//! ```

use std::path::{Path, PathBuf};
use std::process::Command;

use experiments::error::{bail, Context, Result};
use experiments::foreign::{self, Sensing, Structure};
use identify::validation::discrepancy::{self, Search, SEARCH};
use identify::validation::free_run::{chain_of, fit_percent, simulate_channels, Integrator};
use models::building::{Building, Damping};
use models::dataset::{load_dir, LoadedDataset};
use models::description::StructureDescription;
use models::sensors::MeasurementKind;
use nalgebra::{DMatrix, DVector};

/// Identifying and judging earthquakes (neither is the corpus's).
const IDENTIFY: &str = "san-fernando-1971";
const JUDGE: &str = "northridge-1994";
const SEED: u64 = 7;

fn sysid() -> PathBuf {
    let exe = std::env::current_exe().expect("the example's path");
    // target/release/examples/discrepancy_dev → target/release/sysid
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .join("sysid")
}

fn run(args: &[&str], out: &Path) -> Result<String> {
    let o = Command::new(sysid())
        .args(args)
        .arg("--out")
        .arg(out)
        .output()?;
    let text = String::from_utf8_lossy(&o.stderr).to_string();
    if !o.status.success() && o.status.code() != Some(1) {
        bail!("sysid {args:?}: {text}");
    }
    Ok(text)
}

/// The clean ground motion of earthquake `name`, 30 s at 200 Hz.
fn ground(name: &str, dir: &Path) -> Result<(Vec<f64>, f64)> {
    let mut args = foreign::GROUND.to_vec();
    args.extend(["--excitation", name, "--duration", "30"]);
    run(&args, dir)?;
    foreign::clean_ground(dir)
}

fn chain(k: &[f64]) -> DMatrix<f64> {
    foreign::chain(k)
}

/// A structure of mass `m` and stiffness `k` with Rayleigh damping of 3 % in the first and last
/// modes of `k`, the ground's influence `r`, the sensors' rows `sensors`.
fn planar(m: DMatrix<f64>, k: DMatrix<f64>, sensors: DMatrix<f64>, r: DVector<f64>) -> Structure {
    Structure {
        c: foreign::rayleigh(&m, &k, 0.03, foreign::band(&k)),
        m,
        k,
        joint: None,
        r,
        sensors,
    }
}

/// The development structures (name, structure).
fn structures() -> Vec<(&'static str, Structure)> {
    let base = [1500.0, 1100.0, 900.0];
    let eye3 = DMatrix::identity(3, 3);
    let ones3 = DVector::from_element(3, 1.0);
    let mut out = vec![(
        "in-class",
        planar(eye3.clone(), chain(&base), eye3.clone(), ones3.clone()),
    )];
    // A brace from the ground to floor 2 (30 % of storey 2's stiffness).
    let mut braced = chain(&base);
    braced[(1, 1)] += 0.3 * base[1];
    out.push((
        "brace ground-2",
        planar(eye3.clone(), braced, eye3.clone(), ones3.clone()),
    ));
    // Sway and twist, the mass 20 % of the radius of gyration off, twist 10 % softer than sway.
    let ks = chain(&base);
    let (mut m6, mut k6) = (DMatrix::identity(6, 6), DMatrix::zeros(6, 6));
    k6.view_mut((0, 0), (3, 3)).copy_from(&ks);
    k6.view_mut((3, 3), (3, 3)).copy_from(&(&ks * 0.9));
    for j in 0..3 {
        m6[(j, j + 3)] = 0.2;
        m6[(j + 3, j)] = 0.2;
        m6[(j + 3, j + 3)] = 1.04;
    }
    let mut r6 = DVector::zeros(6);
    r6.rows_mut(0, 3).fill(1.0);
    let mut s6 = DMatrix::zeros(3, 6);
    for j in 0..3 {
        s6[(j, j)] = 1.0;
        s6[(j, j + 3)] = 1.0;
    }
    out.push(("torsion 0.2", planar(m6, k6, s6, r6)));
    // An 8 % mass on floor 2 tuned 10 % above the first mode.
    let (m4, k4) =
        foreign::with_mass_on(&chain(&base), 1, 0.08, 1.1 * foreign::band(&chain(&base)).0);
    out.push((
        "appendage floor 2",
        planar(
            m4,
            k4,
            DMatrix::identity(3, 4),
            DVector::from_element(4, 1.0),
        ),
    ));
    // Two directions, the second 6 % stiffer, both shaken (the ground at 20° off the first
    // axis) and read by sensors at 20° too: every mode split in two.
    let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
    let mut k2 = DMatrix::zeros(6, 6);
    k2.view_mut((0, 0), (3, 3)).copy_from(&chain(&base));
    k2.view_mut((3, 3), (3, 3))
        .copy_from(&(chain(&base) * 1.06));
    let mut r2 = DVector::zeros(6);
    r2.rows_mut(0, 3).fill(c);
    r2.rows_mut(3, 3).fill(s);
    let mut s2 = DMatrix::zeros(3, 6);
    for j in 0..3 {
        s2[(j, j)] = c;
        s2[(j, j + 3)] = s;
    }
    out.push((
        "two directions",
        planar(DMatrix::identity(6, 6), k2, s2, r2),
    ));
    out
}

/// The structure's record under `ug`, measured with 5 % white noise on stream `purpose`, as a
/// data set in `dir`.
fn record(
    s: &Structure,
    ug: &[f64],
    dt: f64,
    i: u64,
    purpose: &str,
    dir: &Path,
) -> Result<LoadedDataset> {
    let clean = foreign::respond(s, ug, dt);
    let mut rng = core_filters::rng::stream(SEED, i, purpose);
    let mut rec = foreign::measure(&Sensing::default(), ug, clean, &mut rng);
    // A ground motion in the direction of the first axis is what the sensors' table reads.
    rec.ug = ug.to_vec();
    foreign::write(&rec, dt, dir)?;
    Ok(load_dir(dir)?)
}

fn channels(data: &LoadedDataset) -> Vec<Vec<f64>> {
    (0..data.channels)
        .map(|c| (0..data.len()).map(|k| data.y(k)[c]).collect())
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn main() -> Result<()> {
    let tmp = std::env::temp_dir().join("discrepancy-dev");
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp)?;
    let (ug_a, dt) = ground(IDENTIFY, &tmp.join("ground-a"))?;
    let (ug_b, dt_b) = ground(JUDGE, &tmp.join("ground-b"))?;
    if (dt - dt_b).abs() > 1e-12 {
        bail!("the two ground motions have different time steps");
    }
    let variants: Vec<(&str, Search)> = vec![
        (
            "up to 4, the new mode refined alone",
            Search {
                max_modes: 4,
                refine_all: false,
                ..SEARCH
            },
        ),
        (
            "up to 4, every mode refined",
            Search {
                max_modes: 4,
                ..SEARCH
            },
        ),
        (
            "up to 6, every mode refined",
            Search {
                max_modes: 6,
                ..SEARCH
            },
        ),
        ("sysid filter's (up to 8, every mode refined)", SEARCH),
        (
            "up to 8, every mode refined, ζ ≥ 0.5 %",
            Search {
                damping: (0.005, 0.5),
                ..SEARCH
            },
        ),
    ];
    let mut totals = vec![0.0; variants.len()];
    println!("| structure | search | modes chosen (Hz) | {IDENTIFY} held-out | {JUDGE} fit, building alone | with the discrepancy |");
    println!("|---|---|---|---|---|---|");
    for (i, (name, s)) in structures().iter().enumerate() {
        let dir_a = tmp.join(format!("s{i}-a"));
        let dir_b = tmp.join(format!("s{i}-b"));
        let a = record(s, &ug_a, dt, i as u64, "discrepancy dev identify", &dir_a)?;
        let b = record(s, &ug_b, dt, i as u64, "discrepancy dev judge", &dir_b)?;
        let out = dir_a.join("r.json");
        let mut args: Vec<&str> = vec!["filter"];
        args.extend(foreign::MINIMAL_FLAGS);
        let seed = SEED.to_string();
        let data = dir_a.display().to_string();
        args.extend(["--seed", &seed, "--data", &data]);
        run(&args, &out)?;
        let r = identify::validation::cross::read_record(&out)?;
        let damping = if r.param_names.iter().any(|n| n == "alpha") {
            Damping::StoreyMass
        } else {
            Damping::Storey
        };
        let building = Building::new(vec![1.0; 3], vec![], damping)?;
        let d = StructureDescription::of(&building, vec![1, 2, 3], MeasurementKind::Absolute);
        let chain = chain_of(&d, &r.theta_val).context("θ_val")?;
        let sim = |data: &LoadedDataset| {
            simulate_channels(
                &chain,
                &data.ug_meas,
                dt,
                &data.sensors,
                MeasurementKind::Absolute,
                Integrator::ExactLinear,
            )
        };
        let (sim_a, sim_b) = (sim(&a)?, sim(&b)?);
        let (ya, yb) = (channels(&a), channels(&b));
        let names: Vec<String> = (1..=3).map(|s| format!("a{s}")).collect();
        let alone: Vec<f64> = yb
            .iter()
            .zip(&sim_b)
            .map(|(y, s)| fit_percent(y, s))
            .collect();
        let from = identify::choice::split_point(&a);
        for (v, (vname, search)) in variants.iter().enumerate() {
            let choice = discrepancy::choose(search, &names, &ya, &sim_a, &a.ug_meas, dt, from)
                .with_context(|| format!("{name}: the record is too short to choose"))?;
            let modes = choice.modes().to_vec();
            let disc = discrepancy::refit(&modes, &names, &ya, &sim_a, (&a.ug_meas, dt), a.len());
            let add = discrepancy::contribution(&disc, &b.ug_meas, dt);
            let with: Vec<f64> = (0..3)
                .map(|c| {
                    let yhat: Vec<f64> = sim_b[c].iter().zip(&add[c]).map(|(x, e)| x + e).collect();
                    fit_percent(&yb[c], &yhat)
                })
                .collect();
            totals[v] += mean(&with) - mean(&alone);
            let f = |x: &[f64]| {
                x.iter()
                    .map(|v| format!("{v:.1}"))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            println!(
                "| {name} | {vname} | {} | {:.1} → {:.1} | {} | {} |",
                disc.describe_modes(),
                choice.candidates[0].score.unwrap_or(f64::NAN),
                choice.candidates[choice.chosen].score.unwrap_or(f64::NAN),
                f(&alone),
                f(&with)
            );
        }
    }
    println!();
    for ((vname, _), t) in variants.iter().zip(&totals) {
        println!(
            "{vname}: mean gain on {JUDGE} over the structures {:.2} points",
            t / structures().len() as f64
        );
    }
    Ok(())
}
