//! Model loaders: URDF, MJCF and the built-in models.

mod builtin;
mod mjcf;
mod urdf;
