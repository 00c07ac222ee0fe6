//! Driving-scene data.
