//! The whiteness check of the one-step prediction errors (`identify::residuals`) is calibrated:
//! on records of the model's own class it flags channels at about its nominal 5 %, and on the
//! shake-table frame, which the shear model does not fully explain, it flags every channel.

use crate::common;

use std::ffi::OsStr;
use std::path::Path;

use identify::record::RunRecord;

fn flagged(record: &Path) -> (usize, usize) {
    let r: RunRecord = serde_json::from_str(&std::fs::read_to_string(record).unwrap()).unwrap();
    let n = r.innovation_checks.len();
    (r.innovation_checks.iter().filter(|c| !c.white).count(), n)
}

#[test]
fn on_records_of_the_models_own_class_it_flags_at_its_nominal_rate() {
    let (_tmp, root) = common::temp_dir("sysid-white-");
    let (mut hits, mut channels) = (0, 0);
    // The user guide's command: the paper's data, 500 particles (4 pooled filters).
    for seed in 51..71 {
        let data = root.join(format!("d{seed}"));
        let seed = seed.to_string();
        common::sysid_ok([
            OsStr::new("simulate"),
            "--seed".as_ref(),
            seed.as_ref(),
            "--out".as_ref(),
            data.as_os_str(),
        ]);
        let record = root.join(format!("r{seed}.json"));
        common::sysid_ok(
            [
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--particles",
                "500",
                "--seed",
                "1",
            ]
            .map(OsStr::new)
            .into_iter()
            .chain([
                "--data".as_ref(),
                data.as_os_str(),
                "--out".as_ref(),
                record.as_os_str(),
            ]),
        );
        let (h, n) = flagged(&record);
        hits += h;
        channels += n;
    }
    // 60 channels of a 5 % test: at most 9 is the 99.9 % quantile of Binomial(60, 0.05).
    assert_eq!(channels, 60);
    assert!(hits <= 9, "{hits} of {channels} channels flagged");
}

#[test]
fn on_the_shake_table_frame_it_flags_every_channel() {
    let (_tmp, dir) = common::temp_dir("sysid-white-");
    let data = dir.join("northridge");
    common::import_frame_northridge(&data);
    let record = dir.join("r.json");
    common::sysid_ok(common::FRAME_FILTER.iter().map(OsStr::new).chain([
        "--data".as_ref(),
        data.as_os_str(),
        "--out".as_ref(),
        record.as_os_str(),
    ]));
    assert_eq!(flagged(&record), (3, 3));
}
