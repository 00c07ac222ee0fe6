//! Edits against the generator's ground truth at the fixture's resolution (front camera, 160x112, inputs at
//! frames 0, 4, 8 and 12 of seed 0), with images: per edit the PSNR on the edited object's pixels before and
//! after the edit against the generator's edited render, at input frames and between them; instance grouping
//! (count, coverage, purity); the cost of applying the edits and of rendering an edited view. Writes
//! `before | edited | truth | holes` strips (frames 6 and 8) as PNG into the folder given as the first argument
//! (default `target/edit-figures`; a relative path is the crate's folder's).
//!
//! `cargo bench -p dggt-edit --bench edit_truth -- "$PWD/docs/images"`

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use common::{colours, masked_psnr, object_mask, oracle, synth_sized, target, truth};
use dggt_edit::{Edit, EditedScene, apply_edits};
use dggt_geom::ImageSize;
use dggt_geom::glam::DVec3;
use dggt_synth::{ObjectEdit, SynthScene, WorldChange};
use dggt_test_data::median_ms;

const FRAMES: [usize; 4] = [0, 4, 8, 12];
const SHOWN: [usize; 4] = [2, 4, 6, 8];
/// The frames in the figures: an input and the frame between two inputs.
const PICTURED: [usize; 2] = [6, 8];

fn main() {
    let out =
        std::env::args().nth(1).filter(|a| !a.starts_with('-')).map_or("target/edit-figures".into(), PathBuf::from);
    std::fs::create_dir_all(&out).unwrap();
    let device = Device::flex();
    let synth = synth_sized(0, 13, 160, 112);
    let started = std::time::Instant::now();
    let scene = oracle(&synth, &FRAMES, &device);
    println!("ground-truth scene: {} Gaussians in {:.0} ms", scene.pixels.len(), started.elapsed().as_secs_f64() * 1e3);
    let file = out.join("edit-truth-scene.safetensors");
    let save_ms = median_ms(5, || dggt_scene::save_scene(&scene, &file).unwrap());
    let load_ms = median_ms(5, || drop(dggt_scene::load_scene(&file, &device).unwrap()));
    let bytes = std::fs::metadata(&file).unwrap().len();
    std::fs::remove_file(&file).unwrap();
    println!(
        "saved scene: {:.2} MB, written in {save_ms:.1} ms, read in {load_ms:.1} ms (medians of 5)",
        bytes as f64 / 1e6
    );
    let found = scene.pixels.instances().unwrap();
    println!("instances: {}", found.len());
    let mut car_instance = Vec::new();
    for car in 0..3u32 {
        let (mut votes, mut total) = (std::collections::BTreeMap::<usize, usize>::new(), 0usize);
        for (view, &frame) in FRAMES.iter().enumerate() {
            for (pixel, _) in object_mask(&synth, frame, car).iter().enumerate().filter(|(_, m)| **m) {
                total += 1;
                if let Some(k) = found.instance_of(view, pixel) {
                    *votes.entry(k).or_default() += 1;
                }
            }
        }
        let (&k, &own) = votes.iter().max_by_key(|(_, count)| **count).unwrap();
        let labelled: usize = (0..FRAMES.len())
            .map(|view| (0..scene.pixels.per_view()).filter(|&p| found.instance_of(view, p) == Some(k)).count())
            .sum();
        println!(
            "car {car}: instance {k}, coverage {:.3} of {total} pixels, purity {:.3} of {labelled}",
            own as f64 / total as f64,
            own as f64 / labelled as f64
        );
        car_instance.push(k as u32);
    }
    let size = scene.pixels.size;
    let cases: Vec<(&str, Vec<Edit>, SynthScene, u32)> = vec![
        (
            "remove-passing-car",
            vec![Edit::remove(&car_instance[2].to_string()).unwrap()],
            synth.edited(&[ObjectEdit::Remove(2)]).unwrap(),
            2,
        ),
        (
            "remove-lead-car",
            vec![Edit::remove(&car_instance[0].to_string()).unwrap()],
            synth.edited(&[ObjectEdit::Remove(0)]).unwrap(),
            0,
        ),
        (
            "move-passing-car",
            vec![Edit::moved(&format!("{}:0,3,0,0", car_instance[2])).unwrap()],
            synth
                .edited(&[ObjectEdit::Move { object: 2, change: WorldChange::translation(DVec3::new(0.0, 3.0, 0.0)) }])
                .unwrap(),
            2,
        ),
        {
            let parked = common::largest_parked_car(&synth, 4);
            let edits = vec![Edit::remove_box(&common::box_around(parked)).unwrap()];
            ("remove-parked-car-by-box", edits, synth.edited(&[ObjectEdit::Remove(parked.id())]).unwrap(), parked.id())
        },
    ];
    println!("| edit | frame | pixels | PSNR before (dB) | PSNR after (dB) | holes |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (name, edits, truth_scene, car) in cases {
        let apply_ms = median_ms(5, || drop(apply_edits(scene.clone(), &edits, &device).unwrap()));
        let edited = apply_edits(scene.clone(), &edits, &device).unwrap();
        let mut strips = Vec::new();
        for frame in SHOWN {
            let mask: Vec<bool> = object_mask(&synth, frame, car)
                .iter()
                .zip(object_mask(&truth_scene, frame, car))
                .map(|(a, b)| *a || b)
                .collect();
            let (row, psnr_before, psnr_after, holes) = strip(&edited, &synth, &truth_scene, frame, &mask, size);
            println!(
                "| {name} | {frame} | {} | {psnr_before:.2} | {psnr_after:.2} | {holes} |",
                mask.iter().filter(|m| **m).count()
            );
            if PICTURED.contains(&frame) {
                strips.push(row);
            }
        }
        let view = target(&synth, 6);
        let render_ms = median_ms(5, || drop(edited.render(&view).unwrap()));
        println!(
            "{name}: applying the edit {apply_ms:.1} ms, rendering an edited view {render_ms:.1} ms (medians of 5)"
        );
        write_strips(&out.join(format!("edit-{name}.png")), size, &strips);
    }
    println!("figures in {}", out.display());
}

/// `before | edited | truth | holes` of `frame` (interleaved RGB, four images wide), the PSNRs on `mask` and
/// the number of holes.
fn strip(
    edited: &EditedScene,
    synth: &SynthScene,
    truth_scene: &SynthScene,
    frame: usize,
    mask: &[bool],
    size: ImageSize,
) -> (Vec<f32>, f64, f64, usize) {
    let view = target(synth, frame);
    let (before, after) = (edited.original.render(&view).unwrap(), edited.render(&view).unwrap());
    let alpha =
        |render: &dggt_scene::ViewRender| -> Vec<f32> { render.alpha.clone().into_data().try_into_vec().unwrap() };
    let holes: Vec<bool> = alpha(&before).iter().zip(alpha(&after)).map(|(b, a)| *b >= 0.5 && a < 0.5).collect();
    let (before, after) = (colours(before), colours(after));
    let truth = truth(truth_scene, frame);
    let (psnr_before, psnr_after) = (masked_psnr(&before, &truth, mask), masked_psnr(&after, &truth, mask));
    let hole_image: Vec<f32> = holes.iter().flat_map(|&h| if h { [1.0, 0.0, 1.0] } else { [0.0; 3] }).collect();
    let width = size.width as usize;
    let row: Vec<f32> = (0..size.height as usize)
        .flat_map(|y| {
            [&before, &after, &truth, &hole_image]
                .into_iter()
                .flat_map(move |image| image[y * width * 3..(y + 1) * width * 3].to_vec())
        })
        .collect();
    (row, psnr_before, psnr_after, holes.iter().filter(|h| **h).count())
}

fn write_strips(path: &Path, size: ImageSize, strips: &[Vec<f32>]) {
    let all: Vec<f32> = strips.concat();
    let size = ImageSize::new(size.width * 4, size.height * strips.len() as u32).unwrap();
    dggt_formats::images::write_rgb_png(path, size, &all).unwrap();
}
