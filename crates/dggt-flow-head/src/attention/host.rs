//! [`AttentionKernels`] for `flex`: the inputs read into host buffers, [`kernel`] run per query on rayon's pool,
//! the results written back. The saved state is the host inputs (behind an `Arc`); the backward recomputes each
//! query's encodings and weights from them, and sums the shared gradients over one buffer per worker.

use std::sync::Arc;

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Flex, TensorMetadata};
use burn::tensor::{TensorData, try_read_sync};
use rayon::prelude::*;

use super::kernel::{Dims, HostInputs, OwnGrads, Scratch, SharedGrads, backward_query, forward_query};
use super::{AttentionGrads, AttentionInputs, AttentionKernels};

/// Host copies of one call's inputs.
#[derive(Debug)]
pub struct HostCall {
    dims: Dims,
    offsets: Vec<f32>,
    rows: Vec<usize>,
    keys_values: Vec<f32>,
    encoder_weight: Vec<f32>,
    encoder_bias: Vec<f32>,
    queries: Vec<f32>,
    turned: Vec<f32>,
}

impl HostCall {
    fn read<B: Backend>(inputs: AttentionInputs<B>) -> Self {
        let [queries, neighbours, _] = dims3(&inputs.offsets);
        let [_, heads, width] = dims3(&inputs.queries);
        let [_, _, hidden] = dims3(&inputs.turned);
        let targets = inputs.keys_values.shape()[0];
        let dims = Dims { queries, neighbours, heads, width, hidden, targets };
        let rows = read_data(B::int_into_data(inputs.rows), "rows")
            .convert::<i64>()
            .try_into_vec::<i64>()
            .unwrap_or_else(|e| panic!("neighbour attention: `rows` is not an integer tensor: {e:?}"));
        let rows: Vec<usize> = rows.into_iter().map(|r| usize::try_from(r).unwrap_or(usize::MAX)).collect();
        if let Some(bad) = rows.iter().find(|&&r| r >= targets) {
            panic!("neighbour attention: row {bad} of a {targets}-point target");
        }
        Self {
            dims,
            offsets: read::<B>(inputs.offsets, "offsets"),
            rows,
            keys_values: read::<B>(inputs.keys_values, "keys_values"),
            encoder_weight: read::<B>(inputs.encoder_weight, "encoder_weight"),
            encoder_bias: read::<B>(inputs.encoder_bias, "encoder_bias"),
            queries: read::<B>(inputs.queries, "queries"),
            turned: read::<B>(inputs.turned, "turned"),
        }
    }

    fn inputs(&self) -> HostInputs<'_> {
        HostInputs {
            dims: self.dims,
            offsets: &self.offsets,
            rows: &self.rows,
            keys_values: &self.keys_values,
            encoder_weight: &self.encoder_weight,
            encoder_bias: &self.encoder_bias,
            queries: &self.queries,
            turned: &self.turned,
        }
    }

    fn forward(&self) -> Vec<f32> {
        let inputs = self.inputs();
        let dims = self.dims;
        let row = dims.heads * dims.out_channels();
        let mut out = vec![0.0f32; dims.queries * row];
        out.par_chunks_mut(row)
            .enumerate()
            .for_each_init(|| Scratch::new(&dims), |scratch, (query, out)| forward_query(&inputs, query, scratch, out));
        out
    }

    fn backward(&self, grad_out: &[f32]) -> (Vec<f32>, Vec<f32>, Vec<f32>, SharedGrads) {
        let inputs = self.inputs();
        let Dims { queries, neighbours, heads, width, hidden, .. } = self.dims;
        let dims = self.dims;
        let (mut offsets, mut grad_queries, mut turned) = (
            vec![0.0; queries * neighbours * 3],
            vec![0.0; queries * heads * width],
            vec![0.0; queries * heads * hidden],
        );
        // One contiguous block of queries per worker, each with its own shared gradients.
        let block = queries.div_ceil(rayon::current_num_threads().max(1)).max(1);
        let shared = offsets
            .par_chunks_mut(block * neighbours * 3)
            .zip(grad_queries.par_chunks_mut(block * heads * width))
            .zip(turned.par_chunks_mut(block * heads * hidden))
            .enumerate()
            .map(|(index, ((offsets, queries), turned))| {
                let own = OwnGrads { offsets, queries, turned };
                self.backward_block(&inputs, index * block, grad_out, own)
            })
            .reduce(|| SharedGrads::zeros(&dims), SharedGrads::sum);
        (offsets, grad_queries, turned, shared)
    }

    /// The queries from `first` on whose own gradient rows `own` holds (`[count, k, 3]` and so on): those rows
    /// written, and the shared gradients of the block returned.
    fn backward_block(&self, inputs: &HostInputs, first: usize, grad_out: &[f32], own: OwnGrads) -> SharedGrads {
        let dims = self.dims;
        let Dims { neighbours, heads, width, hidden, .. } = dims;
        let (mut scratch, mut shared) = (Scratch::new(&dims), SharedGrads::zeros(&dims));
        let row = heads * dims.out_channels();
        let OwnGrads { offsets: own_offsets, queries: own_queries, turned: own_turned } = own;
        let rows = own_offsets.chunks_exact_mut(neighbours * 3);
        let rows =
            rows.zip(own_queries.chunks_exact_mut(heads * width)).zip(own_turned.chunks_exact_mut(heads * hidden));
        for (local, ((offsets, queries), turned)) in rows.enumerate() {
            let query = first + local;
            let grad = &grad_out[query * row..(query + 1) * row];
            backward_query(inputs, query, grad, &mut scratch, OwnGrads { offsets, queries, turned }, &mut shared);
        }
        shared
    }
}

fn dims3<T: TensorMetadata>(tensor: &T) -> [usize; 3] {
    let shape = tensor.shape();
    [shape[0], shape[1], shape[2]]
}

fn read_data(
    data: impl std::future::Future<Output = Result<TensorData, burn::tensor::ExecutionError>>,
    what: &str,
) -> TensorData {
    try_read_sync(data)
        .unwrap_or_else(|| panic!("neighbour attention: reading `{what}` cannot complete synchronously"))
        .unwrap_or_else(|e| panic!("neighbour attention: reading `{what}` failed: {e:?}"))
}

fn read<B: Backend>(tensor: FloatTensor<B>, what: &str) -> Vec<f32> {
    read_data(B::float_into_data(tensor), what)
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap_or_else(|e| panic!("neighbour attention: `{what}` is not a float tensor: {e:?}"))
}

fn write<B: Backend>(values: Vec<f32>, shape: Vec<usize>, device: &B::Device) -> FloatTensor<B> {
    B::float_from_data(TensorData::new(values, shape), device)
}

impl AttentionKernels for Flex {
    type Saved = Arc<HostCall>;

    fn attention_forward(inputs: AttentionInputs<Self>) -> (FloatTensor<Self>, Self::Saved) {
        let device = inputs.offsets.device();
        let call = HostCall::read::<Self>(inputs);
        let dims = call.dims;
        let out = write::<Self>(call.forward(), vec![dims.queries, dims.heads, dims.out_channels()], &device);
        (out, Arc::new(call))
    }

    fn attention_backward(saved: Self::Saved, grad_out: FloatTensor<Self>) -> AttentionGrads<Self> {
        let device = grad_out.device();
        let dims = saved.dims;
        let (offsets, queries, turned, shared) = saved.backward(&read::<Self>(grad_out, "output gradient"));
        AttentionGrads {
            offsets: write::<Self>(offsets, vec![dims.queries, dims.neighbours, 3], &device),
            keys_values: write::<Self>(shared.keys_values, vec![dims.targets, dims.key_value_channels()], &device),
            encoder_weight: write::<Self>(shared.encoder_weight, vec![3, dims.hidden], &device),
            encoder_bias: write::<Self>(shared.encoder_bias, vec![dims.hidden], &device),
            queries: write::<Self>(queries, vec![dims.queries, dims.heads, dims.width], &device),
            turned: write::<Self>(turned, vec![dims.queries, dims.heads, dims.hidden], &device),
        }
    }
}
