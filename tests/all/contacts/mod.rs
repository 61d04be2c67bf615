//! Contact algorithms (constrained inverse dynamics, KKT, impact; 3-D and 6-D contacts) against the
//! contact oracle.

mod kkt_impact;
mod loops;
