//! Cross-checks against Pinocchio 4.1.0 fixtures (`tests/fixtures`).

mod contacts;
mod contacts6d;
mod dynamics;
mod loops;
mod pin_map;
mod second_order;
