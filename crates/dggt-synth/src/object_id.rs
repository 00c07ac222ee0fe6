//! The identity of one object of a scene: the scene lists its objects by it ([`crate::scene`]), edits name the
//! object they change ([`crate::edit`]), and errors the object at fault ([`crate::SynthError`]).

/// Identifies one object of a scene. The instance ids of the export are the ids of the cars.
pub type ObjectId = u32;
