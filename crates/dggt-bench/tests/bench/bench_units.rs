//! Unit tests of the sweep's pure parts: the configurations a sweep produces, the choice of input and target
//! frames, opacity parsing, and the Pareto front.

use dggt_bench::frames::plan_frames;
use dggt_bench::knobs::*;
use dggt_bench::pareto_front;
use dggt_infer::SkyChoice;
use dggt_scene::DynamicMotion;

#[test]
fn one_knob_at_a_time_without_duplicates() {
    let spec = SweepSpec::default();
    let rows = spec.configurations();
    assert_eq!(rows[0].varied, Varied::Reference);
    assert_eq!(rows[0].knobs.culling, Culling::Off);
    assert_eq!(rows[1].knobs, spec.baseline);
    // 3 other widths, 2 other frame counts, 2 other thresholds, 2 other precisions, sky off, 3 skips, held and
    // instances.
    assert_eq!(rows.len(), 2 + 3 + 2 + 2 + 2 + 1 + 3 + 2);
    for row in &rows[2..] {
        let b = spec.baseline;
        let k = row.knobs;
        let differing = [
            k.width != b.width,
            k.input_frames != b.input_frames,
            k.culling != b.culling,
            k.precision != b.precision,
            k.sky != b.sky,
            k.skips != b.skips,
            k.motion != b.motion,
        ];
        assert_eq!(differing.iter().filter(|d| **d).count(), 1, "{}", k.label());
    }
}

#[test]
fn full_grid_adds_every_combination_once() {
    let spec = SweepSpec {
        widths: vec![28, 42],
        input_frames: vec![2, 3],
        min_opacities: vec![0.1],
        precisions: vec![Precision::F32],
        sky: vec![SkyChoice::Render, SkyChoice::Skip],
        skips: vec![],
        motions: vec![],
        full_grid: true,
        baseline: Knobs {
            width: 28,
            input_frames: 2,
            culling: Culling::MinOpacity(0.1),
            precision: Precision::F32,
            sky: SkyChoice::Render,
            skips: Skips::Nothing,
            motion: DynamicMotion::Velocity,
        },
    };
    let rows = spec.configurations();
    // The reference plus the 8 grid points (the baseline is one of them).
    assert_eq!(rows.len(), 1 + 8);
}

#[test]
fn opacities_parse_as_fractions_and_decimals() {
    assert_eq!(parse_opacity("1/255").unwrap(), 1.0 / 255.0);
    assert_eq!(parse_opacity("0.05").unwrap(), 0.05);
    assert!(parse_opacity("2").is_err());
    assert!(parse_opacity("x").is_err());
    assert_eq!(format_opacity(dggt_scene::MIN_OPACITY), "1/255");
    assert_eq!(Precision::parse("BF16").unwrap(), Precision::Bf16);
    assert_eq!(Skips::parse("Motion").unwrap(), Skips::StillMotion);
    assert!(Skips::parse("everything").is_err());
    assert_eq!(parse_motion("Instances").unwrap(), DynamicMotion::Instances);
    assert!(parse_motion("tracker").unwrap_err().to_string().contains("velocity, instances or learnt"));
    assert!(Precision::parse("f8").is_err());
}

#[test]
fn twenty_frames_give_four_targets_and_sixteen_inputs() {
    let plan = plan_frames(20, None).unwrap();
    assert_eq!(plan.targets, vec![2, 7, 12, 17]);
    assert_eq!(plan.pool.len(), 16);
    assert_eq!(plan.inputs(16).unwrap(), plan.pool);
    let four = plan.inputs(4).unwrap();
    assert_eq!(four.len(), 4);
    assert_eq!((four[0], four[3]), (0, 19));
    assert!(four.iter().all(|f| !plan.targets.contains(f)));
    assert!(four.windows(2).all(|w| w[0] < w[1]));
    assert!(plan.inputs(17).unwrap_err().to_string().contains("16 non-target frames"));
}

#[test]
fn targets_must_be_bracketed() {
    assert!(plan_frames(10, Some(&[0])).is_err());
    assert!(plan_frames(10, Some(&[9])).is_err());
    assert_eq!(plan_frames(10, Some(&[5, 3, 5])).unwrap().targets, vec![3, 5]);
    assert!(plan_frames(3, None).is_err());
}

#[test]
fn keeps_the_undominated_points() {
    // (time, quality)
    let points = [
        (1.0, 20.0), // fastest: on the front
        (2.0, 25.0), // better and slower: on the front
        (2.5, 24.0), // dominated by (2.0, 25.0)
        (3.0, 30.0), // best: on the front
        (3.0, 29.0), // as slow as (3.0, 30.0) but worse
        (0.5, f64::NAN),
    ];
    assert_eq!(pareto_front(&points), vec![true, true, false, true, false, false]);
}

#[test]
fn equal_points_both_stay_and_infinity_wins() {
    let points = [(1.0, 10.0), (1.0, 10.0), (5.0, f64::INFINITY), (6.0, f64::INFINITY)];
    assert_eq!(pareto_front(&points), vec![true, true, true, false]);
    assert!(pareto_front(&[]).is_empty());
}
