//! Seeded draws from the backend's random generator, one caller at a time.
//!
//! burn keeps one random generator per backend and process: `Device::seed` resets it for every thread, and every
//! `Tensor::random` anywhere advances it. Two threads that each seed and then draw — two runs started in one
//! process, tests running side by side — interleave their draws and both get weights no seed describes. A fresh
//! network is drawn inside [`with_seed`], which seeds and draws under one process-wide lock, so that its weights
//! are a function of the seed alone. Draws made outside it (a caller's own `Tensor::random`) are not ordered
//! by the lock; the project draws everything that must be reproducible through it.

use std::sync::{Mutex, PoisonError};

use burn::tensor::Device;

static TURN: Mutex<()> = Mutex::new(());

/// Seeds `device`'s backend with `seed` and runs `draw` while no other [`with_seed`] call can draw.
pub fn with_seed<T>(device: &Device, seed: u64, draw: impl FnOnce() -> T) -> T {
    // A caller that panicked mid-draw leaves nothing for the next one to repair: it reseeds before drawing.
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    device.seed(seed);
    draw()
}
