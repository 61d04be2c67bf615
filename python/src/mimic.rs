//! Models loaded with `mimic=True`: the `sodyn::mimic` counterparts of the single-state and
//! batched functions, in the reduced coordinates.

use crate::batch::batch_call;
use crate::contacts::{
    PyContact, impact_dict, impact_dict_of, kkt_dict, kkt_dict_of, resolve, rows_of,
};
use crate::convert::{
    check_out, core_err, out_mat, out_tensor, out_vec, read_batch, read_fext, read_vec, write_out,
};
use crate::data::{ContactKey, PyData};
use nalgebra::{DMatrix, DVector};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use sodyn::Error;
use sodyn::batch::copy_output;
use sodyn::mimic::{
    self, MimicContractedData, MimicData, MimicImpactContracted, MimicImpactData,
    MimicKktContracted, MimicKktData, MimicModel, MimicSoData,
};
use sodyn::model::Model;

/// The workspaces of a model with mimic joints in a `Data`.
pub(crate) struct MimicWs {
    pub(crate) d: MimicData,
    pub(crate) so: Option<MimicSoData>,
    pub(crate) con: Option<MimicContractedData>,
    pub(crate) kkt: Option<(ContactKey, MimicKktData)>,
    pub(crate) impact: Option<(ContactKey, MimicImpactData)>,
    pub(crate) kktc: Option<(ContactKey, MimicKktData, MimicKktContracted)>,
    pub(crate) impc: Option<(ContactKey, MimicImpactData, MimicImpactContracted)>,
}

/// The mimic workspaces of `d`, an error if it was made for a model without mimic joints.
pub(crate) fn mimic_ws(d: &mut PyData) -> PyResult<&mut MimicWs> {
    d.mimic.as_deref_mut().ok_or_else(|| {
        core_err(Error::Workspace(
            "this Data was made for a model without mimic joints; make it with \
             model.create_data() of the model loaded with mimic=True"
                .into(),
        ))
    })
}

/// Reads `q` (reduced nq) and, if given, `v` and `x` (reduced nv) into the data's buffers.
pub(crate) fn mimic_read(
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'_, PyAny>,
    v: Option<&Bound<'_, PyAny>>,
    x: Option<(&Bound<'_, PyAny>, &str)>,
) -> PyResult<()> {
    read_vec(q, "q", mm.nq(), "nq (reduced coordinates: mimic joints excluded)", &mut d.q)?;
    if let Some(v) = v {
        read_vec(v, "v", mm.nv(), "nv (reduced coordinates)", &mut d.v)?;
    }
    if let Some((x, name)) = x {
        read_vec(x, name, mm.nv(), "nv (reduced coordinates)", &mut d.a)?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_rnea<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::rnea(mm, md, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.tau()))
}

pub(crate) fn mimic_crba<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, None)?;
    mimic_ws(d)?;
    let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    py.detach(|| mimic::crba(mm, md, q).map(|_| ())).map_err(core_err)?;
    Ok(out_mat(py, md.m()))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_aba<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::aba(mm, md, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.qdd()))
}

pub(crate) fn mimic_nle<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), None)?;
    mimic_ws(d)?;
    let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    py.detach(|| mimic::nonlinear_effects(mm, md, q, v, None).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.nle()))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_id_fo<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::id_derivatives(mm, md, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, md.dtau_dq()), out_mat(py, md.dtau_dv())])
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_fd_fo<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::fd_derivatives(mm, md, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, md.dqdd_dq()), out_mat(py, md.dqdd_dv()), out_mat(py, md.minv())])
}

/// `id_so_derivatives` (`fd = false`) or `fd_so_derivatives` (`fd = true`) of a mimic model.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
    fd: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, mm.nv())).transpose()?;
    mimic_read(mm, d, q, Some(v), Some((x, if fd { "tau" } else { "a" })))?;
    mimic_ws(d)?;
    let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, .. } = &mut **ws;
    let so = so.get_or_insert_with(|| MimicSoData::new(mm));
    let ts = if fd {
        py.detach(|| mimic::fd_so_derivatives(mm, md, so, q, v, a, None)).map_err(core_err)?;
        [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()]
    } else {
        py.detach(|| mimic::id_so_derivatives(mm, md, so, q, v, a, None)).map_err(core_err)?;
        [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()]
    };
    if let Some(out) = out {
        return write_out(out, ts);
    }
    PyTuple::new(py, ts.map(|t| out_tensor(py, t)))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_id_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_so(py, mm, d, q, v, a, out, false)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_fd_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_so(py, mm, d, q, v, tau, out, true)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_constrained_id<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    lam: &Bound<'py, PyAny>,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(lam, "lam", rows_of(&cs), "3 or 6 rows per contact", &mut d.lam)?;
    mimic_ws(d)?;
    let PyData { q, v, a, lam, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, kkt, .. } = &mut **ws;
    if kkt.as_ref().is_none_or(|(k, _)| *k != key) {
        *kkt = Some((key, MimicKktData::new(mm, &cs).map_err(core_err)?));
    }
    let kd = &mut kkt.as_mut().expect("set above").1;
    let out = PyDict::new(py);
    if order == 2 {
        let so = so.get_or_insert_with(|| MimicSoData::new(mm));
        py.detach(|| mimic::constrained_id_derivatives(mm, md, kd, Some(so), q, v, a, lam))
            .map_err(core_err)?;
        out.set_item("d2tau_dq2", out_tensor(py, so.d2tau_dq2()))?;
    } else {
        py.detach(|| mimic::constrained_id_derivatives(mm, md, kd, None, q, v, a, lam))
            .map_err(core_err)?;
    }
    out.set_item("tau", out_vec(py, md.tau()))?;
    out.set_item("dtau_dq", out_mat(py, md.dtau_dq()))?;
    out.set_item("dtau_dv", out_mat(py, md.dtau_dv()))?;
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_kkt<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let (cs, key) = resolve(full, contacts)?;
    mimic_ws(d)?;
    let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, kkt, .. } = &mut **ws;
    let fits =
        |k: &MimicKktData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if kkt.as_ref().is_none_or(|(k2, kd)| !fits(kd, k2)) {
        let mut kd = MimicKktData::new(mm, &cs).map_err(core_err)?;
        if order == 2 {
            kd = kd.with_second_order(mm);
        }
        *kkt = Some((key, kd));
    }
    let kd = &mut kkt.as_mut().expect("set above").1;
    if order == 2 {
        py.detach(|| mimic::kkt_so_derivatives(mm, md, kd, q, v, a)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::kkt_derivatives(mm, md, kd, q, v, a)).map_err(core_err)?;
    }
    kkt_dict_of!(py, kd, order)
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_impact<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    restitution: f64,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v_minus), None)?;
    let (cs, key) = resolve(full, contacts)?;
    mimic_ws(d)?;
    let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, impact, .. } = &mut **ws;
    let fits =
        |k: &MimicImpactData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if impact.as_ref().is_none_or(|(k2, im)| !fits(im, k2)) {
        let mut im = MimicImpactData::new(mm, &cs).map_err(core_err)?;
        if order == 2 {
            im = im.with_second_order(mm);
        }
        *impact = Some((key, im));
    }
    let im = &mut impact.as_mut().expect("set above").1;
    im.set_restitution(restitution).map_err(core_err)?;
    if order == 2 {
        py.detach(|| mimic::impact_so_derivatives(mm, md, im, q, v)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::impact_derivatives(mm, md, im, q, v)).map_err(core_err)?;
    }
    impact_dict_of!(py, im, order)
}

/// `id_so_contracted` (`fd = false`) or `fd_so_contracted` (`fd = true`) of a mimic model.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
    fd: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((x, if fd { "tau" } else { "a" })))?;
    read_vec(w, "w", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    mimic_ws(d)?;
    let PyData { q, v, a, w, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, con, .. } = &mut **ws;
    let c = con.get_or_insert_with(|| MimicContractedData::new(mm));
    if fd {
        py.detach(|| mimic::fd_so_contracted(mm, md, c, q, v, a, w)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::id_so_contracted(mm, md, c, q, v, a, w)).map_err(core_err)?;
    }
    let last = if fd { c.c_tauq() } else { c.c_mq() };
    PyTuple::new(
        py,
        [out_mat(py, c.c_qq()), out_mat(py, c.c_vv()), out_mat(py, c.c_qv()), out_mat(py, last)],
    )
}

/// `idfoza` of a mimic model: `∂(M x)/∂q` in the reduced coordinates.
pub(crate) fn mimic_idfoza<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, Some((x, "x")))?;
    mimic_ws(d)?;
    let PyData { q, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    let mut out = DMatrix::zeros(mm.nv(), mm.nv());
    py.detach(|| mimic::idfoza(mm, md, q, a, &mut out)).map_err(core_err)?;
    Ok(out_mat(py, &out))
}

/// `idsoza` of a mimic model: `∂²(M x)/∂q²` in the reduced coordinates.
pub(crate) fn mimic_idsoza<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, Some((x, "x")))?;
    mimic_ws(d)?;
    let PyData { q, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, .. } = &mut **ws;
    let so = so.get_or_insert_with(|| MimicSoData::new(mm));
    py.detach(|| mimic::idsoza(mm, md, so, q, a).map(|_| ())).map_err(core_err)?;
    Ok(out_tensor(py, so.d2tau_dq2()))
}

/// `kkt_so_contracted` of a mimic model.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_kkt_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    w_qdd: &Bound<'py, PyAny>,
    w_lambda: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(w_qdd, "w_qdd", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    read_vec(w_lambda, "w_lambda", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    mimic_ws(d)?;
    let PyData { q, v, a, w, wl, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, kktc, .. } = &mut **ws;
    if kktc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let kd = MimicKktData::new(mm, &cs).map_err(core_err)?;
        let kc = MimicKktContracted::new(mm, &kd);
        *kktc = Some((key, kd, kc));
    }
    let (_, kd, kc) = kktc.as_mut().expect("set above");
    py.detach(|| mimic::kkt_so_contracted(mm, md, kd, kc, q, v, a, w, wl)).map_err(core_err)?;
    PyTuple::new(
        py,
        [
            out_mat(py, kc.c_qq()),
            out_mat(py, kc.c_vv()),
            out_mat(py, kc.c_qv()),
            out_mat(py, kc.c_tauq()),
        ],
    )
}

/// `impact_so_contracted` of a mimic model.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_impact_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    w_vplus: &Bound<'py, PyAny>,
    w_impulse: &Bound<'py, PyAny>,
    restitution: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v_minus), None)?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(w_vplus, "w_vplus", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    read_vec(w_impulse, "w_impulse", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    mimic_ws(d)?;
    let PyData { q, v, w, wl, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, impc, .. } = &mut **ws;
    if impc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let im = MimicImpactData::new(mm, &cs).map_err(core_err)?;
        let ic = MimicImpactContracted::new(mm, &im);
        *impc = Some((key, im, ic));
    }
    let (_, im, ic) = impc.as_mut().expect("set above");
    im.set_restitution(restitution).map_err(core_err)?;
    py.detach(|| mimic::impact_so_contracted(mm, md, im, ic, q, v, w, wl)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, ic.c_qq()), out_mat(py, ic.c_qvminus())])
}

/// The batched functions of a model loaded with `mimic=True`.
#[derive(Clone, Copy)]
pub(crate) enum MimicBatch {
    Rnea,
    Aba,
    Nle,
    Crba,
    IdFo,
    FdFo,
    IdSo,
    FdSo,
}

/// A batched call on a mimic model in the reduced coordinates (`q`: `(N, nq)`; `v` and `x`,
/// `a` or `tau`: `(N, nv)`): the single-state functions of `sodyn::mimic` on the pool, one
/// `MimicData` (and `MimicSoData`) per thread, as `sodyn::mimic::batch` runs them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mimic_batch<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    threads: Option<i64>,
    which: MimicBatch,
    q: &Bound<'py, PyAny>,
    v: Option<&Bound<'py, PyAny>>,
    x: Option<(&Bound<'py, PyAny>, &str)>,
) -> PyResult<Bound<'py, PyAny>> {
    let qs = read_batch(q, "q", mm.nq(), "nq (reduced coordinates: mimic joints excluded)", None)?;
    let n = qs.count;
    let mut ins = vec![qs];
    if let Some(v) = v {
        ins.push(read_batch(v, "v", mm.nv(), "nv (reduced coordinates)", Some(n))?);
    }
    if let Some((x, name)) = x {
        ins.push(read_batch(x, name, mm.nv(), "nv (reduced coordinates)", Some(n))?);
    }
    let nv = mm.nv();
    let (vec_, mat, ten) = (&[nv][..], &[nv, nv][..], &[nv, nv, nv][..]);
    let so = matches!(which, MimicBatch::IdSo | MimicBatch::FdSo).then(|| MimicSoData::new(mm));
    // The thread's workspaces and a zero acceleration (the nonlinear effects).
    let ws = (MimicData::new(mm), so, DVector::zeros(nv));
    match which {
        MimicBatch::Rnea => batch_call(py, threads, ws, &ins, 1, vec_, |(d, ..), st, o| {
            copy_output(o[0], mimic::rnea(mm, d, &st[0], &st[1], &st[2], None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Aba => batch_call(py, threads, ws, &ins, 1, vec_, |(d, ..), st, o| {
            copy_output(o[0], mimic::aba(mm, d, &st[0], &st[1], &st[2], None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Nle => batch_call(py, threads, ws, &ins, 1, vec_, |(d, _, z), st, o| {
            copy_output(o[0], mimic::rnea(mm, d, &st[0], &st[1], z, None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Crba => batch_call(py, threads, ws, &ins, 1, mat, |(d, ..), st, o| {
            copy_output(o[0], mimic::crba(mm, d, &st[0])?.as_slice());
            Ok(())
        }),
        MimicBatch::IdFo => batch_call(py, threads, ws, &ins, 2, mat, |(d, ..), st, o| {
            mimic::id_derivatives(mm, d, &st[0], &st[1], &st[2], None)?;
            copy_output(o[0], d.dtau_dq().as_slice());
            copy_output(o[1], d.dtau_dv().as_slice());
            Ok(())
        }),
        MimicBatch::FdFo => batch_call(py, threads, ws, &ins, 3, mat, |(d, ..), st, o| {
            mimic::fd_derivatives(mm, d, &st[0], &st[1], &st[2], None)?;
            for (dst, src) in o.iter_mut().zip([d.dqdd_dq(), d.dqdd_dv(), d.minv()]) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
        MimicBatch::IdSo => batch_call(py, threads, ws, &ins, 4, ten, |(d, so, _), st, o| {
            let so = so.as_mut().expect("made for the second order");
            mimic::id_so_derivatives(mm, d, so, &st[0], &st[1], &st[2], None)?;
            let ts = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
            for (dst, src) in o.iter_mut().zip(ts) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
        MimicBatch::FdSo => batch_call(py, threads, ws, &ins, 4, ten, |(d, so, _), st, o| {
            let so = so.as_mut().expect("made for the second order");
            mimic::fd_so_derivatives(mm, d, so, &st[0], &st[1], &st[2], None)?;
            let ts = [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()];
            for (dst, src) in o.iter_mut().zip(ts) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
    }
}
