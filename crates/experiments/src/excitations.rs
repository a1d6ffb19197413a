//! The excitations study (`experiments/excitations.toml`, `sysid excitations`, `cargo xtask
//! reproduce-excitations`): the paper's structure identified under other ground motions than
//! El Centro, to test the paper's remark that its results "would most likely vary with the
//! excitation" (SPEC §9).
//!
//! The study is an ordinary [`Study`] whose structure axis varies the excitation (the
//! `excitation` and `scale` fields of `[[sweep.structures]]`); its sweep is the one of the
//! scaling study (`crate::scaling::run_with`: resumable, shardable, CPU time per run). This
//! module writes its outputs: per ground motion and algorithm the stiffness and damping errors,
//! θ_val ratios of the Bouc–Wen parameters, the coverage of the 95 % intervals of k and c and
//! the failures; a figure; and the verdicts the study file declares (`[[verdicts]]`, test
//! `differs-from-first`: "the accuracy varies with the excitation", one per algorithm), decided
//! by [`crate::verdict::Declared::decide_structures`] on the records of each ground motion.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::Result;
use serde::Serialize;

use crate::markdown::{compact_header, joined, num, share};
use crate::scaling::structures::{structure_values, StructureValues};
use crate::scaling::{self, Cell, Options};
use crate::study::{Job, Study};
use crate::sweep::write_bytes_atomic;
use crate::verdict::declared::Metric;
use crate::verdict::{group_error, ratio, Declared, Estimate, Finding};
use identify::figures::{category_panels, CategoryGroup, CategoryPanel};
use identify::metrics::mean_sd;
use identify::pipeline::Algorithm;
use identify::record::RunRecord;

/// Runs the study and writes its outputs. Returns the cells.
pub fn run(opts: &Options) -> Result<Vec<Cell>> {
    scaling::run_with(opts, &write_outputs)
}

/// One ground motion × algorithm.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub structure: String,
    pub algorithm: String,
    pub runs: usize,
    pub failed: usize,
    /// Storey-averaged |k̂ − k|/k and |ĉ − c|/c over the completed runs: mean and s.e.
    pub k_error: Estimate,
    pub c_error: Estimate,
    /// Mean θ_val/θ_true of β, γ, n over the completed runs (first element).
    pub beta_ratio: f64,
    pub gamma_ratio: f64,
    pub n_ratio: f64,
    /// Fraction of (run, parameter) pairs of the k's and c's whose 95 % interval holds the truth.
    pub coverage95_kc: f64,
    pub coverage_pairs: usize,
}

fn first_element(name: &str, base: &str) -> bool {
    name == base || name == format!("{base}1")
}

/// The rows of the report from the study's jobs and records.
pub fn rows(study: &Study, jobs: &[Job], records: &[RunRecord]) -> Vec<Row> {
    let mut out = Vec::new();
    for (i, st) in study.sweep.structures.iter().enumerate() {
        let algorithms = st.algorithms.as_ref().unwrap_or(&study.sweep.algorithms);
        for &a in algorithms {
            let recs: Vec<&RunRecord> = jobs
                .iter()
                .zip(records)
                .filter(|(j, _)| j.structure == Some(i) && j.algorithm == a)
                .map(|(_, r)| r)
                .collect();
            out.push(row(&st.label, a, &recs));
        }
    }
    out
}

fn row(label: &str, a: Algorithm, recs: &[&RunRecord]) -> Row {
    let done: Vec<&RunRecord> = recs.iter().copied().filter(|r| !r.is_failure()).collect();
    let mean_ratio = |base: &str| {
        let v: Vec<f64> = done
            .iter()
            .filter_map(|r| {
                let name = r.param_names.iter().find(|n| first_element(n, base))?;
                Some(ratio(r, name))
            })
            .collect();
        mean_sd(&v).0
    };
    let (coverage95_kc, coverage_pairs) = crate::coverage::stiffness_damping_coverage(&done, 0.95);
    let errors =
        |prefix: char| -> Vec<f64> { done.iter().map(|r| group_error(r, prefix)).collect() };
    Row {
        structure: label.to_string(),
        algorithm: a.name().to_string(),
        runs: recs.len(),
        failed: recs.len() - done.len(),
        k_error: Estimate::of(&errors('k')),
        c_error: Estimate::of(&errors('c')),
        beta_ratio: mean_ratio("beta"),
        gamma_ratio: mean_ratio("gamma"),
        n_ratio: mean_ratio("n"),
        coverage95_kc,
        coverage_pairs,
    }
}

/// The study's declared verdicts decided on the records of each ground motion (the first the
/// control), each with its declaration.
pub fn verdicts<'a>(
    study: &'a Study,
    jobs: &[Job],
    records: &'a [RunRecord],
) -> Vec<(&'a Declared, Finding)> {
    let structures: Vec<(&str, Vec<&RunRecord>)> = (study.sweep.structures.iter().enumerate())
        .map(|(i, st)| {
            let runs = jobs
                .iter()
                .zip(records)
                .filter(|(j, _)| j.structure == Some(i));
            (st.label.as_str(), runs.map(|(_, r)| r).collect())
        })
        .collect();
    (study.verdicts.iter())
        .filter_map(|d| Some((d, d.decide_structures(&structures, "ground motion")?)))
        .collect()
}

fn pct(e: &Estimate) -> String {
    match (e.mean.is_finite(), e.se.is_finite()) {
        (false, _) => "–".into(),
        (true, false) => format!("{:.2}%", 100.0 * e.mean),
        (true, true) => format!("{:.2}% ± {:.2}%", 100.0 * e.mean, 100.0 * e.se),
    }
}

fn write_outputs(
    opts: &Options,
    study: &Study,
    _cells: &[Cell],
    jobs: &[Job],
    records: &[RunRecord],
) -> Result<()> {
    let out = &opts.out;
    let values = structure_values(study)?;
    let rows = rows(study, jobs, records);
    let verdicts = verdicts(study, jobs, records);
    let decided: Vec<serde_json::Value> = (verdicts.iter())
        .map(|(d, f)| {
            let a = d.algorithms.join(", ");
            serde_json::json!({ "algorithm": a, "differences": f.parts, "verdict": f.verdict })
        })
        .collect();
    identify::plot::figures_in_place(out, |dir| {
        figure(study, &rows, &dir.join("errors_by_excitation.svg"))
    })?;
    scaling::write_summary(
        opts,
        study,
        &values,
        serde_json::json!({
            "rows": rows,
            "verdicts": decided,
        }),
    )?;
    let text = report(study, &values, &rows, &verdicts, opts.mode.quick);
    write_bytes_atomic(&out.join("REPORT.md"), text.as_bytes())
}

fn figure(study: &Study, rows: &[Row], path: &Path) -> Result<()> {
    let categories: Vec<String> = study
        .sweep
        .structures
        .iter()
        .map(|s| s.label.clone())
        .collect();
    let panel = |caption: &str, pick: &dyn Fn(&Row) -> &Estimate| CategoryPanel {
        caption: caption.to_string(),
        y_desc: "error [%] (± 2 s.e.)".to_string(),
        groups: study
            .sweep
            .algorithms
            .iter()
            .map(|a| {
                let (mean, half_width) = categories
                    .iter()
                    .map(|c| {
                        rows.iter()
                            .find(|r| &r.structure == c && r.algorithm == a.name())
                            .map_or((f64::NAN, f64::NAN), |r| {
                                let e = pick(r);
                                (100.0 * e.mean, 200.0 * e.se)
                            })
                    })
                    .unzip();
                CategoryGroup {
                    label: a.name().to_string(),
                    mean,
                    half_width,
                }
            })
            .collect(),
    };
    category_panels(
        &categories,
        &[
            panel(
                "stiffness: mean over runs of the storey-averaged |k̂ − k|/k",
                &|r| &r.k_error,
            ),
            panel(
                "damping: mean over runs of the storey-averaged |ĉ − c|/c",
                &|r| &r.c_error,
            ),
        ],
        path,
        "Identification of the paper's structure under each ground motion",
    )
}

/// The report text.
pub fn report(
    study: &Study,
    values: &[StructureValues],
    rows: &[Row],
    verdicts: &[(&Declared, Finding)],
    quick: bool,
) -> String {
    let mut o = String::new();
    preamble(&mut o, study, quick);
    ground_motions(&mut o, values);
    measurement(&mut o, rows);
    let _ = writeln!(o, "\n![errors](errors_by_excitation.svg)\n");
    verdict_tables(&mut o, verdicts);
    o
}

/// The title and where the report comes from: the study's description, seed, particles and
/// discretisation.
fn preamble(o: &mut String, study: &Study, quick: bool) {
    let _ = writeln!(
        o,
        "# Excitations study{}\n",
        if quick { " (quick form)" } else { "" }
    );
    let _ = writeln!(
        o,
        "{}\n\nGenerated by `sysid excitations` (`cargo xtask reproduce-excitations`) from the \
         records in `records/`; the numbers are in `summary.json` and `cells.csv`. Master seed \
         {}, {} particles, {} discretisation, the paper's filter settings and priors \
         (docs/excitations.md).\n",
        study.description,
        study.sweep.master_seed,
        joined(&study.sweep.particles, ", "),
        study.filter.discretisation.name(),
    );
}

/// The paper's remark, how the ground motions are scaled, and one row per ground motion: its
/// record, scale, PGA, duration and how far the Bouc–Wen element yields.
fn ground_motions(o: &mut String, values: &[StructureValues]) {
    let _ = writeln!(
        o,
        "## Beyond the paper: other ground motions\n\n**The paper's remark** (Olivier & Smyth \
         2016, Section 5): the structure is identified under El Centro only, and the results \
         \"would most likely vary with the excitation\".\n\n**The ground motions.** Each \
         record is scaled so that the Bouc–Wen element reaches the same fraction of its \
         saturation (β + γ)^(−1/n) as under the paper's El Centro × 3.0 (0.65): the structure \
         yields as much under every record, so what differs is the frequency content and the \
         duration. The first row is the paper's data (the control).\n"
    );
    compact_header(
        o,
        &[
            "ground motion",
            "record",
            "scale",
            "PGA",
            "duration (s)",
            "max \\|r₁\\| / saturation",
        ],
        "llrrrr",
    );
    for v in values {
        let y = joined(v.yielding.iter().map(|(_, r)| format!("{r:.2}")), ", ");
        let _ = writeln!(
            o,
            "| `{}` | {} | {} | {:.2} | {:.1} | {} |",
            v.label, v.excitation, v.scale, v.pga, v.duration, y
        );
    }
}

/// What is measured, and one row per ground motion and algorithm: errors, ratios of the
/// Bouc–Wen parameters, coverage and failed runs.
fn measurement(o: &mut String, rows: &[Row]) {
    let _ = writeln!(
        o,
        "\n**The measurement.** Per ground motion and algorithm: the storey-averaged stiffness \
         and damping errors (mean over runs ± standard error), the mean θ_val/θ_true of β, γ, n, \
         the fraction of (run, k or c) pairs whose central 95 % interval holds the truth, and \
         the failed runs.\n"
    );
    compact_header(
        o,
        &[
            "ground motion",
            "algorithm",
            "k error",
            "c error",
            "β ratio",
            "γ ratio",
            "n ratio",
            "95 % coverage (k, c)",
            "runs (failed)",
        ],
        "llrrrrrrr",
    );
    for r in rows {
        let _ = writeln!(
            o,
            "| `{}` | {} | {} | {} | {} | {} | {} | {} | {} ({}) |",
            r.structure,
            r.algorithm,
            pct(&r.k_error),
            pct(&r.c_error),
            num(r.beta_ratio, 2),
            num(r.gamma_ratio, 2),
            num(r.n_ratio, 2),
            share(r.coverage95_kc, r.coverage_pairs),
            r.runs,
            r.failed
        );
    }
}

/// One paragraph and table per statement and test (the file declares one, per algorithm):
/// each algorithm's differences from the control and its verdict.
fn verdict_tables(o: &mut String, verdicts: &[(&Declared, Finding)]) {
    for group in
        verdicts.chunk_by(|(_, f), (_, g)| (&f.statement, &f.test) == (&g.statement, &g.test))
    {
        let (d, first) = &group[0];
        let _ = writeln!(
            o,
            "**The verdict.** Statement, per algorithm: *{}*. Test: {}.\n",
            first.statement, first.test
        );
        let k = d
            .metric
            .filter(|m| *m == Metric::CError)
            .map_or("k", |_| "c");
        let columns = format!("differences from the control ({k} error)");
        compact_header(o, &["algorithm", &columns, "verdict"], "lll");
        for (d, f) in group {
            let a = d.algorithms.join(", ");
            let _ = writeln!(o, "| {a} | {} | **{}** |", f.evidence, f.verdict.label());
        }
        let _ = writeln!(o);
    }
}
