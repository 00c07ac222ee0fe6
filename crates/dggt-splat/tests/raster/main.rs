//! Integration tests of the rasteriser: parity with gsplat, finite differences, per-view opacities,
//! robustness and determinism, empty scenes.

mod empty;
mod finite_difference;
mod parity;
mod per_view;
mod scenes;
mod stress;
