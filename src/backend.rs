//! Compute devices: which burn backends this build has, and the `--device` choice that selects one.
//!
//! Backends are cargo features of the `dggt` package (`flex` by default, `ndarray`, `wgpu`, `cuda`), so a
//! CPU-only build never compiles GPU crates. Asking for a backend the build lacks is an error that says which
//! feature to enable.

use anyhow::{Result, bail};
use burn::tensor::{Device, Tensor};

/// A backend the user can ask for with `--device`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceChoice {
    /// Pure-Rust CPU backend (`flex`, the default).
    Cpu,
    /// The ndarray CPU backend.
    Ndarray,
    /// GPU through wgpu (Vulkan, Metal, DX12), CubeCL kernels.
    Wgpu,
    /// NVIDIA GPU through CUDA, the same CubeCL kernels.
    Cuda,
}

impl DeviceChoice {
    pub const ALL: [DeviceChoice; 4] = [Self::Cpu, Self::Ndarray, Self::Wgpu, Self::Cuda];

    /// The cargo feature that compiles this backend in.
    pub fn feature(self) -> &'static str {
        match self {
            Self::Cpu => "flex",
            Self::Ndarray => "ndarray",
            Self::Wgpu => "wgpu",
            Self::Cuda => "cuda",
        }
    }

    /// Whether this build includes the backend.
    pub fn compiled(self) -> bool {
        match self {
            Self::Cpu => cfg!(feature = "flex"),
            Self::Ndarray => cfg!(feature = "ndarray"),
            Self::Wgpu => cfg!(feature = "wgpu-backend"),
            Self::Cuda => cfg!(feature = "cuda-backend"),
        }
    }

    /// The burn device, or an error naming the missing feature.
    pub fn device(self) -> Result<Device> {
        self.device_at(0)
    }

    /// Device number `index` of this backend (GPUs; the CPU backends have one device).
    #[cfg_attr(not(any(feature = "wgpu-backend", feature = "cuda-backend")), allow(unused_variables))]
    pub fn device_at(self, index: usize) -> Result<Device> {
        match self {
            #[cfg(feature = "flex")]
            Self::Cpu => Ok(Device::flex()),
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)]
            Self::Ndarray => Ok(Device::ndarray()),
            #[cfg(feature = "wgpu-backend")]
            Self::Wgpu if index == 0 => Ok(Device::wgpu(burn::tensor::DeviceKind::default())),
            #[cfg(feature = "wgpu-backend")]
            Self::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DiscreteGpu(index))),
            #[cfg(feature = "cuda-backend")]
            Self::Cuda => Ok(Device::cuda(index)),
            #[allow(unreachable_patterns)]
            other => bail!(
                "this build of dggt has no {other:?} backend; rebuild with `cargo build --release --features {}`",
                other.feature()
            ),
        }
    }
}

/// One device: a backend and, for GPUs, which one (`cpu`, `wgpu:1`, `cuda:0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceSpec {
    pub choice: DeviceChoice,
    pub index: usize,
}

impl std::str::FromStr for DeviceSpec {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> Result<Self> {
        let text = text.trim();
        let (name, index) = match text.split_once(':') {
            Some((name, index)) => {
                let index = index.parse().map_err(|_| anyhow::anyhow!("bad device index in `{text}`"))?;
                (name, index)
            }
            None => (text, 0),
        };
        let choice = <DeviceChoice as clap::ValueEnum>::from_str(name, true)
            .map_err(|_| anyhow::anyhow!("unknown device `{text}` (cpu, ndarray, wgpu[:N], cuda[:N])"))?;
        if index > 0 && matches!(choice, DeviceChoice::Cpu | DeviceChoice::Ndarray) {
            bail!("the {choice:?} backend has one device; `{text}` does not exist");
        }
        Ok(Self { choice, index })
    }
}

impl DeviceSpec {
    /// The burn device, or an error naming the feature this build lacks.
    pub fn device(self) -> Result<Device> {
        self.choice.device_at(self.index)
    }
}

/// The devices a command runs on, as `--device` names them (`cpu`, `wgpu`, `cuda:0,cuda:1`): parsed once, when
/// the command line is read, by every subcommand.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceList(Vec<DeviceSpec>);

impl std::str::FromStr for DeviceList {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> Result<Self> {
        Self::from_names(text.split(','))
    }
}

impl DeviceList {
    /// Parses each of `names` (for example a configuration's `run.devices`).
    pub fn from_names<S: AsRef<str>>(names: impl IntoIterator<Item = S>) -> Result<Self> {
        let specs = names.into_iter().map(|name| name.as_ref().parse()).collect::<Result<Vec<DeviceSpec>>>()?;
        anyhow::ensure!(!specs.is_empty(), "no device given");
        Ok(Self(specs))
    }

    /// Every device, in order.
    pub fn devices(&self) -> Result<Vec<Device>> {
        self.0.iter().map(|spec| spec.device()).collect()
    }

    /// The one device of a command that runs on one.
    pub fn single(&self) -> Result<Device> {
        match self.0.as_slice() {
            [one] => one.device(),
            _ => bail!("this command runs on one device; {} were given", self.0.len()),
        }
    }
}

/// Runs a small matrix product on `device` and returns the largest difference from the same product on the
/// host, proving that the backend computes.
pub fn self_check(device: &Device) -> Result<f32> {
    let (m, k, n) = (17, 33, 9);
    let a: Vec<f32> = (0..m * k).map(|i| ((i * 7 % 13) as f32 - 6.0) / 7.0).collect();
    let b: Vec<f32> = (0..k * n).map(|i| ((i * 5 % 11) as f32 - 5.0) / 5.0).collect();
    let expected: Vec<f32> =
        (0..m * n).map(|idx| (0..k).map(|p| a[idx / n * k + p] * b[p * n + idx % n]).sum()).collect();
    let ta = Tensor::<2>::from_data(burn::tensor::TensorData::new(a, [m, k]), device);
    let tb = Tensor::<2>::from_data(burn::tensor::TensorData::new(b, [k, n]), device);
    let product: Vec<f32> = ta
        .matmul(tb)
        .into_data()
        .try_to_vec::<f32>()
        .map_err(|e| anyhow::anyhow!("reading back the product: {e:?}"))?;
    Ok(product.iter().zip(&expected).fold(0.0f32, |m, (x, y)| m.max((x - y).abs())))
}
