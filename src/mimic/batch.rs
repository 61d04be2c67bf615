//! Batched evaluation of the dynamics of a [`MimicModel`] over many states, in parallel.
//!
//! The counterparts of [`crate::batch::rnea_batch`], [`crate::batch::crba_batch`],
//! [`crate::batch::aba_batch`], [`crate::batch::id_derivatives_batch`],
//! [`crate::batch::fd_derivatives_batch`], [`crate::batch::id_so_derivatives_batch`] and
//! [`crate::batch::fd_so_derivatives_batch`] in the reduced coordinates: state `k` is given by
//! the `k`-th entries of the input slices (`q` of length [`MimicModel::nq`], the others of
//! length [`MimicModel::nv`]) and its result is written into entry `k` of the caller's output
//! slices, which must already have the reduced shapes (`nv`, `nv × nv`, or a
//! [`MimicSoData::new`] per state). The workspaces are a [`BatchData`] of one [`MimicData`] per
//! thread ([`batch_data`], [`batch_data_with_pool`]), run on a [`BatchPool`] as the batches of
//! the full [`Model`](crate::model::Model) are, with the same scheduling: each state is
//! computed by the single-state function of [`crate::mimic`] (no external forces), so the
//! results are bit for bit those of the sequential calls, whatever the number of threads.
//!
//! Errors are those of [`crate::batch`]: inconsistent slice lengths, output shapes and
//! workspaces made for another model are reported before anything is computed; otherwise the
//! error of the first failing state in index order, its variant kept and "state `k`" added to
//! its message.
//!
//! ```
//! use nalgebra::{DMatrix, DVector};
//! use sodyn::batch::BatchPool;
//! use sodyn::mimic::{MimicModel, batch};
//! use sodyn::model::UrdfOptions;
//! use sodyn::rng::Rng;
//! use std::sync::Arc;
//! let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf");
//! let opts = UrdfOptions { mimic: true, ..UrdfOptions::default() };
//! let m = MimicModel::load_urdf_file(&path, &opts)?;
//! let mut rng = Rng::new(1);
//! let qs: Vec<_> = (0..16).map(|_| m.random_configuration(&mut rng)).collect();
//! let vs = vec![DVector::from_element(m.nv(), 0.1); 16];
//! let taus = vec![DVector::zeros(m.nv()); 16];
//! let mut dq = vec![DMatrix::zeros(m.nv(), m.nv()); 16];
//! let mut dv = dq.clone();
//! let mut bd = batch::batch_data_with_pool(&m, Arc::new(BatchPool::new(2)?));
//! batch::fd_derivatives_batch(&m, &mut bd, &qs, &vs, &taus, &mut dq, &mut dv)?;
//! # Ok::<(), sodyn::Error>(())
//! ```

use super::{MimicData, MimicModel, MimicSoData};
use crate::batch::{
    BatchData, BatchPool, check_count, check_first_order, check_matrices, check_vectors, copy,
    drive,
};
use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

/// Workspaces for batched calls on `model` (one [`MimicData`] per thread), run on the shared
/// pool ([`BatchPool::shared`], one thread per core).
pub fn batch_data(model: &MimicModel) -> BatchData<MimicData> {
    batch_data_with_pool(model, BatchPool::shared())
}

/// Workspaces for batched calls on `model` (one [`MimicData`] per thread), run on `pool`.
pub fn batch_data_with_pool(model: &MimicModel, pool: Arc<BatchPool>) -> BatchData<MimicData> {
    BatchData::from_workspace(pool, MimicData::new(model))
}

/// Checks that the per-thread workspaces of `bd` were made for `model`.
fn check_workspaces(model: &MimicModel, bd: &BatchData<MimicData>) -> Result<()> {
    bd.workspaces().iter().try_for_each(|d| d.check(model))
}

/// Checks that every `out[k]` was made for `model`, naming `k`.
fn check_so_outputs(model: &MimicModel, out: &[MimicSoData]) -> Result<()> {
    for (k, so) in out.iter().enumerate() {
        so.check(model).map_err(|e| match e {
            Error::Workspace(s) => Error::Workspace(format!("out[{k}]: {s}")),
            e => e,
        })?;
    }
    Ok(())
}

/// Inverse dynamics ([`super::rnea`], no external forces) at every state:
/// `out_tau[k] = Gᵀ τ_full(expand(qs[k]), G vs[k], G as_[k])` (length `nv` each).
///
/// # Errors
/// See the [module documentation](self).
pub fn rnea_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_tau: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out_tau", out_tau.len(), n)?;
    check_vectors("out_tau", out_tau, model.nv)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out_tau, &mut vec![(); n], |data, k, out, _| {
        out.copy_from(super::rnea(model, data, &qs[k], &vs[k], &as_[k], None)?);
        Ok(())
    })
}

/// Mass matrix ([`super::crba`]) at every configuration: `out_m[k] = Gᵀ M_full(expand(qs[k])) G`
/// (`nv × nv` each).
///
/// # Errors
/// See the [module documentation](self).
pub fn crba_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    out_m: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("out_m", out_m.len(), n)?;
    check_matrices("out_m", out_m, model.nv)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out_m, &mut vec![(); n], |data, k, out, _| {
        copy(out, super::crba(model, data, &qs[k])?);
        Ok(())
    })
}

/// Forward dynamics ([`super::aba`], no external forces) at every state:
/// `out_qdd[k] = FD(qs[k], vs[k], taus[k])` (length `nv` each).
///
/// # Errors
/// See the [module documentation](self); a singular mass matrix is the error of its state.
pub fn aba_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_qdd: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out_qdd", out_qdd.len(), n)?;
    check_vectors("out_qdd", out_qdd, model.nv)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out_qdd, &mut vec![(); n], |data, k, out, _| {
        out.copy_from(super::aba(model, data, &qs[k], &vs[k], &taus[k], None)?);
        Ok(())
    })
}

/// First-order inverse-dynamics derivatives ([`super::id_derivatives`], no external forces) at
/// every state: `out_dq[k] = ∂τ/∂q`, `out_dv[k] = ∂τ/∂q̇` at `(qs[k], vs[k], as_[k])`
/// (`nv × nv` each, reduced tangent space).
///
/// # Errors
/// See the [module documentation](self).
pub fn id_derivatives_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_first_order([("vs", vs.len()), ("as_", as_.len())], out_dq, out_dv, n, model.nv)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out_dq, out_dv, |data, k, dq, dv| {
        super::id_derivatives(model, data, &qs[k], &vs[k], &as_[k], None)?;
        copy(dq, &data.dtau_dq);
        copy(dv, &data.dtau_dv);
        Ok(())
    })
}

/// First-order forward-dynamics derivatives ([`super::fd_derivatives`], no external forces) at
/// every state: `out_dq[k] = ∂q̈/∂q`, `out_dv[k] = ∂q̈/∂q̇` at `(qs[k], vs[k], taus[k])`
/// (`nv × nv` each, reduced tangent space).
///
/// # Errors
/// See the [module documentation](self); a singular mass matrix is the error of its state.
pub fn fd_derivatives_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_first_order([("vs", vs.len()), ("taus", taus.len())], out_dq, out_dv, n, model.nv)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out_dq, out_dv, |data, k, dq, dv| {
        super::fd_derivatives(model, data, &qs[k], &vs[k], &taus[k], None)?;
        copy(dq, &data.dqdd_dq);
        copy(dv, &data.dqdd_dv);
        Ok(())
    })
}

/// Second-order inverse-dynamics derivatives ([`super::id_so_derivatives`], no external
/// forces) at every state, written directly into `out[k]` (each made by
/// `MimicSoData::new(model)`): its `d2tau_dq2`, `d2tau_dv2`, `d2tau_dqdv`, `dm_dq`.
///
/// # Errors
/// See the [module documentation](self); an `out[k]` made for another model (naming `k`).
pub fn id_so_derivatives_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out: &mut [MimicSoData],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out", out.len(), n)?;
    check_so_outputs(model, out)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out, &mut vec![(); n], |data, k, so, _| {
        super::id_so_derivatives(model, data, so, &qs[k], &vs[k], &as_[k], None)
    })
}

/// Second-order forward-dynamics derivatives ([`super::fd_so_derivatives`], no external
/// forces) at every state, written directly into `out[k]` (each made by
/// `MimicSoData::new(model)`): its `d2qdd_dq2`, `d2qdd_dv2`, `d2qdd_dqdv`, `d2qdd_dtaudq`
/// (and the inverse-dynamics tensors at `(q, q̇, q̈)`).
///
/// # Errors
/// See the [module documentation](self); an `out[k]` made for another model (naming `k`); a
/// singular mass matrix is the error of its state.
pub fn fd_so_derivatives_batch(
    model: &MimicModel,
    bd: &mut BatchData<MimicData>,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out: &mut [MimicSoData],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out", out.len(), n)?;
    check_so_outputs(model, out)?;
    check_workspaces(model, bd)?;
    drive(bd, n, out, &mut vec![(); n], |data, k, so, _| {
        super::fd_so_derivatives(model, data, so, &qs[k], &vs[k], &taus[k], None)
    })
}
