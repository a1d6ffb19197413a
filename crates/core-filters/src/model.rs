//! The vocabulary every model and filter shares: where a named quantity lives ([`Slot`],
//! [`Layout`]) and constant Hessians as sparse entry lists ([`SparseHessians`]). The capability
//! traits a model implements are in [`crate::smc::model`].

/// Where a named quantity (a parameter of θ or a physical state) lives in a filter's
/// representation: an entry of the sampled (particle) vector or of the marginalised Gaussian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Entry `i` of the sampled vector (averaged over particles).
    Sampled(usize),
    /// Entry `i` of the marginalised Gaussian (mixture of per-particle Gaussians).
    Marginal(usize),
}

/// Names and slots of the parameters θ and the physical states, in the model's order.
/// Filters use it to report posterior means and standard deviations by name.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub param_names: Vec<String>,
    pub params: Vec<Slot>,
    pub state_names: Vec<String>,
    pub states: Vec<Slot>,
}

/// One non-zero second derivative `∂²f_output / ∂x_a ∂x_b = value`.
///
/// Symmetric pairs are listed once: an entry with `a != b` stands for both `(a, b)` and `(b, a)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HessianEntry {
    pub output: usize,
    pub a: usize,
    pub b: usize,
    pub value: f64,
}

/// The Hessians of a vector-valued map as a sparse entry list (SPEC §4: never dense n×n×n).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SparseHessians {
    entries: Vec<HessianEntry>,
}

impl SparseHessians {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `∂²f_output/∂x_a∂x_b = value` (and its symmetric twin when `a != b`).
    pub fn push(&mut self, output: usize, a: usize, b: usize, value: f64) {
        self.entries.push(HessianEntry {
            output,
            a,
            b,
            value,
        });
    }

    /// The entries, each symmetric pair listed once.
    pub fn entries(&self) -> &[HessianEntry] {
        &self.entries
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The dense Hessian of component `output` (n×n), for tests and diagnostics only.
    pub fn dense(&self, output: usize, n: usize) -> nalgebra::DMatrix<f64> {
        let mut h = nalgebra::DMatrix::zeros(n, n);
        for e in self.entries.iter().filter(|e| e.output == output) {
            h[(e.a, e.b)] += e.value;
            if e.a != e.b {
                h[(e.b, e.a)] += e.value;
            }
        }
        h
    }
}
