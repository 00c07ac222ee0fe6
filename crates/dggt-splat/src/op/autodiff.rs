//! [`SplatOps`] under burn's autodiff: one graph node per call, whose backward step is the backend's
//! [`SplatKernels::splat_backward`].
//!
//! The node's parents are the six differentiable inputs (means, quaternions, scales, opacities, colours,
//! background); the cameras enter as constants. Only a tracked call (some parent requires a gradient) keeps the
//! backend's saved state, as the node's state; it lives until the backward pass consumes the node or the graph
//! is dropped. The call is compute bound: checkpointing never recomputes it.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Autodiff, Backend};
use dggt_geom::ImageSize;

use super::{SplatInputs, SplatKernels, SplatOps};
use crate::settings::RasterSettings;

/// The backward step; its state is the backend's [`SplatKernels::Saved`].
#[derive(Debug)]
struct SplatBackward;

impl<B: Backend + SplatKernels> Backward<B, 6> for SplatBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 6>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let grad_images = grads.consume::<B>(&ops.node);
        let g = B::splat_backward(ops.state, grad_images);
        let [means, quats, scales, opacities, colors, background] = ops.parents;
        let pairs = [
            (means, g.means),
            (quats, g.quats),
            (scales, g.scales),
            (opacities, g.opacities),
            (colors, g.colors),
            (background, g.background),
        ];
        for (parent, grad) in pairs {
            if let Some(node) = parent {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: Backend + SplatKernels, C: CheckpointStrategy> SplatOps for Autodiff<B, C> {
    fn splat_render(
        inputs: SplatInputs<Self>,
        settings: RasterSettings,
        size: ImageSize,
    ) -> (FloatTensor<Self>, IntTensor<Self>) {
        let SplatInputs { means, quats, scales, opacities, colors, background, viewmats, intrinsics } = inputs;
        let guards = [means.node(), quats.node(), scales.node(), opacities.node(), colors.node(), background.node()];
        let inputs = SplatInputs::<B> {
            means: means.into_primitive(),
            quats: quats.into_primitive(),
            scales: scales.into_primitive(),
            opacities: opacities.into_primitive(),
            colors: colors.into_primitive(),
            background: background.into_primitive(),
            viewmats: viewmats.into_primitive(),
            intrinsics: intrinsics.into_primitive(),
        };
        match <SplatBackward as Backward<B, 6>>::prepare::<C>(SplatBackward, guards).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (outputs, saved) = B::splat_forward_saved(inputs, &settings, size);
                (prep.finish(saved, outputs.images), outputs.stats)
            }
            OpsKind::UnTracked(prep) => {
                let outputs = B::splat_forward(inputs, &settings, size);
                (prep.finish(outputs.images), outputs.stats)
            }
        }
    }
}
