//! XLA FFI handlers of `sodyn.jax`: RNEA, ABA and the nonlinear effects (value, first-order
//! Jacobians, dense second order) and CRBA (value, `dM/dq`) as typed-FFI custom calls, so that
//! a jitted `sodyn.jax` function runs sodyn without entering Python.
//!
//! The handlers follow the C ABI of XLA's typed FFI (`xla/ffi/api/c_api.h`, API 0.x, shipped
//! with jaxlib): `XLA_FFI_Error* handler(XLA_FFI_CallFrame*)`. The few structures they read are
//! declared below with the header's layout. Every handler
//!
//! * answers the metadata query (a call frame carrying the metadata extension) with the API
//!   version it was written against and no traits;
//! * returns success without work for the instantiate, prepare and initialize stages;
//! * at the execute stage checks every argument (count, buffer type, `F64`, rank, the trailing
//!   dimension `nq` / `nv`, the same leading dimensions for all) and every result (count,
//!   `F64`, dimensions) before reading or writing memory, and the `model` attribute (an `S64`
//!   handle of this module's registry): a wrong call is an XLA error naming what is wrong,
//!   never an out-of-bounds access;
//! * runs one state on a workspace kept per model, several (the leading dimensions of a
//!   `jax.vmap` with `vmap_method="broadcast_all"`) on sodyn's shared batch pool, exactly as
//!   `sodyn.batch` does, so the results are bit for bit those of the direct calls.
//!
//! Outputs are written row-major (XLA's default layout): `J[..., i, j]` at `i * n + j`,
//! `T[..., i, j, k]` at `(i * n + j) * n + k`, from sodyn's column-major storage.
//!
//! Models reach the handlers through a registry of snapshots: `_jax_ffi_model(model)` clones
//! the model once and returns its handle (never reused); `Model.gravity = ...` replaces the
//! snapshot, and dropping the Python `Model` removes it (a compiled function that still names
//! the handle then gets an XLA error, not a dangling model).

use nalgebra::{DMatrix, DVector};
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyDict};
use sodyn::algo::{self, Data};
use sodyn::batch::{BatchData, BatchPool, map_states};
use sodyn::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use sodyn::model::Model;
use sodyn::tensor::Tensor3;
use std::collections::HashMap;
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, RwLock};

// ---------------------------------------------------------------------------------------------
// The C ABI (declarations of `xla/ffi/api/c_api.h`, API version 0.3)

/// The FFI API version these declarations follow (`XLA_FFI_API_MAJOR`, `XLA_FFI_API_MINOR`).
const API_MAJOR: c_int = 0;
const API_MINOR: c_int = 3;

const EXTENSION_METADATA: c_int = 1;
const STAGE_EXECUTE: c_int = 3;
const ERROR_INVALID_ARGUMENT: c_int = 3;
const ERROR_INTERNAL: c_int = 13;
const DTYPE_S64: c_int = 5;
const DTYPE_F64: c_int = 12;
const ARG_BUFFER: c_int = 1;
const RET_BUFFER: c_int = 1;
const ATTR_SCALAR: c_int = 3;

/// `XLA_FFI_Error` (opaque).
#[repr(C)]
pub(crate) struct XlaError {
    _private: [u8; 0],
}

#[repr(C)]
struct ExtensionBase {
    struct_size: usize,
    kind: c_int,
    next: *mut ExtensionBase,
}

#[repr(C)]
struct ApiVersion {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    major_version: c_int,
    minor_version: c_int,
}

#[repr(C)]
struct ErrorCreateArgs {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    message: *const c_char,
    errc: c_int,
}

/// The leading fields of `XLA_FFI_Api`, up to the one function used here.
#[repr(C)]
struct Api {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    api_version: ApiVersion,
    internal_api: *const c_void,
    error_create: Option<unsafe extern "C" fn(*mut ErrorCreateArgs) -> *mut XlaError>,
}

#[repr(C)]
struct Buffer {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    dtype: c_int,
    data: *mut c_void,
    rank: i64,
    dims: *const i64,
}

#[repr(C)]
struct ByteSpan {
    ptr: *const c_char,
    len: usize,
}

#[repr(C)]
struct Scalar {
    dtype: c_int,
    value: *const c_void,
}

/// `XLA_FFI_Args` and `XLA_FFI_Rets` (same layout).
#[repr(C)]
struct List {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    size: i64,
    types: *const c_int,
    items: *const *mut c_void,
}

#[repr(C)]
struct Attrs {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    size: i64,
    types: *const c_int,
    names: *const *const ByteSpan,
    attrs: *const *const c_void,
}

#[repr(C)]
pub(crate) struct CallFrame {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    api: *const Api,
    ctx: *mut c_void,
    stage: c_int,
    args: List,
    rets: List,
    attrs: Attrs,
    future: *mut c_void,
}

#[repr(C)]
struct Metadata {
    struct_size: usize,
    api_version: ApiVersion,
    traits: u32,
    state_type_id: i64,
}

#[repr(C)]
struct MetadataExtension {
    extension_base: ExtensionBase,
    metadata: *mut Metadata,
}

/// `XLA_FFI_STRUCT_SIZE(type, last_field)`: the offset of the last field plus its size.
macro_rules! struct_size {
    ($t:ty, $f:ident, $ft:ty) => {
        std::mem::offset_of!($t, $f) + std::mem::size_of::<$ft>()
    };
}
const CALL_FRAME_SIZE: usize = struct_size!(CallFrame, attrs, Attrs);
const METADATA_SIZE: usize = struct_size!(Metadata, traits, u32);
const METADATA_FULL_SIZE: usize = std::mem::size_of::<Metadata>();
const METADATA_EXTENSION_SIZE: usize = struct_size!(MetadataExtension, metadata, *mut Metadata);
const ERROR_CREATE_ARGS_SIZE: usize = struct_size!(ErrorCreateArgs, errc, c_int);
const API_VERSION_SIZE: usize = struct_size!(ApiVersion, minor_version, c_int);
const API_MIN_SIZE: usize = struct_size!(
    Api,
    error_create,
    Option<unsafe extern "C" fn(*mut ErrorCreateArgs) -> *mut XlaError>
);

// ---------------------------------------------------------------------------------------------
// The model registry

/// One state's workspace: sodyn's `Data` (its second-order capacity added on first use) and
/// the three input vectors.
#[derive(Clone)]
struct Ws {
    d: Data,
    x: [DVector<f64>; 3],
}

impl Ws {
    fn new(m: &Model) -> Self {
        Self {
            d: Data::new(m),
            x: [DVector::zeros(m.nq()), DVector::zeros(m.nv()), DVector::zeros(m.nv())],
        }
    }
}

/// A registered model: its snapshot, spare single-state workspaces and a batch workspace.
struct Entry {
    model: Model,
    spare: Mutex<Vec<Ws>>,
    batch: Mutex<Option<BatchData<Ws>>>,
}

impl Entry {
    fn new(model: Model) -> Arc<Self> {
        Arc::new(Self { model, spare: Mutex::new(Vec::new()), batch: Mutex::new(None) })
    }
}

fn registry() -> &'static RwLock<HashMap<u64, Arc<Entry>>> {
    static R: OnceLock<RwLock<HashMap<u64, Arc<Entry>>>> = OnceLock::new();
    R.get_or_init(Default::default)
}

fn lookup(handle: i64) -> Option<Arc<Entry>> {
    let r = registry().read().unwrap_or_else(|e| e.into_inner());
    u64::try_from(handle).ok().and_then(|h| r.get(&h).cloned())
}

/// The registry handle of a Python `Model` (none until `sodyn.jax` first needs it); dropping
/// it removes the snapshot.
#[derive(Default)]
pub(crate) struct Link(OnceLock<u64>);

impl Link {
    /// The model's handle, registering a snapshot of `m` on first use.
    pub(crate) fn handle(&self, m: &Model) -> u64 {
        *self.0.get_or_init(|| {
            static NEXT: AtomicU64 = AtomicU64::new(1);
            let h = NEXT.fetch_add(1, Ordering::Relaxed);
            registry().write().unwrap_or_else(|e| e.into_inner()).insert(h, Entry::new(m.clone()));
            h
        })
    }

    /// Replaces the snapshot after a change of the model (its gravity).
    pub(crate) fn changed(&self, m: &Model) {
        if let Some(h) = self.0.get() {
            registry().write().unwrap_or_else(|e| e.into_inner()).insert(*h, Entry::new(m.clone()));
        }
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        if let Some(h) = self.0.get() {
            registry().write().unwrap_or_else(|e| e.into_inner()).remove(h);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The functions

#[derive(Clone, Copy, PartialEq, Eq)]
enum Func {
    Rnea,
    Aba,
    /// `nonlinear_effects(q, v)`: RNEA at `a = 0`.
    Nle,
    /// `crba(q)`: value and first order (`dM/dq` from `id_so_derivatives` at `v = a = 0`).
    Crba,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Order {
    /// The value (`tau`, `qdd`, `b` or `M`).
    Value,
    /// The value and its Jacobian blocks (one per argument).
    First,
    /// The dense second-order tensors of `id_so_derivatives` / `fd_so_derivatives` (the
    /// first three at `a = 0` for `Nle`; none for `Crba`).
    Second,
}

impl Func {
    fn name(self) -> &'static str {
        match self {
            Func::Rnea => "sodyn.jax.rnea",
            Func::Aba => "sodyn.jax.aba",
            Func::Nle => "sodyn.jax.nonlinear_effects",
            Func::Crba => "sodyn.jax.crba",
        }
    }
    fn arg_names(self) -> &'static [&'static str] {
        match self {
            Func::Rnea => &["q", "v", "a"],
            Func::Aba => &["q", "v", "tau"],
            Func::Nle => &["q", "v"],
            Func::Crba => &["q"],
        }
    }
    /// The per-state result shapes: the rank of each (every dimension is `nv`).
    fn ret_ranks(self, order: Order) -> &'static [usize] {
        match (self, order) {
            (Func::Rnea | Func::Aba, Order::Value) | (Func::Nle, Order::Value) => &[1],
            (Func::Rnea | Func::Aba, Order::First) => &[1, 2, 2, 2],
            (Func::Rnea | Func::Aba, Order::Second) => &[3, 3, 3, 3],
            (Func::Nle, Order::First) => &[1, 2, 2],
            (Func::Nle, Order::Second) => &[3, 3, 3],
            (Func::Crba, Order::Value) => &[2],
            (Func::Crba, Order::First) => &[2, 3],
            (Func::Crba, Order::Second) => &[],
        }
    }
}

impl Order {
    fn what(self) -> &'static str {
        match self {
            Order::Value => "value",
            Order::First => "first order",
            Order::Second => "second order",
        }
    }
}

/// Copies a column-major `n × n` matrix into a row-major block.
fn write_matrix(dst: &mut [f64], src: &DMatrix<f64>) {
    let n = src.nrows();
    for (i, row) in dst.chunks_exact_mut(n.max(1)).enumerate().take(n) {
        for (j, x) in row.iter_mut().enumerate() {
            *x = src[(i, j)];
        }
    }
}

/// Copies a column-major `n × n × n` tensor into a row-major block.
fn write_tensor(dst: &mut [f64], src: &Tensor3) {
    let (a, b, c) = src.dims();
    let s = src.as_slice();
    let mut o = 0;
    for i in 0..a {
        for j in 0..b {
            for k in 0..c {
                dst[o] = s[i + a * (j + b * k)];
                o += 1;
            }
        }
    }
}

/// One state: the inputs are in `w.x` (zeros after the function's arguments), the results go
/// to `out` (one row-major block each).
fn run_state(
    f: Func,
    order: Order,
    m: &Model,
    w: &mut Ws,
    out: &mut [&mut [f64]],
) -> sodyn::Result<()> {
    let Ws { d, x: [q, v, x] } = w;
    match (f, order) {
        (Func::Rnea, Order::Value) => {
            out[0].copy_from_slice(algo::rnea(m, d, q, v, x, None)?.as_slice())
        }
        (Func::Aba, Order::Value) => {
            out[0].copy_from_slice(algo::aba(m, d, q, v, x, None)?.as_slice())
        }
        (Func::Rnea, Order::First) => {
            out[0].copy_from_slice(algo::rnea(m, d, q, v, x, None)?.as_slice());
            id_derivatives(m, d, q, v, x, None)?;
            write_matrix(out[1], d.dtau_dq());
            write_matrix(out[2], d.dtau_dv());
            write_matrix(out[3], algo::crba(m, d, q)?);
        }
        (Func::Aba, Order::First) => {
            out[0].copy_from_slice(algo::aba(m, d, q, v, x, None)?.as_slice());
            fd_derivatives(m, d, q, v, x, None)?;
            write_matrix(out[1], d.dqdd_dq());
            write_matrix(out[2], d.dqdd_dv());
            write_matrix(out[3], d.minv());
        }
        (Func::Rnea, Order::Second) => {
            d.reserve_second_order(m)?;
            let so = id_so_derivatives(m, d, q, v, x, None)?;
            let ts = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
            for (dst, t) in out.iter_mut().zip(ts) {
                write_tensor(dst, t);
            }
        }
        (Func::Aba, Order::Second) => {
            d.reserve_second_order(m)?;
            let fso = fd_so_derivatives(m, d, q, v, x, None)?;
            let ts = [fso.d2qdd_dq2(), fso.d2qdd_dv2(), fso.d2qdd_dqdv(), fso.d2qdd_dtaudq()];
            for (dst, t) in out.iter_mut().zip(ts) {
                write_tensor(dst, t);
            }
        }
        (Func::Nle, Order::Value) => {
            out[0].copy_from_slice(algo::nonlinear_effects(m, d, q, v)?.as_slice())
        }
        (Func::Nle, Order::First) => {
            out[0].copy_from_slice(algo::nonlinear_effects(m, d, q, v)?.as_slice());
            id_derivatives(m, d, q, v, x, None)?;
            write_matrix(out[1], d.dtau_dq());
            write_matrix(out[2], d.dtau_dv());
        }
        (Func::Nle, Order::Second) => {
            d.reserve_second_order(m)?;
            let so = id_so_derivatives(m, d, q, v, x, None)?;
            for (dst, t) in out.iter_mut().zip([so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv()]) {
                write_tensor(dst, t);
            }
        }
        (Func::Crba, Order::Value) => write_matrix(out[0], algo::crba(m, d, q)?),
        (Func::Crba, Order::First) => {
            write_matrix(out[0], algo::crba(m, d, q)?);
            d.reserve_second_order(m)?;
            let so = id_so_derivatives(m, d, q, v, x, None)?;
            write_tensor(out[1], so.dm_dq());
        }
        (Func::Crba, Order::Second) => {}
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Decoding the call frame

/// An error of a call: its code and message.
struct Fail(c_int, String);

fn invalid(msg: String) -> Fail {
    Fail(ERROR_INVALID_ARGUMENT, msg)
}

/// The `model` attribute: an `S64` scalar.
///
/// # Safety
/// `a` is the attributes of a call frame given by XLA (sizes and pointers consistent).
unsafe fn model_attr(a: &Attrs, fname: &str) -> Result<i64, Fail> {
    for i in 0..usize::try_from(a.size).unwrap_or(0) {
        // SAFETY: `i < size`, and XLA gives `size` names, types and attributes.
        let (name, kind, attr) = unsafe { (&**a.names.add(i), *a.types.add(i), *a.attrs.add(i)) };
        // SAFETY: a byte span of XLA's, `len` bytes at `ptr`.
        let name = unsafe { std::slice::from_raw_parts(name.ptr.cast::<u8>(), name.len) };
        if name != b"model" {
            continue;
        }
        if kind != ATTR_SCALAR {
            return Err(invalid(format!("{fname}: the `model` attribute is not a scalar")));
        }
        // SAFETY: a scalar attribute points to an `XLA_FFI_Scalar`.
        let s = unsafe { &*attr.cast::<Scalar>() };
        if s.dtype != DTYPE_S64 || s.value.is_null() {
            return Err(invalid(format!("{fname}: the `model` attribute is not an int64")));
        }
        // SAFETY: an `S64` scalar's value is an `i64`.
        return Ok(unsafe { *s.value.cast::<i64>() });
    }
    Err(invalid(format!("{fname}: the call has no `model` attribute")))
}

/// The dimensions of buffer `b`.
///
/// # Safety
/// `b` is a buffer given by XLA (`rank` dimensions at `dims`).
unsafe fn dims_of(b: &Buffer) -> &[i64] {
    match usize::try_from(b.rank) {
        // SAFETY: XLA gives `rank` dimensions.
        Ok(r) if r > 0 && !b.dims.is_null() => unsafe { std::slice::from_raw_parts(b.dims, r) },
        _ => &[],
    }
}

/// The `i`-th buffer of an argument or result list, checked to be a buffer of `F64`.
///
/// # Safety
/// `l` is the argument or result list of a call frame given by XLA.
unsafe fn buffer<'a>(
    l: &'a List,
    i: usize,
    kind: c_int,
    what: &dyn Fn() -> String,
) -> Result<&'a Buffer, Fail> {
    // SAFETY: callers check `i < size`; XLA gives `size` types and pointers.
    let (t, p) = unsafe { (*l.types.add(i), *l.items.add(i)) };
    if t != kind || p.is_null() {
        return Err(invalid(format!("{} is not a buffer", what())));
    }
    // SAFETY: a buffer argument or result points to an `XLA_FFI_Buffer`.
    let b = unsafe { &*p.cast::<Buffer>() };
    if b.dtype != DTYPE_F64 {
        return Err(invalid(format!(
            "{} has XLA dtype {}, expected float64 (F64): sodyn computes in float64 only, \
             enable it with jax.config.update('jax_enable_x64', True)",
            what(),
            b.dtype
        )));
    }
    Ok(b)
}

fn shape_str(d: &[i64]) -> String {
    let parts: Vec<String> = d.iter().map(|x| x.to_string()).collect();
    format!("({}{})", parts.join(", "), if d.len() == 1 { "," } else { "" })
}

/// Decodes, checks and runs one call.
///
/// # Safety
/// `cf` is a call frame given by XLA at the execute stage.
unsafe fn execute(cf: &CallFrame, f: Func, order: Order) -> Result<(), Fail> {
    let fname = f.name();
    // SAFETY: XLA's attributes.
    let handle = unsafe { model_attr(&cf.attrs, fname)? };
    let entry = lookup(handle).ok_or_else(|| {
        invalid(format!(
            "{fname}: no model with handle {handle} (it was released: the sodyn.Model of this \
             compiled function no longer exists)"
        ))
    })?;
    let m = &entry.model;
    let (nq, nv) = (m.nq(), m.nv());
    let names = f.arg_names();
    let nargs = names.len();
    if usize::try_from(cf.args.size).ok() != Some(nargs) {
        return Err(invalid(format!("{fname}: expected {nargs} arguments, got {}", cf.args.size)));
    }
    // The arguments: same leading dimensions, trailing nq / nv.
    let mut lead: Option<&[i64]> = None;
    let mut ins: [&[f64]; 3] = [&[], &[], &[]];
    for (a, name) in names.iter().enumerate() {
        let what = || format!("{fname}: argument '{name}'");
        // SAFETY: `a < nargs == size`.
        let b = unsafe { buffer(&cf.args, a, ARG_BUFFER, &what)? };
        // SAFETY: XLA's buffer.
        let d = unsafe { dims_of(b) };
        let n = if a == 0 { nq } else { nv };
        let Some((&last, l)) = d.split_last() else {
            return Err(invalid(format!("{} is a scalar, expected shape (..., {n})", what())));
        };
        if usize::try_from(last).ok() != Some(n) {
            return Err(invalid(format!(
                "{} has shape {}, expected (..., {n})",
                what(),
                shape_str(d)
            )));
        }
        match lead {
            None => lead = Some(l),
            Some(l0) if l0 != l => {
                return Err(invalid(format!(
                    "{} has leading dimensions {}, argument '{}' {}",
                    what(),
                    shape_str(l),
                    names[0],
                    shape_str(l0)
                )));
            }
            Some(_) => {}
        }
        let len = l.iter().try_fold(n, |acc, &x| usize::try_from(x).ok()?.checked_mul(acc));
        let len = len.ok_or_else(|| invalid(format!("{} has a bad shape", what())))?;
        ins[a] = if len == 0 {
            &[]
        } else {
            // SAFETY: an F64 buffer of these dimensions holds `len` doubles at `data`.
            unsafe { std::slice::from_raw_parts(b.data.cast::<f64>(), len) }
        };
    }
    let lead = lead.unwrap_or(&[]);
    let count: usize = lead.iter().map(|&x| x as usize).product();
    // The results: lead + (nv,) * rank.
    let ranks = f.ret_ranks(order);
    if usize::try_from(cf.rets.size).ok() != Some(ranks.len()) {
        return Err(invalid(format!(
            "{fname} ({}): expected {} results, got {}",
            order.what(),
            ranks.len(),
            cf.rets.size
        )));
    }
    let mut outs: [&mut [f64]; 4] = [&mut [], &mut [], &mut [], &mut []];
    let mut blocks = [0usize; 4];
    for (r, &rank) in ranks.iter().enumerate() {
        let what = || format!("{fname} ({}): result {r}", order.what());
        // SAFETY: `r < size`.
        let b = unsafe { buffer(&cf.rets, r, RET_BUFFER, &what)? };
        // SAFETY: XLA's buffer.
        let d = unsafe { dims_of(b) };
        let (dl, dt) = d.split_at(d.len().min(lead.len()));
        if dl != lead || dt.len() != rank || dt.iter().any(|&x| x != nv as i64) {
            let want: Vec<i64> =
                lead.iter().copied().chain(std::iter::repeat_n(nv as i64, rank)).collect();
            return Err(invalid(format!(
                "{} has shape {}, expected {}",
                what(),
                shape_str(d),
                shape_str(&want)
            )));
        }
        blocks[r] = nv.pow(rank as u32);
        let len = blocks[r] * count;
        outs[r] = if len == 0 {
            &mut []
        } else {
            // SAFETY: an F64 result buffer of these dimensions holds `len` doubles at `data`,
            // written by this call only, distinct from the arguments (no aliasing requested).
            unsafe { std::slice::from_raw_parts_mut(b.data.cast::<f64>(), len) }
        };
    }
    let nret = ranks.len();
    let fail = |e: sodyn::Error| {
        invalid(format!("{fname}: {}", crate::convert::python_message(e.to_string())))
    };
    if count == 1 {
        let mut w = {
            let mut spare = entry.spare.lock().unwrap_or_else(|e| e.into_inner());
            spare.pop()
        }
        .unwrap_or_else(|| Ws::new(m));
        for (a, x) in w.x.iter_mut().enumerate() {
            if a < nargs {
                x.as_mut_slice().copy_from_slice(ins[a]);
            } else {
                x.fill(0.0);
            }
        }
        let r = run_state(f, order, m, &mut w, &mut outs[..nret]);
        entry.spare.lock().unwrap_or_else(|e| e.into_inner()).push(w);
        return r.map_err(fail);
    }
    if count == 0 {
        return Ok(());
    }
    // Several states: sodyn's batch pool, as `sodyn.batch`.
    let mut per_state: Vec<[&mut [f64]; 4]> = Vec::with_capacity(count);
    let mut i = 0;
    let mut iters = outs.map(|s| {
        let it = s.chunks_exact_mut(blocks[i].max(1));
        i += 1;
        it
    });
    for _ in 0..count {
        let mut row: [&mut [f64]; 4] = [&mut [], &mut [], &mut [], &mut []];
        for (slot, it) in row.iter_mut().zip(iters.iter_mut()) {
            *slot = it.next().unwrap_or(&mut []);
        }
        per_state.push(row);
    }
    let taken = entry.batch.lock().unwrap_or_else(|e| e.into_inner()).take();
    let mut bd =
        taken.unwrap_or_else(|| BatchData::from_workspace(BatchPool::shared(), Ws::new(m)));
    let (lq, lv) = (nq, nv);
    let r = map_states(&mut bd, &mut per_state, |w, k, o| {
        let lens = [lq, lv, lv];
        for (a, (x, n)) in w.x.iter_mut().zip(lens).enumerate() {
            if a < nargs {
                x.as_mut_slice().copy_from_slice(&ins[a][k * n..(k + 1) * n]);
            } else {
                x.fill(0.0);
            }
        }
        run_state(f, order, m, w, &mut o[..nret])
    });
    *entry.batch.lock().unwrap_or_else(|e| e.into_inner()) = Some(bd);
    r.map_err(fail)
}

/// Fills the metadata of a metadata query.
///
/// # Safety
/// `ext` is the metadata extension of a call frame given by XLA.
unsafe fn metadata(ext: *mut ExtensionBase) -> Result<(), Fail> {
    // SAFETY: an extension of type metadata is an `XLA_FFI_Metadata_Extension`.
    let ext = unsafe { &mut *ext.cast::<MetadataExtension>() };
    if ext.extension_base.struct_size < METADATA_EXTENSION_SIZE || ext.metadata.is_null() {
        return Err(invalid("XLA_FFI_Metadata_Extension is too small".into()));
    }
    // SAFETY: checked non-null; XLA's metadata structure.
    let md = unsafe { &mut *ext.metadata };
    if md.struct_size < METADATA_SIZE {
        return Err(invalid("XLA_FFI_Metadata is too small".into()));
    }
    md.api_version = ApiVersion {
        struct_size: API_VERSION_SIZE,
        extension_start: std::ptr::null_mut(),
        major_version: API_MAJOR,
        minor_version: API_MINOR,
    };
    md.traits = 0;
    if md.struct_size >= METADATA_FULL_SIZE {
        md.state_type_id = 0;
    }
    Ok(())
}

/// An `XLA_FFI_Error` made by XLA's `XLA_FFI_Error_Create` (which copies the message).
///
/// # Safety
/// `api` is null or XLA's API table.
unsafe fn make_error(api: *const Api, Fail(code, msg): Fail) -> *mut XlaError {
    // SAFETY: XLA's API table when non-null.
    let Some(api) = (unsafe { api.as_ref() }) else { return std::ptr::null_mut() };
    let Some(create) = api.error_create.filter(|_| api.struct_size >= API_MIN_SIZE) else {
        return std::ptr::null_mut();
    };
    let msg = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    let mut args = ErrorCreateArgs {
        struct_size: ERROR_CREATE_ARGS_SIZE,
        extension_start: std::ptr::null_mut(),
        message: msg.as_ptr(),
        errc: code,
    };
    // SAFETY: XLA's function, given a valid argument structure.
    unsafe { create(&mut args) }
}

/// The body of every handler.
///
/// # Safety
/// `cf` is null or a call frame given by XLA.
unsafe fn handle(cf: *mut CallFrame, f: Func, order: Order) -> *mut XlaError {
    // SAFETY: XLA's call frame when non-null.
    let Some(cf) = (unsafe { cf.as_ref() }) else { return std::ptr::null_mut() };
    let api = cf.api;
    let r = catch_unwind(AssertUnwindSafe(|| {
        if cf.struct_size < CALL_FRAME_SIZE {
            return Err(invalid(format!(
                "{}: XLA_FFI_CallFrame of {} bytes, expected at least {CALL_FRAME_SIZE} (check \
                 the installed jaxlib)",
                f.name(),
                cf.struct_size
            )));
        }
        // SAFETY: the extension chain of XLA's call frame.
        if let Some(ext) = unsafe { cf.extension_start.as_ref() }
            && ext.kind == EXTENSION_METADATA
        {
            // SAFETY: a metadata extension.
            return unsafe { metadata(cf.extension_start) };
        }
        if cf.stage != STAGE_EXECUTE {
            return Ok(());
        }
        // SAFETY: XLA's call frame at the execute stage.
        unsafe { execute(cf, f, order) }
    }));
    let r =
        r.unwrap_or_else(|_| Err(Fail(ERROR_INTERNAL, format!("{}: internal panic", f.name()))));
    match r {
        Ok(()) => std::ptr::null_mut(),
        // SAFETY: XLA's API table.
        Err(e) => unsafe { make_error(api, e) },
    }
}

macro_rules! handlers {
    ($($name:ident: $f:expr, $o:expr;)*) => {
        $(
            /// An XLA FFI handler (see the module documentation).
            ///
            /// # Safety
            /// Called by XLA with its call frame.
            unsafe extern "C" fn $name(cf: *mut CallFrame) -> *mut XlaError {
                // SAFETY: XLA's call frame.
                unsafe { handle(cf, $f, $o) }
            }
        )*
    };
}

handlers! {
    rnea_value: Func::Rnea, Order::Value;
    rnea_first: Func::Rnea, Order::First;
    rnea_second: Func::Rnea, Order::Second;
    aba_value: Func::Aba, Order::Value;
    aba_first: Func::Aba, Order::First;
    aba_second: Func::Aba, Order::Second;
    nle_value: Func::Nle, Order::Value;
    nle_first: Func::Nle, Order::First;
    nle_second: Func::Nle, Order::Second;
    crba_value: Func::Crba, Order::Value;
    crba_first: Func::Crba, Order::First;
}

type Handler = unsafe extern "C" fn(*mut CallFrame) -> *mut XlaError;

/// The handlers as `{target name: PyCapsule}` for `jax.ffi.register_ffi_target(...,
/// api_version=1)`.
#[pyfunction]
fn _jax_ffi_targets(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let table: [(&str, &'static CStr, Handler); 11] = [
        ("sodyn_rnea", c"sodyn.jax_ffi.rnea", rnea_value),
        ("sodyn_rnea_first", c"sodyn.jax_ffi.rnea_first", rnea_first),
        ("sodyn_rnea_second", c"sodyn.jax_ffi.rnea_second", rnea_second),
        ("sodyn_aba", c"sodyn.jax_ffi.aba", aba_value),
        ("sodyn_aba_first", c"sodyn.jax_ffi.aba_first", aba_first),
        ("sodyn_aba_second", c"sodyn.jax_ffi.aba_second", aba_second),
        ("sodyn_nonlinear_effects", c"sodyn.jax_ffi.nonlinear_effects", nle_value),
        ("sodyn_nonlinear_effects_first", c"sodyn.jax_ffi.nonlinear_effects_first", nle_first),
        ("sodyn_nonlinear_effects_second", c"sodyn.jax_ffi.nonlinear_effects_second", nle_second),
        ("sodyn_crba", c"sodyn.jax_ffi.crba", crba_value),
        ("sodyn_crba_first", c"sodyn.jax_ffi.crba_first", crba_first),
    ];
    let d = PyDict::new(py);
    for (name, cname, h) in table {
        let p = NonNull::new(h as *mut c_void).expect("a function pointer is not null");
        // SAFETY: a function pointer of this library, valid for the life of the process.
        let cap = unsafe { PyCapsule::new_with_pointer(py, p, cname)? };
        d.set_item(name, cap)?;
    }
    Ok(d)
}

/// Adds this family's functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_jax_ffi_targets, m)?)?;
    Ok(())
}
