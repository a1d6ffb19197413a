//! After set-up, a particle filter `step` allocates nothing (STYLE lesson 4): a counting global
//! allocator counts the allocations made by this thread while 50 steps run.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::{Linked, StaticOnly};
use core_filters::particle::bootstrap::BootstrapPf;
use core_filters::particle::mlnrbpf::MlnRbpf;
use core_filters::particle::storvik::{Storvik, StorvikUpdate};
use core_filters::particle::{ParticleConfig, ParticleFilter};
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::stream;
use nalgebra::{SVector, Vector2};

struct Counting;

thread_local! {
    /// Allocations counted on this thread while `ARMED` is set (other test threads never count).
    static COUNT: Cell<u64> = const { Cell::new(0) };
    static ARMED: Cell<bool> = const { Cell::new(false) };
}

fn note_allocation() {
    // `try_with` keeps the allocator usable while thread-locals are torn down.
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

/// Initialises `filter`, then counts the allocations of 50 steps.
fn allocations_in_steps<const NY: usize, F: ParticleFilter<NY>>(
    filter: &mut F,
    ys: &[SVector<f64, NY>],
) -> u64 {
    assert_eq!(ys.len(), 50);
    let mut rng = stream(4, 0, "no-alloc");
    filter.initialise(&mut rng);
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let mut ok = 0;
    for (i, y) in ys.iter().enumerate() {
        if filter.step(i + 1, y, &mut rng).is_err() {
            break;
        }
        ok += 1;
    }
    ARMED.with(|a| a.set(false));
    // A failed step could skip the work whose allocations we count.
    assert_eq!(ok, ys.len(), "{} failed at step {}", filter.name(), ok + 1);
    COUNT.with(|c| c.get())
}

#[test]
fn steps_allocate_nothing_after_set_up() {
    // The counter must see allocations at all, or a zero below would prove nothing.
    ARMED.with(|a| a.set(true));
    let v = std::hint::black_box(vec![1u8; 16]);
    ARMED.with(|a| a.set(false));
    drop(v);
    assert_eq!(COUNT.with(|c| c.get()), 1);

    let linked = Linked {
        a: 0.8,
        b: 0.5,
        c: 1.0,
        d: 0.4,
        q_sd: 0.3,
        r_sd: 0.5,
        u0_mean: 0.0,
        u0_sd: 0.5,
        z_mean: 1.0,
        z_sd: 0.5,
    };
    let ys = linked.simulate(1.3, 50, &mut stream(4, 0, "data"));
    let mut policies = vec![ResamplePolicy::default()];
    for scheme in Scheme::ALL {
        policies.push(ResamplePolicy {
            scheme,
            ess_threshold: Some(0.5),
        });
    }
    for resampling in policies {
        let cfg = ParticleConfig {
            particles: 200,
            resampling,
        };
        let n = allocations_in_steps(&mut BootstrapPf::new(linked, cfg), &ys);
        assert_eq!(n, 0, "bootstrap {resampling:?}");
        let n = allocations_in_steps(&mut MlnRbpf::new(linked, cfg), &ys);
        assert_eq!(n, 0, "mln-rbpf {resampling:?}");
        for update in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
            let n = allocations_in_steps(&mut Storvik::with_update(linked, cfg, update), &ys);
            assert_eq!(n, 0, "storvik {update:?} {resampling:?}");
        }
        let so = StaticOnly::example();
        let ys2 = so.simulate(Vector2::new(1.5, -1.0), 50, &mut stream(4, 1, "data"));
        let n = allocations_in_steps(&mut MlnRbpf::new(so, cfg), &ys2);
        assert_eq!(n, 0, "mln-rbpf static {resampling:?}");
    }
}
