//! What finding the moving objects costs, on the default CPU thread pool: `find_instances` over ray-cast point
//! maps of two cars (the tests' scene: one turning, one oncoming) at the main job's size and at the release's.
//!
//! `cargo bench -p dggt-instances --bench find`:
//! - **fixture**: 4 input views of 84 x 84 (the main job's network size);
//! - **release**: 12 input views of 518 x 350 (3 cameras at 4 times, the release's input size), each time's
//!   three views seeing the same cars, so that every object is joined across cameras.
//!
//! Medians of seven runs after a warm-up, with the clustering, linking and registration of every step.

#[path = "../tests/common/cars.rs"]
mod cars;

use cars::{Camera, PointMap, points_of, views_at};
use dggt_instances::{InstanceSettings, ViewPoints, find_instances};
use dggt_test_data::median_ms;

fn measure(name: &str, camera: Camera, cameras: usize) {
    let times: Vec<(f64, bool)> = (0..4).map(|i| (i as f64 / 3.0, true)).collect();
    let maps: Vec<PointMap> = views_at(camera, &times);
    let views: Vec<ViewPoints> = points_of(camera, &maps)
        .into_iter()
        .flat_map(|view| (0..cameras).map(move |rig_camera| ViewPoints { rig_camera, ..view }))
        .collect();
    let settings = InstanceSettings::default();
    let found = find_instances(&views, &settings).expect("the views are consistent");
    let pixels: usize = found.instances.iter().flat_map(|i| &i.appearances).map(|a| a.pixels).sum();
    let ms = median_ms(7, || {
        std::hint::black_box(find_instances(&views, &settings).expect("the views are consistent"));
    });
    println!(
        "{name}: {} views of {}x{}, {} objects over {pixels} dynamic pixels: {ms:.2} ms",
        views.len(),
        camera.width,
        camera.height,
        found.len()
    );
}

fn main() {
    measure("fixture", Camera { width: 84, height: 84, focal: 63.0 }, 1);
    measure("release", Camera { width: 518, height: 350, focal: 390.0 }, 3);
}
