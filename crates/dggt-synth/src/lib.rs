//! Synthetic driving scenes.
