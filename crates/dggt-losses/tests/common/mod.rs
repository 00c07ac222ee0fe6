//! Shared test utilities: the parity folder, safetensors reading and writing, host/tensor conversion and a
//! deterministic generator for synthetic weights and images.

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dggt_model::safetensors_file::SafetensorsFile;
use safetensors::Dtype;

/// `$DGGT_PARITY_DIR/metrics`, or `shared/parity/metrics` next to the repository. Panics (failing the
/// test) when the folder is missing.
pub fn metrics_dir() -> PathBuf {
    let dir = dggt_test_data::parity("metrics");
    assert!(
        dir.join("outputs.safetensors").is_file(),
        "metrics parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

/// A host tensor: shape and f32 values.
#[derive(Debug, Clone)]
pub struct Host {
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

impl Host {
    pub fn new(shape: Vec<usize>, values: Vec<f32>) -> Self {
        assert_eq!(shape.iter().product::<usize>(), values.len(), "one value per element of shape {shape:?}");
        Self { shape, values }
    }

    pub fn tensor<const D: usize>(&self, device: &Device) -> Tensor<D> {
        let shape: [usize; D] = self.shape.clone().try_into().expect("rank");
        Tensor::from_data(TensorData::new(self.values.clone(), shape), device)
    }

    /// Entries `[index, ..]` of the leading axis.
    pub fn index(&self, index: usize) -> Host {
        let n: usize = self.shape[1..].iter().product();
        Host::new(self.shape[1..].to_vec(), self.values[index * n..(index + 1) * n].to_vec())
    }
}

/// Every tensor of a safetensors file as f32 (the workspace's reader, which widens f64 and the half types).
pub fn read_safetensors(path: &Path) -> HashMap<String, Host> {
    let mut file = SafetensorsFile::open(path).unwrap_or_else(|e| panic!("{e}"));
    file.names_in_file_order()
        .into_iter()
        .map(|name| {
            let tensor = file.read_f32(&name).unwrap_or_else(|e| panic!("{e}"));
            (name, Host::new(tensor.shape, tensor.values))
        })
        .collect()
}

/// Writes f32 tensors to a safetensors file.
pub fn write_safetensors(path: &Path, tensors: &[(String, Host)]) {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(name, t)| (name.clone(), t.shape.clone(), t.values.iter().flat_map(|v| v.to_le_bytes()).collect()))
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = bytes
        .iter()
        .map(|(name, shape, data)| {
            (name.clone(), safetensors::tensor::TensorView::new(Dtype::F32, shape.clone(), data).unwrap())
        })
        .collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

pub fn values<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.into_data().convert::<f32>().try_into_vec::<f32>().unwrap()
}

pub fn tensor<const D: usize>(values: &[f32], shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), device)
}

/// NCHW host images `[N, C, H, W]` -> NHWC.
pub fn nchw_to_nhwc(host: &Host) -> Host {
    let [n, c, h, w] = host.shape[..] else { panic!("rank 4 expected") };
    let mut out = vec![0.0; host.values.len()];
    for i in 0..n {
        for ch in 0..c {
            for y in 0..h {
                for x in 0..w {
                    out[((i * h + y) * w + x) * c + ch] = host.values[((i * c + ch) * h + y) * w + x];
                }
            }
        }
    }
    Host::new(vec![n, h, w, c], out)
}

/// The seeded generator of the test inputs.
pub use dggt_data::random::SplitMix64 as Rng;

/// Relative error `|a - b| / max(|b|, floor)`.
pub fn rel_err(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / b.abs().max(floor)
}

/// Largest `|a - b|` over two equally long slices, divided by the largest `|b|`.
pub fn max_err_rel_to_max(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "values compared pairwise have equal lengths");
    let max_ref = b.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64));
    let max_diff = a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs() as f64));
    max_diff / max_ref.max(f64::MIN_POSITIVE)
}

/// He-normal conv weights and small biases for `specs`, under torchvision names, plus (if `lin_channels`) the
/// lpips linear weights `linK.model.1.weight` (non-negative).
pub fn synthetic_weights(
    specs: &[dggt_losses::backbone::ConvSpec],
    lin_channels: Option<&[usize]>,
    seed: u64,
) -> Vec<(String, Host)> {
    let mut rng = Rng::new(seed);
    let mut tensors = Vec::new();
    for spec in specs {
        let fan_in = spec.in_channels * spec.kernel * spec.kernel;
        let shape = vec![spec.out_channels, spec.in_channels, spec.kernel, spec.kernel];
        let weight = rng.normals(shape.iter().product(), (2.0 / fan_in as f32).sqrt());
        tensors.push((format!("features.{}.weight", spec.index), Host::new(shape, weight)));
        let bias = rng.normals(spec.out_channels, 0.05);
        tensors.push((format!("features.{}.bias", spec.index), Host::new(vec![spec.out_channels], bias)));
    }
    for (k, &c) in lin_channels.unwrap_or(&[]).iter().enumerate() {
        let weight: Vec<f32> = (0..c).map(|_| rng.unit() * 2.0 / c as f32).collect();
        tensors.push((format!("lin{k}.model.1.weight"), Host::new(vec![1, c, 1, 1], weight)));
    }
    tensors
}

/// Writes f32 tensors as a `torch.save`d state dict (the ZIP layout PyTorch writes: `archive/data.pkl`, a
/// protocol-2 pickle of an `OrderedDict` of `torch._utils._rebuild_tensor_v2` calls whose storages are
/// persistent ids, `archive/data/<key>` with the raw little-endian values, `archive/byteorder`,
/// `archive/version`), uncompressed.
pub fn write_pth(path: &Path, tensors: &[(String, Host)]) {
    fn unicode(out: &mut Vec<u8>, s: &str) {
        out.push(b'X');
        out.extend((s.len() as u32).to_le_bytes());
        out.extend(s.as_bytes());
    }
    fn global(out: &mut Vec<u8>, module: &str, name: &str) {
        out.push(b'c');
        out.extend(format!("{module}\n{name}\n").as_bytes());
    }
    fn int(out: &mut Vec<u8>, v: usize) {
        out.push(b'J');
        out.extend((v as i32).to_le_bytes());
    }
    fn int_tuple(out: &mut Vec<u8>, values: &[usize]) {
        out.push(b'(');
        values.iter().for_each(|&v| int(out, v));
        out.push(b't');
    }
    fn ordered_dict(out: &mut Vec<u8>) {
        global(out, "collections", "OrderedDict");
        out.extend(b")R");
    }
    let mut pickle = vec![0x80, 2];
    ordered_dict(&mut pickle);
    pickle.push(b'(');
    let mut entries: Vec<(String, Vec<u8>)> = vec![];
    for (key, (name, t)) in tensors.iter().enumerate() {
        unicode(&mut pickle, name);
        global(&mut pickle, "torch._utils", "_rebuild_tensor_v2");
        pickle.push(b'(');
        pickle.push(b'(');
        unicode(&mut pickle, "storage");
        global(&mut pickle, "torch", "FloatStorage");
        unicode(&mut pickle, &key.to_string());
        unicode(&mut pickle, "cpu");
        int(&mut pickle, t.values.len());
        pickle.extend(b"tQ");
        int(&mut pickle, 0);
        int_tuple(&mut pickle, &t.shape);
        let strides: Vec<usize> = (0..t.shape.len()).map(|i| t.shape[i + 1..].iter().product()).collect();
        int_tuple(&mut pickle, &strides);
        pickle.push(0x89);
        ordered_dict(&mut pickle);
        pickle.extend(b"tR");
        entries.push((format!("archive/data/{key}"), t.values.iter().flat_map(|v| v.to_le_bytes()).collect()));
    }
    pickle.extend(b"u.");
    entries.insert(0, ("archive/data.pkl".into(), pickle));
    entries.push(("archive/byteorder".into(), b"little".to_vec()));
    entries.push(("archive/version".into(), b"3\n".to_vec()));
    std::fs::write(path, stored_zip(&entries)).unwrap();
}

fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in data {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// A ZIP archive of uncompressed entries.
fn stored_zip(entries: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let offset = out.len() as u32;
        let (crc, size) = (crc32(data), data.len() as u32);
        let common = |h: &mut Vec<u8>| {
            h.extend(20u16.to_le_bytes()); // version needed
            h.extend(0u16.to_le_bytes()); // flags
            h.extend(0u16.to_le_bytes()); // stored
            h.extend(0u16.to_le_bytes()); // time
            h.extend(0x21u16.to_le_bytes()); // date 1980-01-01
            h.extend(crc.to_le_bytes());
            h.extend(size.to_le_bytes());
            h.extend(size.to_le_bytes());
            h.extend((name.len() as u16).to_le_bytes());
            h.extend(0u16.to_le_bytes()); // extra length
        };
        out.extend(0x0403_4b50u32.to_le_bytes());
        common(&mut out);
        out.extend(name.as_bytes());
        out.extend(data);
        central.extend(0x0201_4b50u32.to_le_bytes());
        central.extend(20u16.to_le_bytes()); // version made by
        common(&mut central);
        central.extend([0u8; 6]); // comment length, disk, internal attributes
        central.extend(0u32.to_le_bytes()); // external attributes
        central.extend(offset.to_le_bytes());
        central.extend(name.as_bytes());
    }
    let (central_offset, central_size) = (out.len() as u32, central.len() as u32);
    out.extend(central);
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0u8; 4]);
    out.extend((entries.len() as u16).to_le_bytes());
    out.extend((entries.len() as u16).to_le_bytes());
    out.extend(central_size.to_le_bytes());
    out.extend(central_offset.to_le_bytes());
    out.extend(0u16.to_le_bytes());
    out
}
