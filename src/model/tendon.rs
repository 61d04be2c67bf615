//! MJCF `<tendon>`s as a [`Model`](super::Model) records them (data only: they do not enter
//! the dynamics).

/// A `<tendon>` of an MJCF model, as [`Model::tendons`](super::Model::tendons) records it. Tendons do not enter the
/// mass matrix or the rigid-body dynamics: their limits, springs, damping, friction loss and
/// the actuators acting on them are not modelled (a warning in [`Model::warnings`](super::Model::warnings) says so),
/// and a nonzero tendon `armature` is refused.
#[derive(Clone, Debug, PartialEq)]
pub struct Tendon {
    /// The `name` attribute (`None` for an unnamed tendon).
    pub name: Option<String>,
    /// Its path.
    pub path: TendonPath,
}

/// The path of a [`Tendon`].
#[derive(Clone, Debug, PartialEq)]
pub enum TendonPath {
    /// `<fixed>`: the length is `Σ coef · q_joint`; `(joint index, coef)` in document order
    /// (hinge and slide joints, each once).
    Fixed(Vec<(usize, f64)>),
    /// `<spatial>`: the path elements in document order.
    Spatial(Vec<SpatialWrap>),
}

/// An element of a spatial tendon's path.
#[derive(Clone, Debug, PartialEq)]
pub enum SpatialWrap {
    /// `<site site>`: a site the tendon passes through (a frame of the model unless a body has
    /// its name).
    Site(String),
    /// `<geom geom sidesite>`: a geom the tendon wraps around, with its optional side site.
    Geom {
        /// The geom's name.
        geom: String,
        /// The `sidesite` attribute.
        sidesite: Option<String>,
    },
    /// `<pulley divisor>`: starts a branch whose length is divided by `divisor`.
    Pulley {
        /// The `divisor` attribute.
        divisor: f64,
    },
}
