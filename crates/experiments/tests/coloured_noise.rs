//! Coloured measurement noise (`--coloured-noise RHO,SHARE`, docs/validation.md): the MPF-EKF2
//! carries it as one AR(1) state per channel in its Gaussian part; the plan and the record keep
//! it; the partitions without a Gaussian part and out-of-range values are refused by name. (Its
//! exactness — the filter equals the Kalman filter of the chain with the AR(1) states appended —
//! is tested in `models`' `mpf_ekf2_is_the_kalman_filter_of_a_linear_chain`.)

use crate::common;

use std::ffi::OsStr;
use std::path::Path;

fn sysid(args: &[&OsStr]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sysid"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
        .args(args)
        .output()
        .unwrap()
}

fn read(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The 95 % interval of parameter `name` in a record.
fn interval(r: &serde_json::Value, name: &str) -> (f64, f64) {
    let c = r["credible"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["parameter"] == name)
        .unwrap();
    let i = c["intervals"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["level"] == 0.95)
        .unwrap();
    (i["lo"].as_f64().unwrap(), i["hi"].as_f64().unwrap())
}

#[test]
fn coloured_noise_is_carried_recorded_and_refused_where_it_cannot_be() {
    let (_tmp, root) = common::temp_dir("sysid-coloured-");
    let data = root.join("d");
    common::linear_field_data(&data, "7", "10");
    let run = |extra: &[&str], out: &Path| {
        let args: Vec<&OsStr> = common::LINEAR_FIELD_FILTER
            .iter()
            .chain(&common::LINEAR_FIELD_STATED)
            .chain(extra)
            .map(OsStr::new)
            .chain([
                "--data".as_ref(),
                data.as_os_str(),
                "--out".as_ref(),
                out.as_os_str(),
            ])
            .collect();
        sysid(&args)
    };
    let (white, coloured) = (root.join("white.json"), root.join("coloured.json"));
    for (extra, out) in [
        (&[][..], &white),
        (&["--coloured-noise", "0.9,0.5"][..], &coloured),
    ] {
        let o = run(extra, out);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        // The noise line says what part is coloured, and only when some is.
        let said = err.contains("the part 0.5 is coloured, AR(1) with ρ 0.9 per sample");
        assert_eq!(said, !extra.is_empty(), "{err}");
    }
    let (w, c) = (read(&white), read(&coloured));
    let expected = serde_json::json!({"rho": 0.9, "share": 0.5});
    assert_eq!(c["config"]["spec"]["coloured_noise"], expected);
    assert_eq!(c["plan"]["model"]["coloured_noise"], expected);
    assert_eq!(c["config"]["filter"]["coloured_noise"], expected);
    assert!(w["config"]["spec"].get("coloured_noise").is_none());
    assert!(w["plan"]["model"].get("coloured_noise").is_none());
    assert_ne!(w["fingerprint"], c["fingerprint"]);
    // On data with white noise, half of it declared coloured leaves less to learn θ from: every
    // stiffness's interval is wider, and the answer stays near the white one's.
    for k in ["k1", "k2", "k3"] {
        let ((wl, wh), (cl, ch)) = (interval(&w, k), interval(&c, k));
        assert!(
            ch - cl > wh - wl,
            "{k}: [{cl}, {ch}] not wider than [{wl}, {wh}]"
        );
        let wm = 0.5 * (wl + wh);
        assert!(
            cl < wm && wm < ch,
            "{k}: [{cl}, {ch}] misses the white run's {wm}"
        );
    }

    // The plan keeps it: printed, and run again from the printed plan to the same answer.
    let o = run(
        &["--coloured-noise", "0.9,0.5", "--print-plan"],
        &root.join("x.json"),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let plan = String::from_utf8(o.stdout).unwrap();
    assert!(plan.contains("[model.coloured_noise]"), "{plan}");
    let plan_file = root.join("plan.toml");
    std::fs::write(&plan_file, plan).unwrap();
    let again = root.join("again.json");
    let o = sysid(&[
        "filter".as_ref(),
        "--plan".as_ref(),
        plan_file.as_os_str(),
        "--data".as_ref(),
        data.as_os_str(),
        "--out".as_ref(),
        again.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(read(&again)["theta_val"], c["theta_val"]);

    // Refused by name: a partition without a Gaussian part, values out of range.
    let refused = root.join("refused.json");
    // The minimal flags with the bootstrap PF in place of the MPF-EKF2.
    let bootstrap: Vec<&OsStr> = common::LINEAR_FIELD_FILTER
        .iter()
        .map(|a| if *a == "mpf-ekf2" { "bootstrap" } else { a })
        .chain(["--particles", "50", "--coloured-noise", "0.9,0.5"])
        .map(OsStr::new)
        .chain([
            "--data".as_ref(),
            data.as_os_str(),
            "--out".as_ref(),
            refused.as_os_str(),
        ])
        .collect();
    let o = sysid(&bootstrap);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("coloured_noise") && err.contains("MPF-EKF2"),
        "{err}"
    );
    assert!(!refused.exists(), "no record for a refused run");
    for (bad, says) in [
        ("1,0.5", "coloured_noise.rho"),
        ("0.9,1.5", "coloured_noise.share"),
        ("0.9", "RHO,SHARE"),
        ("x,0.5", "RHO `x`"),
    ] {
        let o = run(&["--coloured-noise", bad], &refused);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{bad}");
        assert!(err.contains(says), "{bad}: {err}");
    }
}
