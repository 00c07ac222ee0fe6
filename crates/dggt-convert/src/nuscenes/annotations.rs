//! The annotated boxes of a nuScenes scene: the masked categories' `sample_annotation` rows in the global frame,
//! and boxes between two key frames interpolated the way drivestudio does (translation and size linearly,
//! rotation by slerp).
//!
//! Box axes (nuScenes `Box.corners`): x along the length, y along the width, z up; `size` is stored as width,
//! length, height and kept here as length, width, height.

use dggt_geom::glam::DVec3;
use dggt_geom::{Ego, GeomError, LogWorld, Rigid, slerp};

use super::tables::{AnnotationRow, SampleRow, Tables};
use crate::box_flow::WorldBox;
use crate::boxes::{AnnotatedBox, ObjectBox, ObjectClass};
use crate::error::Result;

/// The categories that masks and `instances/` keep, and their class (drivestudio's nuScenes lists).
const MASKED_CATEGORIES: &[(&str, ObjectClass)] = &[
    ("animal", ObjectClass::Human),
    ("human.pedestrian.adult", ObjectClass::Human),
    ("human.pedestrian.child", ObjectClass::Human),
    ("human.pedestrian.construction_worker", ObjectClass::Human),
    ("human.pedestrian.personal_mobility", ObjectClass::Human),
    ("human.pedestrian.police_officer", ObjectClass::Human),
    ("human.pedestrian.stroller", ObjectClass::Human),
    ("human.pedestrian.wheelchair", ObjectClass::Human),
    ("vehicle.bicycle", ObjectClass::Human),
    ("vehicle.motorcycle", ObjectClass::Human),
    ("vehicle.bus.bendy", ObjectClass::Vehicle),
    ("vehicle.bus.rigid", ObjectClass::Vehicle),
    ("vehicle.car", ObjectClass::Vehicle),
    ("vehicle.construction", ObjectClass::Vehicle),
    ("vehicle.emergency.ambulance", ObjectClass::Vehicle),
    ("vehicle.emergency.police", ObjectClass::Vehicle),
    ("vehicle.trailer", ObjectClass::Vehicle),
    ("vehicle.truck", ObjectClass::Vehicle),
];

/// A box of a masked class in the global frame.
#[derive(Debug, Clone)]
pub struct GlobalBox {
    pub id: String,
    pub class_name: &'static str,
    pub class: ObjectClass,
    pub global_from_box: Rigid<LogWorld, ObjectBox>,
    /// Length, width, height.
    pub size: DVec3,
}

impl GlobalBox {
    /// The box as box flow and tracks take it.
    pub fn world_box(&self) -> WorldBox {
        WorldBox { id: self.id.clone(), world_from_box: self.global_from_box, size: self.size }
    }

    /// The box in the ego frame whose pose in the global frame is `global_from_ego`.
    pub fn in_ego(&self, global_from_ego: &Rigid<LogWorld, Ego>) -> AnnotatedBox {
        AnnotatedBox {
            id: self.id.clone(),
            class_name: self.class_name,
            class: self.class,
            ego_from_box: global_from_ego.inverse() * self.global_from_box,
            size: self.size,
            speed: 0.0,
            has_points: true,
        }
    }
}

/// The sample's annotations of the masked classes.
pub fn global_boxes(tables: &Tables, sample: &SampleRow) -> Result<Vec<GlobalBox>> {
    let mut boxes = Vec::new();
    for annotation in tables.annotations(sample) {
        let referrer = format!("sample_annotation `{}`", annotation.token);
        let instance = tables.instance.get(&annotation.instance_token, &referrer)?;
        let category = tables.category.get(&instance.category_token, &format!("instance `{}`", instance.token))?;
        let Some(&(class_name, class)) = MASKED_CATEGORIES.iter().find(|(name, _)| *name == category.name) else {
            continue;
        };
        boxes.push(global_box(tables, annotation, class_name, class)?);
    }
    Ok(boxes)
}

fn global_box(
    tables: &Tables,
    annotation: &AnnotationRow,
    class_name: &'static str,
    class: ObjectClass,
) -> Result<GlobalBox> {
    let table = &tables.sample_annotation;
    let [width, length, height] = annotation.size;
    if !annotation.size.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(table.error(
            &annotation.token,
            "a positive finite size (w, l, h)",
            format!("{:?}", annotation.size),
        ));
    }
    Ok(GlobalBox {
        id: annotation.instance_token.clone(),
        class_name,
        class,
        global_from_box: table.rigid(&annotation.token, annotation.rotation, annotation.translation)?,
        size: DVec3::new(length, width, height),
    })
}

impl GlobalBox {
    /// The box a fraction `t` of the way from `self` to `later` (the same instance at a later key frame):
    /// translation and size linearly, rotation by slerp.
    pub fn interpolate(&self, later: &Self, t: f64) -> Result<Self, GeomError> {
        let (a, b) = (&self.global_from_box, &later.global_from_box);
        let rotation = slerp(a.rotation(), b.rotation(), t)?;
        let translation = a.translation().lerp(b.translation(), t);
        Ok(Self {
            global_from_box: Rigid::from_rotation_translation(rotation, translation)?,
            size: self.size.lerp(later.size, t),
            ..self.clone()
        })
    }
}
