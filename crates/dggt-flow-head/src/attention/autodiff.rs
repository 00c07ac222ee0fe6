//! [`NeighbourAttentionOps`] under burn's autodiff: one graph node per call, whose backward step is the backend's
//! [`AttentionKernels::attention_backward`]. The parents are the six float inputs; the rows are data. Only a
//! tracked call keeps the saved state. The call is compute bound: checkpointing never recomputes it.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend};

use super::{AttentionInputs, AttentionKernels, NeighbourAttentionOps};

#[derive(Debug)]
struct AttentionBackward;

impl<B: Backend + AttentionKernels> Backward<B, 6> for AttentionBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 6>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let grad_out = grads.consume::<B>(&ops.node);
        let g = B::attention_backward(ops.state, grad_out);
        let [offsets, keys_values, encoder_weight, encoder_bias, queries, turned] = ops.parents;
        let pairs = [
            (offsets, g.offsets),
            (keys_values, g.keys_values),
            (encoder_weight, g.encoder_weight),
            (encoder_bias, g.encoder_bias),
            (queries, g.queries),
            (turned, g.turned),
        ];
        for (parent, grad) in pairs {
            if let Some(node) = parent {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: Backend + AttentionKernels, C: CheckpointStrategy> NeighbourAttentionOps for Autodiff<B, C> {
    fn neighbour_attention(inputs: AttentionInputs<Self>) -> FloatTensor<Self> {
        let AttentionInputs { offsets, rows, keys_values, encoder_weight, encoder_bias, queries, turned } = inputs;
        let guards = [
            offsets.node(),
            keys_values.node(),
            encoder_weight.node(),
            encoder_bias.node(),
            queries.node(),
            turned.node(),
        ];
        let inputs = AttentionInputs::<B> {
            offsets: offsets.into_primitive(),
            rows,
            keys_values: keys_values.into_primitive(),
            encoder_weight: encoder_weight.into_primitive(),
            encoder_bias: encoder_bias.into_primitive(),
            queries: queries.into_primitive(),
            turned: turned.into_primitive(),
        };
        match <AttentionBackward as Backward<B, 6>>::prepare::<C>(AttentionBackward, guards).compute_bound().stateful()
        {
            OpsKind::Tracked(prep) => {
                let (out, saved) = B::attention_forward(inputs);
                prep.finish(saved, out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::attention_forward(inputs).0),
        }
    }
}
