//! A run stopped by its caller (`identify_stoppable`, the hook of an interactive Ctrl-C) ends
//! with the typed `Interrupted` error, pooled or not; a run that is never stopped returns the
//! record `identify` returns, bit for bit.

use std::sync::atomic::{AtomicUsize, Ordering};

use identify::pipeline::{
    identify, identify_stoppable, Algorithm, FilterSettings, Interrupted, RunInput,
};
use models::dataset::{generate, DatasetConfig};

#[test]
fn a_stopped_run_is_interrupted_and_an_unstopped_one_unchanged() {
    let mut config = DatasetConfig::from_preset("paper-3dof", 4).unwrap();
    config.duration = Some(1.0);
    let data = generate(&config).unwrap();
    let loaded = data.to_loaded();
    let input = RunInput {
        data: &loaded,
        chain: Some(&data.chain),
        experiment: "interrupt",
        seed: 4,
        run: 0,
        progress: None,
        residuals: true,
    };
    let steps = loaded.len() - 1;
    for pool in [1, 2] {
        let s = FilterSettings {
            particles: 40,
            pool,
            ..FilterSettings::default()
        };
        for alg in Algorithm::ALL {
            let asked = AtomicUsize::new(0);
            let stop = || asked.fetch_add(1, Ordering::SeqCst) + 1 >= 30;
            let e = identify_stoppable(&input, alg, &s, &stop).unwrap_err();
            let i = e
                .interrupted()
                .unwrap_or_else(|| panic!("{}: not Interrupted: {e:#}", alg.name()));
            let asked = asked.load(Ordering::SeqCst);
            if pool == 1 {
                assert_eq!(*i, Interrupted { step: 30, steps });
                assert_eq!(asked, 30, "{}: no step after the stop", alg.name());
            } else {
                // The pooled filters run side by side and ask in turn: the 30th question stops
                // the filter that asked it, and every other filter at its next question.
                assert!(i.step <= 30 && i.steps == steps, "{}: {i:?}", alg.name());
                assert!(
                    (30..=30 + pool).contains(&asked),
                    "{}: {asked} questions: a filter stepped on after the stop",
                    alg.name()
                );
            }

            let plain = identify(&input, alg, &s).unwrap();
            let never = identify_stoppable(&input, alg, &s, &|| false).unwrap();
            assert_eq!(plain.deterministic_json(), never.deterministic_json());
        }
    }
}
