//! After set-up, a run's steps allocate nothing (STYLE lesson 4): a counting global allocator
//! counts the allocations made by this thread between the runner's first and last observer
//! calls (the time loop: resampling, the filter's step, weights, posterior summaries).

mod smc_common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use core_filters::model::Layout as ModelLayout;
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::stream;
use core_filters::smc::bootstrap::BootstrapPf;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::runner::WeightedParticles;
use core_filters::smc::storvik::{Storvik, StorvikUpdate};
use core_filters::smc::{run, Filter, Observer, Posterior, SmcConfig, StepInfo};
use nalgebra::Vector2;
use smc_common::{Linked, StaticOnly};

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

/// Arms the counter when the time loop starts and disarms it when it ends; counts steps.
struct Arm(usize);
impl Observer for Arm {
    fn on_start(&mut self, _layout: &ModelLayout, _np: usize) {
        COUNT.with(|c| c.set(0));
        ARMED.with(|a| a.set(true));
    }
    fn on_step(&mut self, _info: &StepInfo, _p: &Posterior) {
        self.0 += 1;
    }
    fn on_finish(&mut self, _last: &WeightedParticles<'_>) {
        ARMED.with(|a| a.set(false));
    }
}

fn allocations(filter: &mut dyn Filter, ys: &[f64], ny: usize, threshold: Option<f64>) -> u64 {
    for scheme in [Scheme::Systematic, Scheme::Residual] {
        let cfg = SmcConfig {
            particles: 37,
            resampling: ResamplePolicy {
                scheme,
                ess_threshold: threshold,
            },
            rejuvenation: None,
        };
        let mut arm = Arm(0);
        let s = run(filter, &cfg, ys, ny, &mut stream(1, 0, "alloc"), &mut arm);
        assert!(s.failure.is_none());
        assert_eq!(arm.0, ys.len() / ny);
        let n = COUNT.with(|c| c.get());
        if n > 0 {
            return n;
        }
    }
    0
}

#[test]
fn steps_allocate_nothing() {
    let linked = Linked::example();
    let ys = linked.simulate(1.3, 50, &mut stream(2, 0, "data"));
    let st = StaticOnly::example();
    let ys2 = st.simulate(Vector2::new(0.3, 1.0), 50, &mut stream(3, 0, "data"));
    for threshold in [None, Some(0.6)] {
        for lanes in [false, true] {
            assert_eq!(
                allocations(
                    &mut MlnRbpf::with_lanes(linked.clone(), lanes),
                    &ys,
                    1,
                    threshold
                ),
                0
            );
            assert_eq!(
                allocations(
                    &mut MlnRbpf::with_lanes(st.clone(), lanes),
                    &ys2,
                    2,
                    threshold
                ),
                0
            );
            for u in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
                assert_eq!(
                    allocations(
                        &mut Storvik::with_lanes(linked.clone(), u, lanes),
                        &ys,
                        1,
                        threshold
                    ),
                    0
                );
            }
        }
        assert_eq!(
            allocations(&mut BootstrapPf::new(linked.augmented()), &ys, 1, threshold),
            0
        );
    }
}
