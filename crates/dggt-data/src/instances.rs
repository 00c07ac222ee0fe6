//! The instance records of the scene-export layout as writers produce them: `instances/instances_info.json`
//! (keys `"0"`, `"1"`, … in order of first appearance) and `instances/frame_instances.json` (frame index ->
//! keys present), whose objects must keep their key order.

use serde::Serialize;
use serde::ser::{SerializeMap, Serializer};

/// A JSON object whose keys keep the given order.
pub struct OrderedMap<V>(pub Vec<(String, V)>);

impl<V: Serialize> Serialize for OrderedMap<V> {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (key, value) in &self.0 {
            map.serialize_entry(key, value)?;
        }
        map.end()
    }
}

/// One object's boxes, frame by frame: `obj_to_world` maps box coordinates (centre origin, x forward, y left,
/// z up) to the export's world, rows of a 4x4 matrix; `box_size` is `[length, width, height]` in metres.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameAnnotations {
    pub frame_idx: Vec<usize>,
    pub obj_to_world: Vec<[[f64; 4]; 4]>,
    pub box_size: Vec<[f64; 3]>,
}
