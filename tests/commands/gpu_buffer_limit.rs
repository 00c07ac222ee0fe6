//! No single device buffer may grow past what a GPU gives one buffer: the full-size training step once failed
//! on an H100 asking for 4 GiB at once. This runs the compute suite's reduced training step (the tiny network,
//! 2 inputs and 4 targets at 70x56) on a wgpu device (on CI, Mesa's software Vulkan driver) whose buffer limit
//! is lowered in the proportion of the reduced workload to the full one (views x pixels: 12 x 518 x 350 against
//! 6 x 70 x 56), so that a buffer growing with the workload past 4 GiB at full size fails here first.
//!
//! The step runs in a child process of this test binary, which ends with `_exit` once it has reported: the
//! software driver crashes tearing down a second, hand-made device at process exit, after the work is done.
#![cfg(feature = "wgpu-backend")]

use std::io::Write as _;
use std::process::Command;

use burn::backend::wgpu::{RuntimeOptions, WgpuSetup, init_device, wgpu};
use burn::tensor::{Device, Tensor};
use dggt_bench::compute::{ComputeOptions, Scale, ScaleSpec, Workload, run_compute};

/// The most a wgpu device gives one buffer at full size (`max_storage_buffer_binding_size` on desktop GPUs).
const FULL_SIZE_LIMIT: u64 = 1 << 32;

/// Set in the child process that runs the step.
const CHILD: &str = "DGGT_BUFFER_LIMIT_CHILD";

/// What the child prints when the step ran under the limit.
const PASSED: &str = "reduced training step under the lowered buffer limit: ran";

/// Views (inputs and their twice as many targets) times pixels of a training step at `spec`'s sizes.
fn pixel_views(spec: &ScaleSpec) -> u64 {
    (3 * spec.train_inputs * spec.image.width as usize * spec.image.height as usize) as u64
}

/// A wgpu device on the first Vulkan adapter whose storage buffers are limited to `bytes`.
fn device_with_buffer_limit(bytes: u64) -> Device {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::VULKAN,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter = futures_lite::future::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .expect("a Vulkan adapter (install Mesa's software driver, mesa-vulkan-drivers, where there is no GPU)");
    let limits = wgpu::Limits { max_buffer_size: bytes, max_storage_buffer_binding_size: bytes, ..adapter.limits() };
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

/// The child's work: the limit bites, and the step runs under it.
fn run_the_step_under_the_limit() {
    let (full, reduced) = (Scale::Full.spec(), Scale::Reduced.spec());
    let limit = FULL_SIZE_LIMIT * pixel_views(&reduced) / pixel_views(&full);
    let device = device_with_buffer_limit(limit);

    let past_the_limit = Tensor::<1>::zeros([limit as usize / 4 + 1024], &device).try_into_data();
    assert!(past_the_limit.is_err(), "a {limit}-byte limit did not stop a larger buffer");

    let options = ComputeOptions {
        workloads: vec![Workload::TrainStep],
        repeat: 1,
        warmup: 0,
        ..ComputeOptions::new(Scale::Reduced)
    };
    let records = run_compute(&options, &device, |_| {}).expect("the suite runs");
    let step = &records[0];
    assert!(step.error.is_none(), "under a {} KiB buffer limit: {:?}", limit >> 10, step.error);
    assert!(step.median_ms.is_some_and(f64::is_finite), "{step:?}");
    println!("{PASSED} ({} KiB limit, {:.1} s)", limit >> 10, step.median_ms.unwrap_or_default() / 1e3);
}

#[test]
fn the_reduced_training_step_fits_a_buffer_limit_lowered_with_the_workload() {
    if std::env::var_os(CHILD).is_some() {
        run_the_step_under_the_limit();
        let _ = std::io::stdout().flush();
        // SAFETY: `_exit` ends the process at once; everything the test reports is flushed above.
        unsafe { libc::_exit(0) };
    }
    // The test's path inside the test binary (`module_path!` starts with the binary's crate name).
    let module = module_path!().split_once("::").map_or("", |(_, module)| module);
    let name = format!("{module}::the_reduced_training_step_fits_a_buffer_limit_lowered_with_the_workload");
    let child = Command::new(std::env::current_exe().expect("the test binary"))
        .args(["--exact", &name, "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .output()
        .expect("the test binary runs");
    let output = format!("{}\n{}", String::from_utf8_lossy(&child.stdout), String::from_utf8_lossy(&child.stderr));
    assert!(child.status.success() && output.contains(PASSED), "the child failed ({}):\n{output}", child.status);
}
