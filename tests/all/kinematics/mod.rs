//! Kinematics: frames, points, centre of mass, centroidal momentum, configuration-space Jacobians
//! and spatial identities.

mod centroidal;
mod com;
mod frames;
mod lie;
mod spatial_identities;
