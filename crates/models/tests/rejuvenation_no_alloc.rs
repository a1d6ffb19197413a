//! With the rejuvenation move on, a run's steps still allocate nothing after set-up: a counting
//! global allocator counts this thread's allocations between the runner's first and last observer
//! calls, for the MPF-EKF2 and the MLN-RBPF on the Bouc–Wen chain (whose exponent n is declared
//! static), resampling at every step and on the ESS. The move does act in these runs (n ends
//! with more distinct values than the run without it).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use core_filters::model::Layout as ModelLayout;
use core_filters::resampling::ResamplePolicy;
use core_filters::rng::stream;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::mpf::MpfEkf2;
use core_filters::smc::runner::WeightedParticles;
use core_filters::smc::{run, Filter, LiuWest, Observer, Posterior, SmcConfig, StepInfo};
use models::building::{Building, Damping};
use models::filtering::{ChainSpec, MlnChain, MpfChain, RmsLevels};
use models::sensors::{MeasurementKind, SensorLayout};

struct Counting;

thread_local! {
    static COUNT: Cell<u64> = const { Cell::new(0) };
    static ARMED: Cell<bool> = const { Cell::new(false) };
}

fn note_allocation() {
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Arms the counter for the time loop; disarmed, it counts the distinct values of n at the end.
struct Arm {
    steps: usize,
    distinct_n: usize,
}
impl Observer for Arm {
    fn on_start(&mut self, _layout: &ModelLayout, _np: usize) {
        COUNT.with(|c| c.set(0));
        ARMED.with(|a| a.set(true));
    }
    fn on_step(&mut self, _info: &StepInfo, _p: &Posterior) {
        self.steps += 1;
    }
    fn on_finish(&mut self, last: &WeightedParticles<'_>) {
        ARMED.with(|a| a.set(false));
        self.distinct_n = last
            .distinct_sampled_params()
            .iter()
            .find(|(name, _)| name == "n")
            .expect("n is sampled")
            .1;
    }
}

fn spec() -> ChainSpec {
    let building = Building::new(vec![1.0; 3], vec![0], Damping::Storey).unwrap();
    let sensors = SensorLayout::new(3, &[1, 2, 3], MeasurementKind::Relative).unwrap();
    let rms = RmsLevels {
        acc: vec![2.0; 3],
        ug: 3.0,
        drift_velocity: vec![0.5],
    };
    let ug: Vec<f64> = (0..61).map(|k| 3.0 * (0.3 * k as f64).sin()).collect();
    ChainSpec::from_rms(0.005, building, sensors, ug, &rms, 0.1).unwrap()
}

/// Allocations in the time loop and distinct values of n at the end.
fn measure(
    filter: &mut dyn Filter,
    threshold: Option<f64>,
    move_: Option<LiuWest>,
) -> (u64, usize) {
    let ys: Vec<f64> = (0..60 * 3)
        .map(|i| 0.5 * ((i as f64) * 0.7).cos())
        .collect();
    let cfg = SmcConfig {
        particles: 37,
        resampling: ResamplePolicy {
            ess_threshold: threshold,
            ..ResamplePolicy::default()
        },
        rejuvenation: move_,
    };
    let mut arm = Arm {
        steps: 0,
        distinct_n: 0,
    };
    let mut rng = stream(1, 0, "alloc");
    let s = run(filter, &cfg, &ys, 3, &mut rng, &mut arm);
    assert!(s.failure.is_none(), "{:?}", s.failure);
    assert_eq!(arm.steps, 60);
    (COUNT.with(|c| c.get()), arm.distinct_n)
}

#[test]
fn steps_with_the_move_allocate_nothing() {
    let k = LiuWest::new(0.95).unwrap();
    for threshold in [None, Some(0.9)] {
        for lanes in [false, true] {
            let filters: [Box<dyn Fn() -> Box<dyn Filter>>; 2] = [
                Box::new(move || {
                    Box::new(MpfEkf2::with_lanes(MpfChain::new(spec()).unwrap(), lanes))
                }),
                Box::new(move || {
                    Box::new(MlnRbpf::with_lanes(MlnChain::new(spec()).unwrap(), lanes))
                }),
            ];
            for make in &filters {
                let (_, off) = measure(make().as_mut(), threshold, None);
                let (allocs, on) = measure(make().as_mut(), threshold, Some(k));
                assert_eq!(allocs, 0, "threshold {threshold:?}, lanes {lanes}");
                assert!(
                    on > off,
                    "n: {on} distinct values with the move, {off} without"
                );
            }
        }
    }
}
