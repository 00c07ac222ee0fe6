//! Integration tests of the rasteriser: parity with gsplat, finite differences, per-view opacities,
//! robustness and determinism, empty scenes, and the burn tensor op against the host functions.

mod empty;
mod finite_difference;
mod parity;
mod per_view;
mod scenes;
mod stress;
mod tensor_op;
