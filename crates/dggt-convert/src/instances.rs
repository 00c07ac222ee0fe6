//! `instances/instances_info.json` and `instances/frame_instances.json`: every annotated object of the masked
//! classes (no speed filter), with its box pose in the log's world per frame.
//!
//! `instances_info.json` maps keys `"0"`, `"1"`, … (order of first appearance) to `{"id": <dataset object id>,
//! "class_name", "frame_annotations": {"frame_idx": [...], "obj_to_world": [4x4 rows, ...], "box_size":
//! [[length, width, height], ...]}}`. `obj_to_world` maps box coordinates (centre origin, x forward, y left,
//! z up) to the world of `ego_pose/` (the log's own world, not re-anchored). `frame_instances.json` maps every
//! frame index to the keys present in it.

use std::collections::HashMap;

use dggt_data::instances::{FrameAnnotations, OrderedMap};
use dggt_data::{ExportLayout, io};
use dggt_geom::{Ego, LogWorld, Rigid};
use serde::Serialize;

use crate::boxes::AnnotatedBox;
use crate::error::{ConvertError, Result};

#[derive(Serialize)]
struct Instance {
    id: String,
    class_name: &'static str,
    frame_annotations: FrameAnnotations,
}

/// The objects seen so far, frame by frame.
#[derive(Default)]
pub struct InstanceLog {
    instances: Vec<Instance>,
    key_of_id: HashMap<String, usize>,
    per_frame: Vec<Vec<usize>>,
}

impl InstanceLog {
    /// Gives each new object of `boxes` its key, in their order: called with a frame's boxes before its masks
    /// are drawn ([`Self::key`]), it assigns the keys [`Self::add_frame`] would.
    pub fn register(&mut self, boxes: &[AnnotatedBox]) {
        for object in boxes {
            self.key_or_new(object);
        }
    }

    /// The key of the object with dataset id `id`, once registered.
    pub fn key(&self, id: &str) -> Option<usize> {
        self.key_of_id.get(id).copied()
    }

    fn key_or_new(&mut self, object: &AnnotatedBox) -> usize {
        *self.key_of_id.entry(object.id.clone()).or_insert_with(|| {
            self.instances.push(Instance {
                id: object.id.clone(),
                class_name: object.class_name,
                frame_annotations: FrameAnnotations::default(),
            });
            self.instances.len() - 1
        })
    }

    /// Records the boxes of `frame` (frames are added in order, each once).
    pub fn add_frame(&mut self, frame: usize, world_from_ego: &Rigid<LogWorld, Ego>, boxes: &[AnnotatedBox]) {
        self.per_frame.resize_with(frame + 1, Vec::new);
        for object in boxes {
            let key = self.key_or_new(object);
            let annotations = &mut self.instances[key].frame_annotations;
            annotations.frame_idx.push(frame);
            annotations.obj_to_world.push((*world_from_ego * object.ego_from_box).to_rows());
            annotations.box_size.push(object.size.to_array());
            self.per_frame[frame].push(key);
        }
    }

    pub fn len(&self) -> usize {
        self.instances.len()
    }

    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }

    /// Writes both files atomically.
    pub fn write(&self, layout: &ExportLayout) -> Result<()> {
        let info =
            OrderedMap(self.instances.iter().enumerate().map(|(key, instance)| (key.to_string(), instance)).collect());
        io::write_atomically(&layout.instances_info(), &json_bytes("instances_info.json", &info)?)?;
        let frames =
            OrderedMap(self.per_frame.iter().enumerate().map(|(frame, keys)| (frame.to_string(), keys)).collect());
        io::write_atomically(&layout.frame_instances(), &json_bytes("frame_instances.json", &frames)?)?;
        Ok(())
    }
}

pub(crate) fn json_bytes(what: &'static str, value: &impl Serialize) -> Result<Vec<u8>> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|source| ConvertError::Json { what, source })?;
    bytes.push(b'\n');
    Ok(bytes)
}
