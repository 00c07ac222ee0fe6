//! The nuScenes converter on crafted tables: a `sample_data` file name that leads out of the data root (a `..`
//! component, an absolute path, a symbolic link) or names a JPEG that is not one is refused naming the table, the
//! row and the field, and nothing of the file it points at reaches the export.

use crate::nuscenes_scene;
use std::path::Path;

use dggt_convert::depth_flows::DepthFlows;
use dggt_convert::masks::DynamicMaskStyle;
use dggt_convert::nuscenes::{FrameRate, NuScenesOptions, NuScenesVersion, Tables, convert_scene};
use dggt_convert::sky::SkyMasks;
use serde_json::Value;

/// What the crafted rows point at, outside the data root.
const SECRET: &[u8] = b"root:x:0:0:not for the export\n";

/// Row of the front camera at sample 0 and of the lidar sweep at sample 0 (sensors 0..7 per reading).
const FRONT_CAMERA_ROW: usize = 0;
const LIDAR_ROW: usize = 6;

fn convert(root: &Path, out: &Path) -> Result<usize, String> {
    let tables = Tables::read(root, &NuScenesVersion::Mini).map_err(|e| e.to_string())?;
    let options = NuScenesOptions {
        cameras: vec![0],
        sky_masks: SkyMasks::None,
        depth_flows: DepthFlows::None,
        dynamic_masks: DynamicMaskStyle::Drivestudio,
        rate: FrameRate::KeyFrames,
    };
    convert_scene(&tables, 0, out, &options, &|_| {}).map(|s| s.frames).map_err(|e| e.to_string())
}

/// Rewrites the data root's `sample_data` table with row `row`'s `filename` set to `filename` (after the files
/// are written, so that the test writes nothing outside its folder).
fn set_filename(root: &Path, row: usize, filename: &str) {
    let path = root.join("v1.0-mini/sample_data.json");
    let mut rows: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    rows[row]["filename"] = filename.into();
    std::fs::write(&path, serde_json::to_vec(&rows).unwrap()).unwrap();
}

/// Whether any file under `folder` holds the secret's bytes.
fn holds_the_secret(folder: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(folder) else { return false };
    entries.flatten().any(|entry| {
        let path = entry.path();
        if path.is_dir() { holds_the_secret(&path) } else { std::fs::read(&path).is_ok_and(|bytes| bytes == SECRET) }
    })
}

/// Converts a root whose row `row` names `filename` (with the secret beside the root, and `prepare` run on the
/// root first); the error, checked to name the table, the row and the field, and that no secret was exported.
fn refused(row: usize, filename: impl FnOnce(&Path) -> String, prepare: impl FnOnce(&Path)) -> String {
    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes_scene::write_root(dir.path(), |_| {});
    std::fs::write(dir.path().join("secret.jpg"), SECRET).unwrap();
    prepare(&root);
    set_filename(&root, row, &filename(&root));
    let out = dir.path().join("000");
    let error = convert(&root, &out).unwrap_err();
    let token = if row == LIDAR_ROW { "data-s0-6" } else { "data-s0-0" };
    assert!(error.contains("sample_data.json") && error.contains(token) && error.contains("`filename`"), "{error}");
    assert!(!holds_the_secret(&out), "{error}: the secret reached the export");
    error
}

#[test]
fn a_file_name_with_a_parent_component_is_refused_naming_the_table_row_and_field() {
    let error = refused(FRONT_CAMERA_ROW, |_| "../secret.jpg".into(), |_| {});
    assert!(error.contains("`..` component"), "{error}");
    let error = refused(FRONT_CAMERA_ROW, |_| "../../../../../../../../etc/passwd".into(), |_| {});
    assert!(error.contains("`..` component") && error.contains("etc/passwd"), "{error}");
    let error = refused(LIDAR_ROW, |_| "samples/../../secret.jpg".into(), |_| {});
    assert!(error.contains("`..` component"), "{error}");
}

#[test]
fn an_absolute_file_name_is_refused() {
    let error =
        refused(FRONT_CAMERA_ROW, |root| root.parent().unwrap().join("secret.jpg").display().to_string(), |_| {});
    assert!(error.contains("is absolute"), "{error}");
    let error = refused(LIDAR_ROW, |root| root.parent().unwrap().join("secret.jpg").display().to_string(), |_| {});
    assert!(error.contains("is absolute"), "{error}");
}

#[cfg(unix)]
#[test]
fn a_symbolic_link_out_of_the_data_root_is_refused() {
    let link = |root: &Path| {
        std::os::unix::fs::symlink(root.parent().unwrap().join("secret.jpg"), root.join("samples/CAM_FRONT/link.jpg"))
            .unwrap();
    };
    let error = refused(FRONT_CAMERA_ROW, |_| "samples/CAM_FRONT/link.jpg".into(), link);
    assert!(error.contains("leads outside"), "{error}");
    let link_folder =
        |root: &Path| std::os::unix::fs::symlink(root.parent().unwrap(), root.join("samples/up")).unwrap();
    let error = refused(FRONT_CAMERA_ROW, |_| "samples/up/secret.jpg".into(), link_folder);
    assert!(error.contains("leads outside"), "{error}");
}

#[test]
fn a_jpeg_name_on_a_file_that_is_no_jpeg_is_refused_and_a_real_one_converts() {
    let not_a_jpeg =
        |root: &Path| std::fs::write(root.join("samples/CAM_FRONT/fake.jpg"), b"GIF89a, not a JPEG").unwrap();
    let error = refused(FRONT_CAMERA_ROW, |_| "samples/CAM_FRONT/fake.jpg".into(), not_a_jpeg);
    assert!(error.contains("a JPEG") && error.contains("fake.jpg"), "{error}");

    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes_scene::write_root(dir.path(), |_| {});
    assert_eq!(convert(&root, &dir.path().join("000")), Ok(2), "the untouched tables convert");
}
