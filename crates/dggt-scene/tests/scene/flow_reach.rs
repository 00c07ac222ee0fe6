//! How far the flow head must look, on the sliding patch of `common`: held still, each patch pixel's true match
//! is the nearest point of the next input; moved by its true 0.7 per step, the match lies exactly where the
//! moved point is, behind nearer points of the same patch.

use burn::tensor::Device;
use dggt_scene::PixelGaussians;

use crate::common::{H, W, in_patch, pixels};

/// The rows of the first view's patch, each with `velocity` (world units per unit of scene time).
fn patch_rows(velocity: [f32; 3]) -> Vec<(usize, [f32; 3])> {
    (0..H * W).filter(|&p| in_patch(0, p % W, p / W)).map(|p| (p, velocity)).collect()
}

#[test]
fn a_still_query_finds_its_match_first_and_a_moving_one_behind_nearer_points() {
    let pixels: PixelGaussians = pixels(&Device::flex());

    let still = pixels.flow_reach(&patch_rows([0.0; 3]), 1).unwrap().expect("the patch has a next input");
    assert_eq!(still.rows, 48, "every pixel of the 8 x 6 patch");
    assert_eq!((still.rank_median, still.rank_p90), (1, 1), "{still:?}");
    assert_eq!(still.within_neighbours, 1.0);
    assert_eq!(still.displacement_median, 0.0);

    // The patch moves 0.7 along x from one input to the next, 0.5 later: 1.4 per unit of scene time.
    let moving = pixels.flow_reach(&patch_rows([1.4, 0.0, 0.0]), 4).unwrap().expect("the patch has a next input");
    assert_eq!(moving.rows, 48);
    assert!((moving.displacement_median - 0.7).abs() < 1e-5, "{moving:?}");
    assert!(moving.miss_median < 1e-5, "the moved patch is among the next input's points: {moving:?}");
    assert!(moving.rank_median > 4, "the match lies behind nearer points of the patch: {moving:?}");
    assert!(moving.within_neighbours < 0.5, "{moving:?}");
    let wide = pixels.flow_reach(&patch_rows([1.4, 0.0, 0.0]), H * W).unwrap().unwrap();
    assert_eq!(wide.within_neighbours, 1.0, "every point is within the whole view");
}
