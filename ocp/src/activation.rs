//! Activations `a(r)` of a residual `r` (Crocoddyl's `ActivationModel*`), with the gradient
//! `A_r = ∂a/∂r` and the diagonal of `A_rr = ∂²a/∂r²` (every activation here has a diagonal
//! Hessian).
//!
//! | activation | `a(r)` |
//! |---|---|
//! | `Quad` | `½ ‖r‖²` |
//! | `WeightedQuad { w }` | `½ Σ wᵢ rᵢ²` |
//! | `QuadBarrier { lb, ub }` | `½ Σ (max(rᵢ − ubᵢ, 0)² + min(rᵢ − lbᵢ, 0)²)` |
//! | `WeightedQuadBarrier { lb, ub, w }` | `½ Σ wᵢ (max(rᵢ − ubᵢ, 0)² + min(rᵢ − lbᵢ, 0)²)` |

use nalgebra::DVector;

/// An activation of a residual of length `nr`.
#[derive(Clone, Debug, PartialEq)]
pub enum Activation {
    /// `½ ‖r‖²`.
    Quad,
    /// `½ rᵀ diag(w) r`.
    WeightedQuad {
        /// The weights (length `nr`).
        w: DVector<f64>,
    },
    /// The quadratic barrier outside `[lb, ub]`.
    QuadBarrier {
        /// Lower bounds (`-inf` allowed).
        lb: DVector<f64>,
        /// Upper bounds (`inf` allowed).
        ub: DVector<f64>,
    },
    /// The weighted quadratic barrier outside `[lb, ub]`.
    WeightedQuadBarrier {
        /// Lower bounds.
        lb: DVector<f64>,
        /// Upper bounds.
        ub: DVector<f64>,
        /// The weights.
        w: DVector<f64>,
    },
}

impl Activation {
    /// The residual length this activation needs, if it fixes one.
    pub fn nr(&self) -> Option<usize> {
        match self {
            Activation::Quad => None,
            Activation::WeightedQuad { w } => Some(w.len()),
            Activation::QuadBarrier { lb, .. } | Activation::WeightedQuadBarrier { lb, .. } => {
                Some(lb.len())
            }
        }
    }
    /// Crocoddyl's name of the activation.
    pub fn name(&self) -> &'static str {
        match self {
            Activation::Quad => "ActivationModelQuad",
            Activation::WeightedQuad { .. } => "ActivationModelWeightedQuad",
            Activation::QuadBarrier { .. } => "ActivationModelQuadraticBarrier",
            Activation::WeightedQuadBarrier { .. } => "ActivationModelWeightedQuadraticBarrier",
        }
    }
    /// Checks the parameters (finite weights, `lb ≤ ub`, no NaN bounds) for a residual of
    /// length `nr`.
    pub(crate) fn check(&self, nr: usize) -> Result<(), String> {
        if let Some(n) = self.nr()
            && n != nr
        {
            return Err(format!("{}: {} entries for a residual of length {nr}", self.name(), n));
        }
        let w = match self {
            Activation::WeightedQuad { w } | Activation::WeightedQuadBarrier { w, .. } => Some(w),
            _ => None,
        };
        if let Some(w) = w
            && let Some(i) = w.iter().position(|x| !x.is_finite() || *x < 0.0)
        {
            return Err(format!("{}: weight {i} is {}", self.name(), w[i]));
        }
        if let Activation::QuadBarrier { lb, ub } | Activation::WeightedQuadBarrier { lb, ub, .. } =
            self
        {
            for i in 0..lb.len() {
                if lb[i].is_nan() || ub[i].is_nan() || lb[i] > ub[i] {
                    return Err(format!(
                        "{}: bounds [{}, {}] at row {i}",
                        self.name(),
                        lb[i],
                        ub[i]
                    ));
                }
            }
        }
        Ok(())
    }
    /// `a(r)`.
    pub fn value(&self, r: &DVector<f64>) -> f64 {
        match self {
            Activation::Quad => 0.5 * r.norm_squared(),
            Activation::WeightedQuad { w } => {
                0.5 * r.iter().zip(w.iter()).map(|(r, w)| w * r * r).sum::<f64>()
            }
            Activation::QuadBarrier { lb, ub } => {
                (0..r.len()).map(|i| 0.5 * barrier(r[i], lb[i], ub[i]).powi(2)).sum()
            }
            Activation::WeightedQuadBarrier { lb, ub, w } => {
                (0..r.len()).map(|i| 0.5 * w[i] * barrier(r[i], lb[i], ub[i]).powi(2)).sum()
            }
        }
    }
    /// `A_r` and the diagonal of `A_rr` at `r`.
    pub fn derivatives(&self, r: &DVector<f64>, ar: &mut DVector<f64>, arr: &mut DVector<f64>) {
        for i in 0..r.len() {
            let (g, h) = match self {
                Activation::Quad => (r[i], 1.0),
                Activation::WeightedQuad { w } => (w[i] * r[i], w[i]),
                Activation::QuadBarrier { lb, ub } => {
                    let b = barrier(r[i], lb[i], ub[i]);
                    (b, if b != 0.0 { 1.0 } else { 0.0 })
                }
                Activation::WeightedQuadBarrier { lb, ub, w } => {
                    let b = barrier(r[i], lb[i], ub[i]);
                    (w[i] * b, if b != 0.0 { w[i] } else { 0.0 })
                }
            };
            ar[i] = g;
            arr[i] = h;
        }
    }
}

/// `max(r − ub, 0) + min(r − lb, 0)`: the distance of `r` outside `[lb, ub]`, signed.
fn barrier(r: f64, lb: f64, ub: f64) -> f64 {
    if r > ub {
        r - ub
    } else if r < lb {
        r - lb
    } else {
        0.0
    }
}
