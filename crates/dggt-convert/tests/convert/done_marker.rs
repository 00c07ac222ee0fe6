//! The done marker of a batch conversion records its source's sizes and times: a re-run skips a scene whose
//! source is unchanged, and refuses one whose source was replaced behind the same path (naming what differs)
//! until told to convert it again. A scene another command is converting is not touched.

use crate::nuscenes_scene;
use std::path::Path;
use std::time::{Duration, SystemTime};

use dggt_convert::batch::{
    ConvertOptions, Dataset, ExistingScenes, FailurePolicy, Outcome, Progress, ProgressUnit, SegmentJob,
    convert_segments, jobs,
};
use dggt_convert::depth_flows::DepthFlows;
use dggt_convert::marker::Refusal;
use dggt_convert::masks::DynamicMaskStyle;
use dggt_convert::nuscenes::{FrameRate, NuScenesVersion};
use dggt_convert::sky::SkyMasks;

struct Silent;

impl Progress for Silent {
    fn started(&self, _: &SegmentJob, _: u64, _: ProgressUnit) {}
    fn advanced(&self, _: &SegmentJob, _: u64) {}
    fn finished(&self, _: &SegmentJob, _: &Outcome) {}
}

/// Converts every scene of the nuScenes root into `out`; the one outcome.
fn convert(root: &Path, out: &Path, existing: ExistingScenes) -> Outcome {
    let dataset = Dataset::NuScenes(NuScenesVersion::Mini, FrameRate::KeyFrames);
    let options = ConvertOptions {
        cameras: vec![0],
        sky_masks: SkyMasks::None,
        depth_flows: DepthFlows::None,
        dynamic_masks: DynamicMaskStyle::Drivestudio,
    };
    let jobs = jobs(&dataset, root, out, None).unwrap();
    let mut outcomes = convert_segments(&dataset, &jobs, &options, 1, FailurePolicy::Stop, existing, &Silent).unwrap();
    assert_eq!(outcomes.len(), 1, "one outcome for the one segment");
    outcomes.remove(0)
}

#[test]
fn a_source_replaced_behind_the_same_path_is_not_taken_for_the_one_converted() {
    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes_scene::write_root(dir.path(), |_| {});
    let out = dir.path().join("scenes");
    assert!(matches!(convert(&root, &out, ExistingScenes::Keep), Outcome::Converted(_)));
    assert!(matches!(convert(&root, &out, ExistingScenes::Keep), Outcome::AlreadyDone(_)), "unchanged: skipped");

    // The same tables written again later (a release re-downloaded, a table edited and saved).
    let table = root.join("v1.0-mini/sample_data.json");
    let later = SystemTime::now() + Duration::from_secs(60);
    std::fs::File::options().append(true).open(&table).unwrap().set_modified(later).unwrap();
    let refused = convert(&root, &out, ExistingScenes::Keep);
    let Outcome::Refused(Refusal::Differs { field, recorded, requested }) = &refused else {
        panic!("a replaced source was reused: {refused:?}")
    };
    assert_eq!(*field, "source files");
    assert_ne!(recorded, requested);
    assert!(refused_text(&refused).contains("converted earlier with source files"), "{}", refused_text(&refused));

    assert!(matches!(convert(&root, &out, ExistingScenes::Replace), Outcome::Converted(_)), "--overwrite");
    assert!(matches!(convert(&root, &out, ExistingScenes::Keep), Outcome::AlreadyDone(_)), "then skipped again");
}

fn refused_text(outcome: &Outcome) -> String {
    match outcome {
        Outcome::Refused(refusal) => refusal.to_string(),
        other => format!("{other:?}"),
    }
}

#[test]
fn a_scene_another_command_is_converting_fails_naming_it_and_is_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes_scene::write_root(dir.path(), |_| {});
    let out = dir.path().join("scenes");
    let held = dggt_data::output_lock::OutputLock::acquire(&out.join("000"), "dggt convert (the first)").unwrap();
    let outcome = convert(&root, &out, ExistingScenes::Replace);
    let Outcome::Failed(error) = &outcome else { panic!("converted under another command: {outcome:?}") };
    assert!(error.to_string().contains("in use by `dggt convert (the first)`"), "{error}");
    assert!(!out.join("000").exists() && !out.join("000.partial").exists());
    drop(held);
    assert!(matches!(convert(&root, &out, ExistingScenes::Keep), Outcome::Converted(_)));
    assert!(!held_lock(&out), "the lock is released when the scene is done");
}

/// Whether a lock file is left in `out`.
fn held_lock(out: &Path) -> bool {
    std::fs::read_dir(out)
        .unwrap()
        .flatten()
        .any(|entry| entry.file_name().to_string_lossy().ends_with(dggt_data::output_lock::LOCK_SUFFIX))
}
