//! `MpfEkf2::step` allocates nothing after set-up (STYLE lesson 4): a counting global allocator
//! counts the allocations made by this thread while steps run, on the paper-sized chain of
//! SPEC §6 (NN = 3, ND = 2, NBL = 13, NY = 3), for every resampling scheme and both kernels.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use core_filters::particle::mpf::{MpfEkf2, MpfKernel};
use core_filters::particle::{ParticleConfig, ParticleFilter};
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::stream;

#[allow(dead_code)]
#[path = "../benches/mpf.rs"]
mod bench;

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    // Only this thread's allocations are counted: the test harness may allocate elsewhere.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

fn note() {
    if COUNTING.with(|c| c.get()) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f` on this thread.
fn allocations_in(f: impl FnOnce()) -> u64 {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

#[test]
fn step_does_not_allocate() {
    // The counter itself must work, or the zero below proves nothing.
    assert!(allocations_in(|| drop(std::hint::black_box(vec![1u8; 16]))) >= 1);

    let (model, ys) = bench::chain::dataset(60, 3);
    for scheme in Scheme::ALL {
        for kernel in [MpfKernel::Sparse, MpfKernel::Dense] {
            let config = ParticleConfig {
                particles: 64,
                resampling: ResamplePolicy {
                    scheme,
                    ess_threshold: None,
                },
            };
            let mut f = MpfEkf2::new(model.clone(), config).with_kernel(kernel);
            let mut rng = stream(9, 0, "filter/mpf-ekf2");
            f.initialise(&mut rng);
            f.step(1, &ys[0], &mut rng).expect("step 1");
            let mut resampled = 0;
            let n = allocations_in(|| {
                for k in 2..=ys.len() {
                    let info = f.step(k, &ys[k - 1], &mut rng).expect("step");
                    resampled += usize::from(info.resampled);
                }
            });
            assert_eq!(n, 0, "{scheme:?} {kernel:?}: {n} allocations in step");
            assert_eq!(resampled, ys.len() - 1, "resampling was exercised");
        }
    }
}
