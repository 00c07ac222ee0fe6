//! Optional capture of named intermediate tensors, under the names the parity vectors use
//! (`enc.down_in.0`, `unet.mid`, `dec.skip.1`, ...). Off, recording costs nothing; on, each tensor is read
//! back to the host, into memory of its own, when recorded.

use burn::tensor::{Tensor, TensorData};

/// Whether a forward pass keeps its intermediates.
#[derive(Debug, Default)]
pub enum Trace {
    #[default]
    Off,
    On(Vec<(String, TensorData)>),
}

impl Trace {
    pub fn on() -> Self {
        Self::On(Vec::new())
    }

    pub fn record<const D: usize>(&mut self, name: impl Into<String>, tensor: &Tensor<D>) {
        if let Self::On(records) = self {
            let data = tensor.clone().into_data();
            // An owned copy: on the wgpu backend the read-back bytes can alias a staging buffer that a later
            // read of the same size overwrites.
            let owned = TensorData::from_bytes_vec(data.as_bytes().to_vec(), data.shape().clone(), data.dtype());
            records.push((name.into(), owned));
        }
    }

    /// The recorded tensors in order (empty when off).
    pub fn into_records(self) -> Vec<(String, TensorData)> {
        match self {
            Self::Off => Vec::new(),
            Self::On(records) => records,
        }
    }
}
