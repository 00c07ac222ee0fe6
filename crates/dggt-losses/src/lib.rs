//! Training losses of dggt (the metrics that score renders are `dggt-metrics`).
//!
//! Conventions at the API: an image batch is a `Tensor<4>` `[V, H, W, 3]`, channel-last linear RGB in
//! [0, 1] (the rasteriser's output); masks are `[V, H, W]`. The convolutional losses convert to NCHW
//! internally ([`images`]). Every loss is a burn tensor expression, differentiable on an autodiff device
//! (`Device::flex().autodiff()`, or a GPU device's); the perceptual networks' weights are plain tensors and
//! never receive gradients.
//!
//! * [`photometric`]: L2 and L1.
//! * [`mask`]: BCE on probabilities (the opacity loss, alpha vs 1 - sky) and from logits (dynamic mask).
//! * [`lifespan`]: the `mean(1 / sigma)` lifespan regulariser.
//! * [`backbone`]: frozen AlexNet and VGG-16 feature stacks and their weight loading.
//! * [`lpips`]: LPIPS v0.1 (AlexNet or VGG), evaluation and training-style inputs.
//! * [`gram`]: the VGG-16 Gram (style) loss.
//! * [`weights`]: named tensors from `.safetensors` / `.pth` files.

pub mod backbone;
pub mod error;
pub mod gram;
pub mod images;
pub mod lifespan;
pub mod lpips;
pub mod mask;
pub mod photometric;
pub mod weights;

pub use backbone::{AlexNet, Vgg16};
pub use error::LossError;
pub use gram::{GramLoss, GramOutput};
pub use lifespan::lifespan_l1;
pub use lpips::{Lpips, LpipsInput, LpipsKind, LpipsNet, LpipsOutput};
pub use mask::{bce_probabilities, bce_with_logits, opacity_loss};
pub use photometric::{l1, l2};
pub use weights::WeightFile;
