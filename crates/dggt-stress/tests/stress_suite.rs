//! The bounded stress suite, as CI runs it: every case passes on the default CPU backend, every stage is
//! actually probed, and the probe itself notices what it is there to notice.

use std::path::PathBuf;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_run::compute_pool::on_pool_worker;
use dggt_stress::{Expect, Probe, Stage, StressOptions, StressScope, run_suite};

/// The shared metrics vectors (LPIPS-Alex and VGG-16 weights): the LPIPS and Gram terms are part of the suite,
/// so a missing folder fails the test, naming where it looked.
fn loss_weights() -> PathBuf {
    let dir = dggt_test_data::parity("metrics");
    for file in ["lpips_alex.safetensors", "vgg16_features.safetensors"] {
        assert!(
            dir.join(file).is_file(),
            "{} not found: the stress suite's LPIPS and Gram terms need the shared metrics vectors (set \
             DGGT_PARITY_DIR to the shared parity folder)",
            dir.join(file).display()
        );
    }
    dir
}

#[test]
fn the_bounded_suite_finds_nothing_non_finite() {
    let options = StressOptions { scope: StressScope::Bounded, loss_weights: Some(loss_weights()) };
    // On one of rayon's threads, as `dggt stress` runs it.
    let report = on_pool_worker(|| run_suite(&options, &Device::flex())).expect("the suite runs");
    println!("{}", report.table());
    assert!(report.passed(), "{}", report.table());
    for group in ["geometry", "crafted", "network"] {
        assert!(report.cases.iter().filter(|c| c.group == group).count() >= 5, "too few {group} cases");
    }
    assert!(report.cases.iter().any(|c| c.expect == Expect::Rejected), "no invalid input is exercised");
    let learnt = report.cases.iter().filter(|c| c.name.starts_with("learnt flow")).count();
    assert!(learnt >= 6, "the learnt flow's extremes: {learnt} cases");
    // flex computes in f16 and bf16: the reduced-precision network cases run, none is skipped.
    assert_eq!(report.skipped().count(), 0, "{}", report.table());
    for precision in [", f16)", ", bf16)"] {
        assert!(report.cases.iter().any(|c| c.name.ends_with(precision)), "no {precision} network case");
    }
    for (i, stage) in Stage::ALL.iter().enumerate() {
        let checked: usize = report.cases.iter().map(|c| c.checked[i]).sum();
        assert!(checked > 0, "nothing was checked at the {stage} stage");
    }
}

/// What the wgpu device adds, through the CubeCL kernels and burn's wgpu backend with fusion (and autotune where
/// the build has it; the test suite's `wgpu-untuned` does not): every crafted case (the rasteriser at its
/// extremes, training included) and one network case, each new kernel compiled once (minutes on the software
/// driver, hence not the whole network group). Without the LPIPS and Gram terms: their VGG features need buffers
/// beyond the 128 MiB storage binding of Mesa's software Vulkan driver.
///
/// The device's buffers are limited in the proportion of the network case's workload to the full-size training
/// step's (see [`buffer_limit`]): the full-size step once failed on an H100 asking for 4 GiB at once, so a buffer
/// growing with the workload past what a GPU gives one buffer fails here first. One process compiles the
/// network's kernels for both checks.
#[cfg(feature = "wgpu")]
#[test]
fn the_device_suite_finds_nothing_non_finite_on_wgpu_under_a_lowered_buffer_limit() {
    let limit = buffer_limit::bytes();
    let device = buffer_limit::device(limit);
    let past_the_limit = Tensor::<1>::zeros([limit as usize / 4 + 1024], &device).try_into_data();
    assert!(past_the_limit.is_err(), "a {limit}-byte limit did not stop a larger buffer");

    let options = StressOptions { scope: StressScope::Device, loss_weights: None };
    let report = run_suite(&options, &device).expect("the suite runs");
    println!("{}", report.table());
    assert!(report.passed(), "under a {} KiB buffer limit:\n{}", limit >> 10, report.table());
    assert_eq!(report.skipped().count(), 0, "{}", report.table());
    assert!(report.cases.iter().filter(|c| c.group == "crafted").count() >= 20, "{}", report.table());
    let network: Vec<&str> = report.cases.iter().filter(|c| c.group == "network").map(|c| c.name.as_str()).collect();
    assert_eq!(network, [buffer_limit::NETWORK_CASE], "the device scope runs one network case");
}

/// The lowered buffer limit of the device test.
#[cfg(feature = "wgpu")]
mod buffer_limit {
    use burn::backend::wgpu::{RuntimeOptions, WgpuSetup, init_device, wgpu};
    use burn::tensor::Device;
    use dggt_bench::compute::Scale;

    /// The most a wgpu device gives one buffer at full size (`max_storage_buffer_binding_size` on desktop GPUs).
    const FULL_SIZE_LIMIT: u64 = 1 << 32;

    /// The device scope's one network case: 3 inputs and the suite's 2 targets at 70x56.
    pub const NETWORK_CASE: &str = "random images (3 at 70x56)";
    const NETWORK_CASE_VIEWS: u64 = 3 + 2;
    const NETWORK_CASE_PIXELS: u64 = 70 * 56;

    /// `FULL_SIZE_LIMIT` scaled by the network case's views x pixels against the full-size training step's (the
    /// compute suite's: its inputs and twice as many targets at its image size).
    pub fn bytes() -> u64 {
        let full = Scale::Full.spec();
        let full_views = 3 * full.train_inputs as u64;
        let full_pixels = u64::from(full.image.width) * u64::from(full.image.height);
        FULL_SIZE_LIMIT * NETWORK_CASE_VIEWS * NETWORK_CASE_PIXELS / (full_views * full_pixels)
    }

    /// A wgpu device on the first Vulkan adapter whose storage buffers are limited to `bytes`.
    pub fn device(bytes: u64) -> Device {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = futures_lite::future::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .expect("a Vulkan adapter (install Mesa's software driver, mesa-vulkan-drivers, where there is no GPU)");
        let limits =
            wgpu::Limits { max_buffer_size: bytes, max_storage_buffer_binding_size: bytes, ..adapter.limits() };
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("lowered buffer limit"),
            required_features: adapter.features().difference(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS),
            required_limits: limits,
            memory_hints: wgpu::MemoryHints::MemoryUsage,
            ..Default::default()
        };
        let (device, queue) =
            futures_lite::future::block_on(adapter.request_device(&descriptor)).expect("a device with lowered limits");
        let setup = WgpuSetup { instance, adapter, device, queue, backend: wgpu::Backend::Vulkan };
        Device::from(init_device(setup, RuntimeOptions::default()))
    }
}

#[test]
fn the_probe_reports_non_finite_values_and_broken_invariants() {
    let device = Device::flex();
    let mut probe = Probe::default();
    let clean = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 2.0, 3.0, 4.0], [2, 2]), &device);
    probe.tensor(Stage::Render, "clean", &clean);
    assert!(probe.findings().is_empty());
    let dirty = Tensor::<1>::from_data(TensorData::new(vec![1.0f32, f32::NAN, f32::INFINITY], [3]), &device);
    probe.tensor(Stage::Losses, "dirty", &dirty);
    probe.require(Stage::Geometry, "rotation", false, "norm 2");
    let findings = probe.findings();
    assert_eq!(findings.len(), 2);
    assert_eq!((findings[0].stage, findings[0].bad, findings[0].total), (Stage::Losses, 2, 3));
    assert_eq!(findings[1].stage, Stage::Geometry);
    assert_eq!(probe.checked(Stage::Render), 4);
}
