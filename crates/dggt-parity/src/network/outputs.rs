//! The table of reference outputs: each name pattern of the network's vectors and how the port reproduces it
//! from one forward pass ([`Prediction`]): from the forward pass itself, the cameras decoded from it, the
//! Gaussian means unprojected from its depth, the sky model coloured with those cameras, the lifespan decay, or
//! the scene rendered from all of these. A name the table does not know is reported as not compared.

use burn::tensor::Tensor;
use burn::tensor::activation::sigmoid;
use dggt_model::lifespan::{dynamic_opacity, frame_times, opacity_at, static_opacity};
use dggt_model::sky::grid_coordinates;

use crate::network::comparison::{Actual, dense, host, image};
use crate::network::prediction::Prediction;
use crate::network::reproduce_error::ReproduceError;
use crate::vectors::HostTensor;

/// How the port's value of one reference output is made.
pub(super) type Reproduce = fn(&Prediction, &Key) -> Result<Actual, ReproduceError>;

/// What a name matched in its pattern: the `{i}` index and the `{head}` name.
pub(super) struct Key {
    pub index: usize,
    pub head: &'static str,
}

/// The DPT heads a `{head}` pattern segment matches.
const DPT_HEADS: [&str; 5] = ["depth_head", "point_head", "gs_head", "instance_head", "semantic_head"];

/// Reference output name patterns and how each is reproduced. In a pattern, `{i}` matches an index, `{head}`
/// one of the DPT heads, and a final `{rest}` any further segments.
const OUTPUTS: &[(&str, Reproduce)] = &[
    // DINO patch embedding.
    ("dino.pos_embed_interp", |p, _| {
        let [_, _, _, height, width] = p.images.dims();
        Ok(dense(p.model.aggregator.patch_embed.interpolated_pos_embed(height, width)))
    }),
    ("dino.prepared_tokens", |p, _| Ok(dense(p.out.aggregator.dino.prepared_tokens.clone()))),
    ("image_feature", |p, _| {
        let last = last(&p.out.aggregator.dino.layers, "DINO layers")?;
        let [batch, frames, ..] = p.images.dims();
        let [rows, cols] = p.out.aggregator.grid;
        let channels = last.dims()[2];
        Ok(dense(last.reshape([batch, frames, rows, cols, channels])))
    }),
    // Aggregator.
    ("agg.output_list.{i}", |p, k| Ok(dense(layer(&p.out.aggregator.output_list, k.index)?))),
    ("agg.output_list_with_tokens.{i}", |p, k| {
        layer(&p.out.aggregator.output_list, k.index)?;
        Ok(dense(p.out.aggregator.output_with_dino_tokens(k.index)))
    }),
    ("agg.dino_token_list.{i}", |p, k| Ok(dense(layer(&p.out.aggregator.dino_token_list, k.index)?))),
    ("agg.patch_start_idx", |p, _| Ok(host(HostTensor::new(vec![1], vec![p.out.aggregator.patch_start_idx as f32])))),
    // Camera head.
    ("camera.token_norm_out", |p, _| {
        let last = last(&p.out.aggregator.output_list, "aggregator layers")?;
        Ok(dense(p.model.camera_head.token_norm_out(last)))
    }),
    ("camera.pose_deltas", |p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.deltas.clone(), 0)))),
    ("camera.pose_preact", |p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.preactivations.clone(), 0)))),
    ("camera.pose_enc_list", |p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.encodings.clone(), 0)))),
    ("camera.pose_enc_iter.{i}", |p, k| Ok(dense(layer(&p.out.camera.encodings, k.index)?))),
    ("pose_enc", |p, _| Ok(dense(p.out.camera.pose_encoding()))),
    // DPT internals and raw outputs.
    ("dbg.{head}.resize.{i}", |p, k| Ok(dense(layer(&p.dpt(k.head)?.resized, k.index)?))),
    ("dbg.{head}.output_conv1", |p, k| Ok(dense(p.dpt(k.head)?.fused.clone()))),
    ("dbg.{head}.head_in", |p, k| Ok(dense(p.dpt(k.head)?.head_in.clone()))),
    ("{head}.raw", |p, k| Ok(dense(p.dpt(k.head)?.raw.clone()))),
    // Depth and point heads.
    ("depth", |p, _| Ok(dense(p.out.depth.prediction.clone()))),
    ("depth_conf", |p, _| Ok(dense(p.out.depth.confidence.clone()))),
    ("world_points", |p, _| Ok(dense(p.points()?.prediction.clone()))),
    ("world_points_conf", |p, _| Ok(dense(p.points()?.confidence.clone()))),
    // Gaussian head.
    ("gs_map", |p, _| Ok(dense(p.gaussians()?.maps.gs_map()))),
    ("gs_conf", |p, _| {
        let mut actual = dense(p.gaussians()?.maps.lifespan.clone());
        actual.map = Some(f32::recip);
        actual.note = Some("compared as 1/gs_conf");
        Ok(actual)
    }),
    ("gs.rgb", |p, _| Ok(dense(p.gaussians()?.maps.rgb.clone()))),
    ("gs.opacity", |p, _| Ok(dense(p.gaussians()?.maps.opacity.clone()))),
    ("gs.scale", |p, _| Ok(dense(p.gaussians()?.maps.scale.clone()))),
    ("gs.rotation", |p, _| Ok(dense(p.gaussians()?.maps.rotation.clone()))),
    ("gs.lifespan_raw", |p, _| Ok(dense(p.gaussians()?.maps.lifespan_raw.clone()))),
    // Instance (dynamic) and semantic heads.
    ("dynamic_conf", |p, _| Ok(dense(p.instance()?.prediction.clone()))),
    ("instance.logit", |p, _| Ok(dense(p.dynamic_logit()?))),
    ("instance.prob", |p, _| Ok(dense(sigmoid(p.dynamic_logit()?)))),
    ("instance.conf_unused", |p, _| Ok(dense(p.instance()?.confidence.clone()))),
    ("semantic_logits", |p, _| Ok(dense(p.semantic()?.prediction.clone()))),
    // Cameras decoded from the pose encoding, and the Gaussian means.
    ("extrinsics", |p, _| {
        let values = p.cameras()?.iter().flat_map(|(c, _)| c.to_rows_3x4_f32()).flatten().collect();
        Ok(host(HostTensor::new(p.per_frame(&[3, 4]), values)))
    }),
    ("intrinsics", |p, _| {
        let values = p.cameras()?.iter().flat_map(|(_, k)| k.to_rows_f32()).flatten().collect();
        Ok(host(HostTensor::new(p.per_frame(&[3, 3]), values)))
    }),
    ("extrinsic_4x4", |p, _| {
        let [_, frames, ..] = p.images.dims();
        let first: Vec<f32> =
            p.cameras()?[..frames].iter().flat_map(|(c, _)| c.to_rows()).flatten().map(|v| v as f32).collect();
        Ok(host(HostTensor::new(vec![frames, 4, 4], first)))
    }),
    ("means.cam", |p, _| p.means(false)),
    ("means.world", |p, _| p.means(true)),
    // Sky model.
    ("sky.pixel_locations", |p, _| {
        let (projection, _) = p.sky()?;
        let values = projection.pixels.iter().flatten().map(|&v| v as f32).collect();
        let mask = projection.seen.iter().flat_map(|&seen| [seen; 2]).collect();
        Ok(p.sky_pixels(values, mask))
    }),
    ("sky.normalized_pixel_locations", |p, _| {
        let (projection, _) = p.sky()?;
        let values =
            projection.pixels.iter().flat_map(|&pixel| grid_coordinates(pixel, p.size)).map(|v| v as f32).collect();
        let mask = projection.seen.iter().flat_map(|&seen| [seen; 2]).collect();
        Ok(p.sky_pixels(values, mask))
    }),
    ("sky.in_front", |p, _| {
        let (projection, _) = p.sky()?;
        let values = projection.depth.iter().map(|&z| f32::from(u8::from(z > 0.0))).collect();
        Ok(host(HostTensor::new(vec![projection.depth.len() / projection.points, projection.points], values)))
    }),
    ("sky.proj_depth", |p, _| {
        let (projection, _) = p.sky()?;
        let values = projection.depth.iter().map(|&z| z as f32).collect();
        Ok(host(HostTensor::new(vec![projection.depth.len() / projection.points, projection.points], values)))
    }),
    ("sky.view_mask", |p, _| {
        let (projection, _) = p.sky()?;
        let (n, views) = (projection.points, projection.seen.len() / projection.points);
        let values = (0..n * views).map(|i| f32::from(u8::from(projection.seen[(i % views) * n + i / views])));
        Ok(host(HostTensor::new(vec![n, views], values.collect())))
    }),
    ("sky.proj_mask", |p, _| {
        let (projection, gaussians) = p.sky()?;
        let mut values = vec![0.0; projection.points];
        gaussians.visible_index.iter().for_each(|&i| values[i] = 1.0);
        Ok(host(HostTensor::new(vec![projection.points], values)))
    }),
    ("sky.visible_index", |p, _| {
        let index = &p.sky()?.1.visible_index;
        Ok(host(HostTensor::new(vec![index.len()], index.iter().map(|&i| i as f32).collect())))
    }),
    ("sky.rgb_mean", |p, _| Ok(dense(p.sky()?.1.rgb_mean.clone()))),
    ("sky.bg_field_out", |p, _| Ok(dense(p.sky()?.1.field_out.clone()))),
    ("sky.colors", |p, _| Ok(dense(p.sky()?.1.colors.clone()))),
    ("sky.means", |p, _| Ok(dense(p.sky()?.1.means.clone()))),
    ("sky.scales", |p, _| Ok(dense(p.sky()?.1.scales.clone()))),
    ("sky.quats", |p, _| Ok(dense(p.sky()?.1.quats.clone()))),
    ("sky.opacities", |p, _| Ok(dense(p.sky()?.1.opacities.clone()))),
    // Frame times, the static/dynamic opacity split and the lifespan decay.
    ("timestamps", |p, _| {
        let times: Vec<f32> = frame_times(p.images.dims()[1]).iter().map(|&t| t as f32).collect();
        Ok(host(HostTensor::new(vec![times.len()], times)))
    }),
    ("lifespan.static_opacity", |p, _| Ok(dense(p.frames(p.split_opacity(static_opacity)?)))),
    ("lifespan.dynamic_opacity", |p, _| Ok(dense(p.frames(p.split_opacity(dynamic_opacity)?)))),
    ("lifespan.static_opacity_at_t", |p, _| Ok(dense(p.static_opacity_at_t()?))),
    ("lifespan.frame0_at_t2", |p, _| {
        let at_t = p.static_opacity_at_t()?;
        let [_, _, height, width] = at_t.dims();
        Ok(dense(at_t.narrow(0, 2, 1).narrow(1, 0, 1).reshape([height, width])))
    }),
    ("lifespan.frame0_raw_opacity_at_t2", |p, _| {
        let maps = &p.gaussians()?.maps;
        let [_, frames, height, width] = maps.opacity.dims();
        let time = *frame_times(frames).get(2).ok_or_else(|| ReproduceError::Input {
            input: "images",
            problem: format!("{frames} frames, not at least 3"),
        })?;
        let first = |t: &Tensor<4>| t.clone().narrow(1, 0, 1).reshape([height, width]);
        let zero = Tensor::zeros([height, width], &maps.opacity.device());
        Ok(dense(opacity_at(first(&maps.opacity), first(&maps.lifespan), zero, time)))
    }),
    // The inference render.
    ("render.bg_mask", |p, _| {
        let values = p.non_sky()?.iter().map(|&b| f32::from(u8::from(b))).collect();
        Ok(host(HostTensor::new(p.per_frame(&[p.size.height as usize, p.size.width as usize]), values)))
    }),
    ("render.static_mask", |p, _| {
        let values = p.scene()?.static_mask.iter().map(|&b| f32::from(u8::from(b))).collect();
        Ok(host(HostTensor::new(p.per_frame(&[p.size.height as usize, p.size.width as usize]), values)))
    }),
    ("render.static_opacity", |p, _| Ok(dense(p.scene()?.static_opacity.clone()))),
    ("render.static_opacity_at_frame.{i}", |p, k| Ok(dense(layer(&p.scene()?.static_opacity_at_frame, k.index)?))),
    ("render.fg_rgb", |p, _| Ok(image(p.scene()?.foreground.colors.clone(), 3))),
    ("render.fg_alpha", |p, _| Ok(image(p.scene()?.foreground.alpha.clone().unsqueeze_dim::<4>(3), 1))),
    ("render.fg_expected_depth", |p, _| Ok(image(p.scene()?.foreground.depth.clone(), 1))),
    ("render.sky_raw", |p, _| Ok(image(p.scene()?.sky.clone(), 3))),
    ("render.sky_minmax", |p, _| Ok(image(p.scene()?.sky_minmax.clone(), 3))),
    ("render.final_rgb", |p, _| Ok(image(p.scene()?.final_rgb.clone(), 3))),
];

/// How to reproduce the reference output `name`, and what its pattern matched.
pub(super) fn lookup(name: &str) -> Option<(Reproduce, Key)> {
    OUTPUTS.iter().find_map(|(pattern, reproduce)| {
        let mut key = Key { index: 0, head: "" };
        let mut segments = name.split('.');
        for expected in pattern.split('.') {
            if expected == "{rest}" {
                return segments.next().map(|_| (*reproduce, key));
            }
            let segment = segments.next()?;
            match expected {
                "{i}" => key.index = segment.parse().ok()?,
                "{head}" => key.head = DPT_HEADS.iter().find(|head| **head == segment)?,
                literal if literal != segment => return None,
                _ => {}
            }
        }
        segments.next().is_none().then_some((*reproduce, key))
    })
}

fn layer<T: Clone>(list: &[T], index: usize) -> Result<T, ReproduceError> {
    list.get(index).cloned().ok_or(ReproduceError::NoEntry { what: "entries", available: list.len(), index })
}

/// The last of `list`, a list of `what`.
fn last<T: Clone>(list: &[T], what: &'static str) -> Result<T, ReproduceError> {
    list.last().cloned().ok_or(ReproduceError::NoEntry { what, available: 0, index: 0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_through_the_table() {
        fn matches(name: &str) -> Option<(usize, &str)> {
            lookup(name).map(|(_, key)| (key.index, key.head))
        }
        assert_eq!(matches("agg.output_list.3"), Some((3, "")));
        assert_eq!(matches("dbg.gs_head.resize.2"), Some((2, "gs_head")));
        assert_eq!(matches("instance_head.raw"), Some((0, "instance_head")));
        assert_eq!(matches("render.static_opacity_at_frame.1"), Some((1, "")));
        assert_eq!(matches("lifespan.frame0_at_t2"), Some((0, "")));
        assert!(matches("render").is_none());
        assert!(matches("agg.output_list.x").is_none());
        assert!(matches("agg.output_list.1.2").is_none());
        assert!(matches("track_head.raw").is_none());
        assert!(matches("something_new").is_none());
    }
}
