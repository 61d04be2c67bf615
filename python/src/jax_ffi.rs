//! XLA FFI handlers of `sodyn.jax`: RNEA, ABA, the nonlinear effects, the KKT and impact
//! dynamics, frame translation and placement and the centre of mass (value, first-order
//! Jacobian blocks, dense second order) and CRBA (value, `dM/dq`) as typed-FFI custom calls, so
//! that a jitted `sodyn.jax` function runs sodyn without entering Python. Each computes what
//! the numpy side of the `jax.pure_callback` path (`sodyn._interop`) computes, with the same
//! sodyn calls in the same order, so the two paths agree bit for bit.
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
//!   `F64`, dimensions) before reading or writing memory, and the attributes (`S64`): `model`
//!   (a handle of this module's registry), `contacts` for the KKT and impact dynamics (a
//!   contact-set handle of that model) and `frame` for the frame functions (an index below
//!   the model's frame count): a wrong call is an XLA error naming what is wrong, never an
//!   out-of-bounds access;
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
//! the handle then gets an XLA error, not a dangling model). Contact sets (with their
//! restitution) are registered by `_jax_ffi_contacts(model, contacts, restitution)`, resolved
//! and checked there, one handle per distinct set and model, removed with the model; each
//! model entry keeps its workspaces (`Data`, `ContactData`) per contact set.

use crate::convert::ContactKey;
use nalgebra::{DVector, Matrix3xX, Matrix6xX};
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyDict};
use sodyn::algo::{self, Contact, Data};
use sodyn::batch::{BatchData, BatchPool, map_states};
use sodyn::deriv::{
    ContactData, fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives,
    impact_derivatives, impact_dynamics, impact_so_derivatives, kkt_derivatives,
    kkt_so_derivatives,
};
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
// The model and contact-set registries

/// One state's workspace: sodyn's `Data` (its second-order capacity added on first use), the
/// three input vectors, the contact set's `ContactData` (contact functions) and the frame and
/// centre-of-mass buffers (made on first use).
#[derive(Clone)]
struct Ws {
    d: Data,
    x: [DVector<f64>; 3],
    cd: Option<ContactData>,
    j6: Option<Matrix6xX<f64>>,
    j3: Option<Matrix3xX<f64>>,
    t6: Option<Tensor3>,
}

impl Ws {
    fn new(m: &Model, cset: Option<&CSet>) -> sodyn::Result<Self> {
        let cd = match cset {
            Some(c) => {
                let mut cd = ContactData::new(m, &c.contacts)?;
                cd.set_restitution(c.restitution)?;
                Some(cd)
            }
            None => None,
        };
        Ok(Self {
            d: Data::new(m),
            x: [DVector::zeros(m.nq()), DVector::zeros(m.nv()), DVector::zeros(m.nv())],
            cd,
            j6: None,
            j3: None,
            t6: None,
        })
    }
}

/// A registered model: its snapshot, spare single-state workspaces and a batch workspace, per
/// contact set (key 0: none).
struct Entry {
    model: Model,
    spare: Mutex<HashMap<u64, Vec<Ws>>>,
    batch: Mutex<HashMap<u64, BatchData<Ws>>>,
}

impl Entry {
    fn new(model: Model) -> Arc<Self> {
        Arc::new(Self { model, spare: Default::default(), batch: Default::default() })
    }
}

/// A registered contact set (the static `contacts` and `restitution` of `kkt_dynamics` /
/// `impact_dynamics`), resolved against the model of handle `model`.
struct CSet {
    model: u64,
    contacts: Vec<Contact>,
    restitution: f64,
    /// The contact rows (3 per 3-D contact, 6 per 6-D contact).
    rows: usize,
    /// What identifies the set: its resolved contacts and the restitution's bits.
    key: (ContactKey, u64),
}

fn registry() -> &'static RwLock<HashMap<u64, Arc<Entry>>> {
    static R: OnceLock<RwLock<HashMap<u64, Arc<Entry>>>> = OnceLock::new();
    R.get_or_init(Default::default)
}

fn csets() -> &'static RwLock<HashMap<u64, Arc<CSet>>> {
    static R: OnceLock<RwLock<HashMap<u64, Arc<CSet>>>> = OnceLock::new();
    R.get_or_init(Default::default)
}

/// A fresh handle (models and contact sets share the counter; never reused).
fn next_handle() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

fn lookup(handle: i64) -> Option<Arc<Entry>> {
    let r = registry().read().unwrap_or_else(|e| e.into_inner());
    u64::try_from(handle).ok().and_then(|h| r.get(&h).cloned())
}

fn cs_handle(h: i64) -> u64 {
    u64::try_from(h).unwrap_or(0)
}

fn lookup_cset(handle: i64) -> Option<Arc<CSet>> {
    let r = csets().read().unwrap_or_else(|e| e.into_inner());
    u64::try_from(handle).ok().and_then(|h| r.get(&h).cloned())
}

/// The registry handle of a Python `Model` (none until `sodyn.jax` first needs it); dropping
/// it removes the snapshot and the model's contact sets.
#[derive(Default)]
pub(crate) struct Link(OnceLock<u64>);

impl Link {
    /// The model's handle, registering a snapshot of `m` on first use.
    pub(crate) fn handle(&self, m: &Model) -> u64 {
        *self.0.get_or_init(|| {
            let h = next_handle();
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
            csets().write().unwrap_or_else(|e| e.into_inner()).retain(|_, c| c.model != *h);
        }
    }
}

/// The registry handle of the contact set `cs` (resolved and checked by the caller, with its
/// key `ckey`) and `restitution` on the model registered by `link`: the same contacts and
/// restitution on the same model get the same handle (the `contacts` attribute of the KKT and
/// impact handlers; `_jax_ffi_contacts` in `contacts.rs`).
pub(crate) fn register_contacts(
    m: &Model,
    link: &Link,
    cs: Vec<Contact>,
    ckey: ContactKey,
    restitution: f64,
) -> sodyn::Result<u64> {
    let mut cd = ContactData::new(m, &cs)?;
    cd.set_restitution(restitution)?;
    let h = link.handle(m);
    let key = (ckey, restitution.to_bits());
    let mut reg = csets().write().unwrap_or_else(|e| e.into_inner());
    if let Some((k, _)) = reg.iter().find(|(_, c)| c.model == h && c.key == key) {
        return Ok(*k);
    }
    let k = next_handle();
    let rows = cs.iter().map(|c| c.dim()).sum();
    reg.insert(k, Arc::new(CSet { model: h, contacts: cs, restitution, rows, key }));
    Ok(k)
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
    /// `kkt_dynamics(q, v, tau)` with the `contacts` attribute's set.
    Kkt,
    /// `impact_dynamics(q, v_minus)` with the `contacts` attribute's set and restitution.
    Impact,
    /// `frame_translation(q)` of the `frame` attribute's frame.
    FrameTranslation,
    /// `frame_placement(q)`, `(4, 4)`, of the `frame` attribute's frame.
    FramePlacement,
    /// `center_of_mass(q)`.
    Com,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Order {
    /// The values.
    Value,
    /// The values and their Jacobian blocks (`Spec.jac_blocks` of `sodyn._interop`).
    First,
    /// The dense second-order tensors (the first three at `a = 0` for `Nle`; none for `Crba`).
    Second,
}

/// A dimension of a result: `nv`, the contact rows, or a constant.
#[derive(Clone, Copy)]
enum Dim {
    V,
    L,
    K(usize),
}
use Dim::{K, L, V};

impl Func {
    fn name(self) -> &'static str {
        match self {
            Func::Rnea => "sodyn.jax.rnea",
            Func::Aba => "sodyn.jax.aba",
            Func::Nle => "sodyn.jax.nonlinear_effects",
            Func::Crba => "sodyn.jax.crba",
            Func::Kkt => "sodyn.jax.kkt_dynamics",
            Func::Impact => "sodyn.jax.impact_dynamics",
            Func::FrameTranslation => "sodyn.jax.frame_translation",
            Func::FramePlacement => "sodyn.jax.frame_placement",
            Func::Com => "sodyn.jax.center_of_mass",
        }
    }
    fn arg_names(self) -> &'static [&'static str] {
        match self {
            Func::Rnea => &["q", "v", "a"],
            Func::Aba | Func::Kkt => &["q", "v", "tau"],
            Func::Nle => &["q", "v"],
            Func::Impact => &["q", "v_minus"],
            Func::Crba | Func::FrameTranslation | Func::FramePlacement | Func::Com => &["q"],
        }
    }
    /// The per-state result shapes.
    fn ret_dims(self, order: Order) -> &'static [&'static [Dim]] {
        match (self, order) {
            (Func::Rnea | Func::Aba | Func::Nle, Order::Value) => &[&[V]],
            (Func::Rnea | Func::Aba, Order::First) => &[&[V], &[V, V], &[V, V], &[V, V]],
            (Func::Rnea | Func::Aba, Order::Second) => {
                &[&[V, V, V], &[V, V, V], &[V, V, V], &[V, V, V]]
            }
            (Func::Nle, Order::First) => &[&[V], &[V, V], &[V, V]],
            (Func::Nle, Order::Second) => &[&[V, V, V], &[V, V, V], &[V, V, V]],
            (Func::Crba, Order::Value) => &[&[V, V]],
            (Func::Crba, Order::First) => &[&[V, V], &[V, V, V]],
            (Func::Crba, Order::Second) => &[],
            (Func::Kkt | Func::Impact, Order::Value) => &[&[V], &[L]],
            (Func::Kkt, Order::First) => {
                &[&[V], &[L], &[V, V], &[V, V], &[V, V], &[L, V], &[L, V], &[L, V]]
            }
            (Func::Kkt, Order::Second) => &[
                &[V, V, V],
                &[V, V, V],
                &[V, V, V],
                &[V, V, V],
                &[L, V, V],
                &[L, V, V],
                &[L, V, V],
                &[L, V, V],
            ],
            (Func::Impact, Order::First) => &[&[V], &[L], &[V, V], &[V, V], &[L, V], &[L, V]],
            (Func::Impact, Order::Second) => &[&[V, V, V], &[V, V, V], &[L, V, V], &[L, V, V]],
            (Func::FrameTranslation | Func::Com, Order::Value) => &[&[K(3)]],
            (Func::FrameTranslation | Func::Com, Order::First) => &[&[K(3)], &[K(3), V]],
            (Func::FrameTranslation | Func::Com, Order::Second) => &[&[K(3), V, V]],
            (Func::FramePlacement, Order::Value) => &[&[K(4), K(4)]],
            (Func::FramePlacement, Order::First) => &[&[K(4), K(4)], &[K(4), K(4), V]],
            (Func::FramePlacement, Order::Second) => &[&[K(4), K(4), V, V]],
        }
    }
    fn has_contacts(self) -> bool {
        matches!(self, Func::Kkt | Func::Impact)
    }
    fn has_frame(self) -> bool {
        matches!(self, Func::FrameTranslation | Func::FramePlacement)
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

/// The most results of a handler (the KKT dynamics' first and second order).
const MAX_RETS: usize = 8;

/// Copies a column-major `r × c` matrix into a row-major block.
fn write_matrix<S: nalgebra::RawStorage<f64, nalgebra::Dyn, nalgebra::Dyn>>(
    dst: &mut [f64],
    src: &nalgebra::Matrix<f64, nalgebra::Dyn, nalgebra::Dyn, S>,
) {
    let c = src.ncols();
    for (i, row) in dst.chunks_exact_mut(c.max(1)).enumerate().take(src.nrows()) {
        for (j, x) in row.iter_mut().enumerate() {
            *x = src[(i, j)];
        }
    }
}

/// Copies the rows `rows` of a column-major `r × c` matrix (fixed rows) into a row-major block.
fn write_rows<R: nalgebra::Dim, S: nalgebra::RawStorage<f64, R, nalgebra::Dyn>>(
    dst: &mut [f64],
    src: &nalgebra::Matrix<f64, R, nalgebra::Dyn, S>,
    rows: std::ops::Range<usize>,
) {
    let c = src.ncols();
    for (row, i) in dst.chunks_exact_mut(c.max(1)).zip(rows) {
        for (j, x) in row.iter_mut().enumerate() {
            *x = src[(i, j)];
        }
    }
}

/// Copies the slices `rows` of the first index of a column-major tensor into a row-major
/// block.
fn write_tensor_rows(dst: &mut [f64], src: &Tensor3, rows: std::ops::Range<usize>) {
    let (a, b, c) = src.dims();
    let s = src.as_slice();
    let mut o = 0;
    for i in rows {
        for j in 0..b {
            for k in 0..c {
                dst[o] = s[i + a * (j + b * k)];
                o += 1;
            }
        }
    }
}

/// Copies a column-major tensor into a row-major block.
fn write_tensor(dst: &mut [f64], src: &Tensor3) {
    write_tensor_rows(dst, src, 0..src.dims().0)
}

/// `[w]×` as rows.
fn skew(w: [f64; 3]) -> [[f64; 3]; 3] {
    [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
}

/// What a call computes: the function, its order and its static attributes.
struct Call {
    f: Func,
    order: Order,
    cset: Option<Arc<CSet>>,
    /// The contact set's handle (0: none), the key of its workspaces in the model's entry.
    ckey: u64,
    frame: usize,
}

/// A frame function's Jacobian and Jacobian-derivative buffers.
fn frame_bufs<'a>(
    j6: &'a mut Option<Matrix6xX<f64>>,
    t6: &'a mut Option<Tensor3>,
    nv: usize,
) -> (&'a mut Matrix6xX<f64>, &'a mut Tensor3) {
    (
        j6.get_or_insert_with(|| Matrix6xX::zeros(nv)),
        t6.get_or_insert_with(|| Tensor3::zeros(6, nv, nv)),
    )
}

/// One state: the inputs are in `w.x` (zeros after the function's arguments), the results go
/// to `out` (one row-major block each).
fn run_state(c: &Call, m: &Model, w: &mut Ws, out: &mut [&mut [f64]]) -> sodyn::Result<()> {
    let nv = m.nv();
    let Ws { d, x: [q, v, x], cd, j6, j3, t6 } = w;
    let lwa = algo::ReferenceFrame::LocalWorldAligned;
    match (c.f, c.order) {
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
        (Func::Kkt | Func::Impact, _) => {
            let cd = cd.as_mut().ok_or_else(|| {
                sodyn::Error::Workspace("no contact workspace (internal error)".into())
            })?;
            run_contacts(c, m, d, cd, [q, v, x], out)?;
        }
        (Func::FrameTranslation, order) => {
            let p = algo::frame_placement(m, d, q, c.frame)?;
            if order != Order::Second {
                out[0].copy_from_slice(p.trans.as_slice());
            }
            let (j6, t6) = frame_bufs(j6, t6, nv);
            match order {
                Order::Value => {}
                Order::First => {
                    algo::frame_jacobian(m, d, q, c.frame, lwa, j6)?;
                    write_rows(out[1], j6, 3..6);
                }
                Order::Second => {
                    algo::frame_jacobian_derivative(m, d, q, c.frame, lwa, t6)?;
                    write_tensor_rows(out[0], t6, 3..6);
                }
            }
        }
        (Func::FramePlacement, order) => {
            let p = algo::frame_placement(m, d, q, c.frame)?;
            let r = &p.rot;
            if order != Order::Second {
                let h = &mut out[0];
                h.fill(0.0);
                for a in 0..3 {
                    for b in 0..3 {
                        h[4 * a + b] = r[(a, b)];
                    }
                    h[4 * a + 3] = p.trans[a];
                }
                h[15] = 1.0;
            }
            if order == Order::Value {
                return Ok(());
            }
            let (j6, t6) = frame_bufs(j6, t6, nv);
            algo::frame_jacobian(m, d, q, c.frame, lwa, j6)?;
            let wj = |j: usize| skew([j6[(0, j)], j6[(1, j)], j6[(2, j)]]);
            if order == Order::First {
                // D[a, c, j] = sum_b [w_j]x[a, b] R[b, c]; D[a, 3, j] = v_j[a]
                let dd = &mut out[1];
                dd.fill(0.0);
                for j in 0..nv {
                    let wm = wj(j);
                    for a in 0..3 {
                        for cc in 0..3 {
                            let mut s = 0.0;
                            for b in 0..3 {
                                s += wm[a][b] * r[(b, cc)];
                            }
                            dd[(4 * a + cc) * nv + j] = s;
                        }
                        dd[(4 * a + 3) * nv + j] = j6[(3 + a, j)];
                    }
                }
                return Ok(());
            }
            algo::frame_jacobian_derivative(m, d, q, c.frame, lwa, t6)?;
            // H[a, c, j, k] = sum_b [dw_j/dq_k]x[a, b] R[b, c]
            //               + sum_b sum_e [w_j]x[a, b] [w_k]x[b, e] R[e, c];
            // H[a, 3, j, k] = dv_j/dq_k[a]
            let hh = &mut out[0];
            hh.fill(0.0);
            for j in 0..nv {
                let wjm = wj(j);
                for k in 0..nv {
                    let wkm = wj(k);
                    let dw = skew([t6[(0, j, k)], t6[(1, j, k)], t6[(2, j, k)]]);
                    for a in 0..3 {
                        for cc in 0..3 {
                            let mut s1 = 0.0;
                            for b in 0..3 {
                                s1 += dw[a][b] * r[(b, cc)];
                            }
                            let mut s2 = 0.0;
                            for b in 0..3 {
                                for e in 0..3 {
                                    s2 += wjm[a][b] * wkm[b][e] * r[(e, cc)];
                                }
                            }
                            hh[((4 * a + cc) * nv + j) * nv + k] = s1 + s2;
                        }
                        hh[((4 * a + 3) * nv + j) * nv + k] = t6[(3 + a, j, k)];
                    }
                }
            }
        }
        (Func::Com, Order::Value) => {
            out[0].copy_from_slice(algo::center_of_mass(m, d, q)?.as_slice());
        }
        (Func::Com, Order::First) => {
            out[0].copy_from_slice(algo::center_of_mass(m, d, q)?.as_slice());
            let j3 = j3.get_or_insert_with(|| Matrix3xX::zeros(nv));
            algo::center_of_mass_jacobian(m, d, q, j3)?;
            write_rows(out[1], j3, 0..3);
        }
        (Func::Com, Order::Second) => {
            // H[i, j, k] = d vcom_i / dq_j at v = e_k
            let j3 = j3.get_or_insert_with(|| Matrix3xX::zeros(nv));
            let h = &mut out[0];
            for k in 0..nv {
                v.fill(0.0);
                v[k] = 1.0;
                algo::center_of_mass_velocity_derivatives(m, d, q, v, j3)?;
                for i in 0..3 {
                    for j in 0..nv {
                        h[(i * nv + j) * nv + k] = j3[(i, j)];
                    }
                }
            }
        }
    }
    Ok(())
}

/// The KKT and impact dynamics of one state (as `kkt_derivatives` / `impact_derivatives` of
/// the numpy API with `order` 1 or 2).
fn run_contacts(
    c: &Call,
    m: &Model,
    d: &mut Data,
    cd: &mut ContactData,
    [q, v, x]: [&mut DVector<f64>; 3],
    out: &mut [&mut [f64]],
) -> sodyn::Result<()> {
    if c.order == Order::Second {
        cd.reserve_second_order(m)?;
    }
    match (c.f, c.order) {
        (Func::Kkt, Order::Value) => {
            // the numpy API's value (kkt_derivatives): kkt_dynamics rounds differently
            let kd = kkt_derivatives(m, d, cd, q, v, x)?;
            out[0].copy_from_slice(kd.qdd().as_slice());
            out[1].copy_from_slice(kd.lambda().as_slice());
        }
        (Func::Kkt, Order::First) => {
            let kd = kkt_derivatives(m, d, cd, q, v, x)?;
            out[0].copy_from_slice(kd.qdd().as_slice());
            out[1].copy_from_slice(kd.lambda().as_slice());
            let fo = [
                kd.dqdd_dq(),
                kd.dqdd_dv(),
                kd.dqdd_dtau(),
                kd.dlambda_dq(),
                kd.dlambda_dv(),
                kd.dlambda_dtau(),
            ];
            for (dst, j) in out[2..].iter_mut().zip(fo) {
                write_matrix(dst, j);
            }
        }
        (Func::Kkt, _) => {
            let kd = kkt_so_derivatives(m, d, cd, q, v, x)?;
            let t = kd.so().ok_or_else(|| {
                sodyn::Error::Workspace("kkt_so_derivatives gave no tensors".into())
            })?;
            let ts = [
                t.d2qdd_dq2(),
                t.d2qdd_dv2(),
                t.d2qdd_dqdv(),
                t.d2qdd_dtaudq(),
                t.d2lambda_dq2(),
                t.d2lambda_dv2(),
                t.d2lambda_dqdv(),
                t.d2lambda_dtaudq(),
            ];
            for (dst, t) in out.iter_mut().zip(ts) {
                write_tensor(dst, t);
            }
        }
        (_, Order::Value) => {
            let im = impact_dynamics(m, d, cd, q, v)?;
            out[0].copy_from_slice(im.vplus().as_slice());
            out[1].copy_from_slice(im.impulse().as_slice());
        }
        (_, Order::First) => {
            let im = impact_derivatives(m, d, cd, q, v)?;
            out[0].copy_from_slice(im.vplus().as_slice());
            out[1].copy_from_slice(im.impulse().as_slice());
            let fo = [im.dvplus_dq(), im.dvplus_dvminus(), im.dimpulse_dq(), im.dimpulse_dvminus()];
            for (dst, j) in out[2..].iter_mut().zip(fo) {
                write_matrix(dst, j);
            }
        }
        (_, Order::Second) => {
            let im = impact_so_derivatives(m, d, cd, q, v)?;
            let t = im.so().ok_or_else(|| {
                sodyn::Error::Workspace("impact_so_derivatives gave no tensors".into())
            })?;
            let ts = [
                t.d2vplus_dq2(),
                t.d2vplus_dqdvminus(),
                t.d2impulse_dq2(),
                t.d2impulse_dqdvminus(),
            ];
            for (dst, t) in out.iter_mut().zip(ts) {
                write_tensor(dst, t);
            }
        }
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

/// The attribute `key`: an `S64` scalar (`None` if absent).
///
/// # Safety
/// `a` is the attributes of a call frame given by XLA (sizes and pointers consistent).
unsafe fn int_attr(a: &Attrs, key: &str, fname: &str) -> Result<Option<i64>, Fail> {
    for i in 0..usize::try_from(a.size).unwrap_or(0) {
        // SAFETY: `i < size`, and XLA gives `size` names, types and attributes.
        let (name, kind, attr) = unsafe { (&**a.names.add(i), *a.types.add(i), *a.attrs.add(i)) };
        // SAFETY: a byte span of XLA's, `len` bytes at `ptr`.
        let name = unsafe { std::slice::from_raw_parts(name.ptr.cast::<u8>(), name.len) };
        if name != key.as_bytes() {
            continue;
        }
        if kind != ATTR_SCALAR {
            return Err(invalid(format!("{fname}: the `{key}` attribute is not a scalar")));
        }
        // SAFETY: a scalar attribute points to an `XLA_FFI_Scalar`.
        let s = unsafe { &*attr.cast::<Scalar>() };
        if s.dtype != DTYPE_S64 || s.value.is_null() {
            return Err(invalid(format!("{fname}: the `{key}` attribute is not an int64")));
        }
        // SAFETY: an `S64` scalar's value is an `i64`.
        return Ok(Some(unsafe { *s.value.cast::<i64>() }));
    }
    Ok(None)
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

/// The static attributes of a call: the model's entry, the contact set and the frame.
///
/// # Safety
/// `a` is the attributes of a call frame given by XLA.
unsafe fn statics(a: &Attrs, f: Func, order: Order) -> Result<(Arc<Entry>, Call), Fail> {
    let fname = f.name();
    // SAFETY: XLA's attributes.
    let handle = unsafe { int_attr(a, "model", fname)? }
        .ok_or_else(|| invalid(format!("{fname}: the call has no `model` attribute")))?;
    let entry = lookup(handle).ok_or_else(|| {
        invalid(format!(
            "{fname}: no model with handle {handle} (it was released: the sodyn.Model of this \
             compiled function no longer exists)"
        ))
    })?;
    let mut call = Call { f, order, cset: None, ckey: 0, frame: 0 };
    if f.has_contacts() {
        // SAFETY: XLA's attributes.
        let h = unsafe { int_attr(a, "contacts", fname)? }
            .ok_or_else(|| invalid(format!("{fname}: the call has no `contacts` attribute")))?;
        let cs = lookup_cset(h).filter(|c| c.model as i64 == handle).ok_or_else(|| {
            invalid(format!(
                "{fname}: no contact set with handle {h} on model {handle} (it was released \
                 with its sodyn.Model, or belongs to another model)"
            ))
        })?;
        call.ckey = cs_handle(h);
        call.cset = Some(cs);
    }
    if f.has_frame() {
        // SAFETY: XLA's attributes.
        let i = unsafe { int_attr(a, "frame", fname)? }
            .ok_or_else(|| invalid(format!("{fname}: the call has no `frame` attribute")))?;
        let n = entry.model.frames().len();
        call.frame = match usize::try_from(i) {
            Ok(i) if i < n => i,
            Ok(_) => {
                return Err(invalid(format!(
                    "{fname}: `frame` index {i} is out of range: the model has {n} frames"
                )));
            }
            Err(_) => {
                return Err(invalid(format!(
                    "{fname}: `frame` must be a frame name or index, got {i}"
                )));
            }
        };
    }
    Ok((entry, call))
}

/// Decodes, checks and runs one call.
///
/// # Safety
/// `cf` is a call frame given by XLA at the execute stage.
unsafe fn execute(cf: &CallFrame, f: Func, order: Order) -> Result<(), Fail> {
    let fname = f.name();
    // SAFETY: XLA's attributes.
    let (entry, call) = unsafe { statics(&cf.attrs, f, order)? };
    let m = &entry.model;
    let (nq, nv) = (m.nq(), m.nv());
    let nl = call.cset.as_ref().map_or(0, |c| c.rows);
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
    // The results: lead + the per-state shape.
    let shapes = f.ret_dims(order);
    if usize::try_from(cf.rets.size).ok() != Some(shapes.len()) {
        return Err(invalid(format!(
            "{fname} ({}): expected {} results, got {}",
            order.what(),
            shapes.len(),
            cf.rets.size
        )));
    }
    let mut outs: [&mut [f64]; MAX_RETS] = Default::default();
    let mut blocks = [0usize; MAX_RETS];
    for (r, &shape) in shapes.iter().enumerate() {
        let what = || format!("{fname} ({}): result {r}", order.what());
        // SAFETY: `r < size`.
        let b = unsafe { buffer(&cf.rets, r, RET_BUFFER, &what)? };
        // SAFETY: XLA's buffer.
        let d = unsafe { dims_of(b) };
        let want = shape.iter().map(|x| match x {
            V => nv,
            L => nl,
            K(k) => *k,
        });
        let (dl, dt) = d.split_at(d.len().min(lead.len()));
        if dl != lead
            || dt.len() != shape.len()
            || dt.iter().zip(want.clone()).any(|(&x, w)| x != w as i64)
        {
            let want: Vec<i64> = lead.iter().copied().chain(want.map(|w| w as i64)).collect();
            return Err(invalid(format!(
                "{} has shape {}, expected {}",
                what(),
                shape_str(d),
                shape_str(&want)
            )));
        }
        blocks[r] = want.product();
        let len = blocks[r] * count;
        outs[r] = if len == 0 {
            &mut []
        } else {
            // SAFETY: an F64 result buffer of these dimensions holds `len` doubles at `data`,
            // written by this call only, distinct from the arguments (no aliasing requested).
            unsafe { std::slice::from_raw_parts_mut(b.data.cast::<f64>(), len) }
        };
    }
    let nret = shapes.len();
    let fail = |e: sodyn::Error| {
        invalid(format!("{fname}: {}", crate::convert::python_message(e.to_string())))
    };
    let ckey = call.ckey;
    let new_ws = || Ws::new(m, call.cset.as_deref());
    if count == 1 {
        let w = {
            let mut spare = entry.spare.lock().unwrap_or_else(|e| e.into_inner());
            spare.get_mut(&ckey).and_then(|v| v.pop())
        };
        let mut w = match w {
            Some(w) => w,
            None => new_ws().map_err(fail)?,
        };
        for (a, x) in w.x.iter_mut().enumerate() {
            if a < nargs {
                x.as_mut_slice().copy_from_slice(ins[a]);
            } else {
                x.fill(0.0);
            }
        }
        let r = run_state(&call, m, &mut w, &mut outs[..nret]);
        entry.spare.lock().unwrap_or_else(|e| e.into_inner()).entry(ckey).or_default().push(w);
        return r.map_err(fail);
    }
    if count == 0 {
        return Ok(());
    }
    // Several states: sodyn's batch pool, as `sodyn.batch`.
    let mut per_state: Vec<[&mut [f64]; MAX_RETS]> = Vec::with_capacity(count);
    let mut i = 0;
    let mut iters = outs.map(|s| {
        let it = s.chunks_exact_mut(blocks[i].max(1));
        i += 1;
        it
    });
    for _ in 0..count {
        let mut row: [&mut [f64]; MAX_RETS] = Default::default();
        for (slot, it) in row.iter_mut().zip(iters.iter_mut()) {
            *slot = it.next().unwrap_or(&mut []);
        }
        per_state.push(row);
    }
    let taken = entry.batch.lock().unwrap_or_else(|e| e.into_inner()).remove(&ckey);
    let mut bd = match taken {
        Some(bd) => bd,
        None => BatchData::from_workspace(BatchPool::shared(), new_ws().map_err(fail)?),
    };
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
        run_state(&call, m, w, &mut o[..nret])
    });
    entry.batch.lock().unwrap_or_else(|e| e.into_inner()).insert(ckey, bd);
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
    kkt_value: Func::Kkt, Order::Value;
    kkt_first: Func::Kkt, Order::First;
    kkt_second: Func::Kkt, Order::Second;
    impact_value: Func::Impact, Order::Value;
    impact_first: Func::Impact, Order::First;
    impact_second: Func::Impact, Order::Second;
    ft_value: Func::FrameTranslation, Order::Value;
    ft_first: Func::FrameTranslation, Order::First;
    ft_second: Func::FrameTranslation, Order::Second;
    fp_value: Func::FramePlacement, Order::Value;
    fp_first: Func::FramePlacement, Order::First;
    fp_second: Func::FramePlacement, Order::Second;
    com_value: Func::Com, Order::Value;
    com_first: Func::Com, Order::First;
    com_second: Func::Com, Order::Second;
}

type Handler = unsafe extern "C" fn(*mut CallFrame) -> *mut XlaError;

/// The handlers as `{target name: PyCapsule}` for `jax.ffi.register_ffi_target(...,
/// api_version=1)`.
#[pyfunction]
fn _jax_ffi_targets(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let table: [(&str, &'static CStr, Handler); 26] = [
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
        ("sodyn_kkt_dynamics", c"sodyn.jax_ffi.kkt_dynamics", kkt_value),
        ("sodyn_kkt_dynamics_first", c"sodyn.jax_ffi.kkt_dynamics_first", kkt_first),
        ("sodyn_kkt_dynamics_second", c"sodyn.jax_ffi.kkt_dynamics_second", kkt_second),
        ("sodyn_impact_dynamics", c"sodyn.jax_ffi.impact_dynamics", impact_value),
        ("sodyn_impact_dynamics_first", c"sodyn.jax_ffi.impact_dynamics_first", impact_first),
        ("sodyn_impact_dynamics_second", c"sodyn.jax_ffi.impact_dynamics_second", impact_second),
        ("sodyn_frame_translation", c"sodyn.jax_ffi.frame_translation", ft_value),
        ("sodyn_frame_translation_first", c"sodyn.jax_ffi.frame_translation_first", ft_first),
        ("sodyn_frame_translation_second", c"sodyn.jax_ffi.frame_translation_second", ft_second),
        ("sodyn_frame_placement", c"sodyn.jax_ffi.frame_placement", fp_value),
        ("sodyn_frame_placement_first", c"sodyn.jax_ffi.frame_placement_first", fp_first),
        ("sodyn_frame_placement_second", c"sodyn.jax_ffi.frame_placement_second", fp_second),
        ("sodyn_center_of_mass", c"sodyn.jax_ffi.center_of_mass", com_value),
        ("sodyn_center_of_mass_first", c"sodyn.jax_ffi.center_of_mass_first", com_first),
        ("sodyn_center_of_mass_second", c"sodyn.jax_ffi.center_of_mass_second", com_second),
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
