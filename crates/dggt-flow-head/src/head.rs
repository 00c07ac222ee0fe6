//! The flow head: the displacement of each query point of time `ta` to time `tb`, refined by attention over its
//! neighbourhood in `tb`'s feature cloud.
//!
//! Each query carries a state (a `hidden`-wide token, initially its projected features) and a displacement
//! (initially zero: the point is held where it is). One refinement iteration:
//!
//! 1. the `k` nearest target points `j` of the query's current position `x_q = p_q + d_q` are found, on the host
//!    from the position read back, or on a CubeCL device where the points are ([`crate::neighbours`]); their rows
//!    are data, not part of the gradient;
//! 2. offsets `o_j = (p_j - x_q) / s` are measured in the target's spacing `s` ([`crate::scale`]);
//! 3. attention, per head: the query token is `state + enc_d(d_q / s)` (the iteration state), each key and value
//!    token is `proj(f_j) + enc_o(o_j)` (the neighbour's features and where it lies); the attended vector is the
//!    weighted values together with each head's weighted offset `sum_j a_j o_j` (the head's soft match);
//! 4. the state takes the attended vector as a residual (`state += merge(attended)`), and the update perceptron
//!    turns the state into a step of the displacement, `d_q += s * update(state)`.
//!
//! The attention is evaluated factored, which is the same arithmetic rearranged (every product is linear): the
//! features' keys and values `proj(f_j) W_k`, `proj(f_j) W_v` are projected once per target point rather than once
//! per neighbour and iteration; the offset encoding's last layer `fc2` is folded into the key and value matrices
//! (`W_2 W_k`, `W_2 W_v`, once per pass), so a neighbour's offset enters as its hidden encoding `g_j = GELU(fc1
//! o_j)` alone. A query's score of `g_j` is `g_j . (W_2 W_k)_h q_h` (the query turned back through the folded
//! matrix once per query and head), and its value share `(sum_j a_j g_j) (W_2 W_v)_h` (the weighted encodings
//! pooled first); the constant `b_2 W_k` of the keys cancels in the softmax and `b_2 W_v` adds to the values'
//! bias. Per neighbour this costs the encoding's first layer and a few dot products of `hidden` channels instead
//! of three `hidden x hidden` products. The per-neighbour sums run in [`crate::attention`]: fused on the CPU and on
//! CubeCL devices, tensor operations elsewhere. `tests/flow_head/attention.rs` checks them against the formulas above written
//! out.
//!
//! After each iteration a displacement longer than the diagonal of the box holding both clouds is shortened to it
//! along its direction (no match lies further; a head gone wrong stays within the scene), and left as it is
//! otherwise. The update's last layer starts at zero, so a fresh head predicts exactly zero displacement. Offsets
//! in, steps out, are in units of `s`, so scaling both clouds' points scales the displacement by the same factor.
//! Queries are processed in chunks of `chunk` rows ([`crate::FlowHeadShape`]); the result does not depend on the
//! chunking.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::attention::{self, AttentionKernel, AttentionTensors};
use crate::cloud::{CloudRole, FlowError, FrameCloud, read_rows};
use crate::config::{ConfigError, FlowHeadConfig, HeadInputs};
use crate::mlp::{Mlp, OutputInit};
use crate::neighbours::{NeighbourSearch, SearchPlace};
use crate::scale::ScaleSource;

/// The learnt scene-flow head `F(ta, tb)`; built by [`FlowHeadConfig::init`].
#[derive(Module, Debug)]
pub struct FlowHead {
    /// Features of either cloud into a token (one projection: both times' features live in the same space).
    pub feature_in: Linear,
    /// Encoding of the query's normalised displacement so far.
    pub state_in: Mlp,
    /// Encoding of a neighbour's normalised offset from the query.
    pub offset_in: Mlp,
    pub query: Linear,
    /// Without bias (it would cancel in the softmax).
    pub key: Linear,
    pub value: Linear,
    /// The attended values and per-head matched offsets into a residual of the state.
    pub merge: Linear,
    /// The state into a step of the normalised displacement; its last layer starts at zero.
    pub update: Mlp,
    feature_width: usize,
    heads: usize,
    neighbours: usize,
    iterations: usize,
    chunk: usize,
    #[module(skip)]
    inputs: HeadInputs,
}

/// One time's cloud prepared for the head, once for every pair it takes part in (as query or as target): shapes
/// and points checked, the points on the host and indexed, the features projected into tokens and into the
/// attention's keys and values. Built by [`FlowHead::prepare`].
pub struct PreparedCloud {
    points: Tensor<2>,
    host_points: Vec<[f32; 3]>,
    /// `None` for an empty cloud.
    projected: Option<Projected>,
}

/// What a non-empty prepared cloud holds beside its points.
struct Projected {
    /// `[N, hidden]`: the projected features, a query's initial state.
    tokens: Tensor<2>,
    /// `[N, 2 hidden]`: the keys then the values of the tokens (the values without their bias).
    keys_values: Tensor<2>,
    search: NeighbourSearch,
    /// Where the offsets' unit comes from when this cloud is the target.
    spacing: ScaleSource,
}

impl PreparedCloud {
    /// Rows (points).
    pub fn len(&self) -> usize {
        self.host_points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.host_points.is_empty()
    }
}

/// What every query chunk reads of the target cloud.
struct Target<'a> {
    points: Tensor<2>,
    /// `[Nt, 2 hidden]`: the keys then the values of the projected features (the values without their bias).
    keys_values: Tensor<2>,
    /// The offset encoding's last layer folded into the key and value matrices.
    folded: FoldedOffsets,
    search: &'a NeighbourSearch,
    /// Where the queries' neighbours are looked up: `search` on the host, or brute force on the device.
    place: SearchPlace,
    /// `[1]`: the spacing offsets are measured in.
    scale: Tensor<1>,
    /// Neighbours per query: the configured count, or every target point when there are fewer.
    k: usize,
    /// The longest displacement allowed: the diagonal of the box holding both clouds' points.
    extent: f32,
}

/// The offset encoding's last layer `fc2` (`W_2`, `b_2`) folded into the attention's key and value matrices, per
/// head: the neighbour's hidden encoding `g` enters the keys as `g W_2 W_k` and the values as `g W_2 W_v`.
struct FoldedOffsets {
    /// `[heads, width, hidden]`: head `h`'s block of `(W_2 W_k)^T`, turning its query into a weighting of `g`.
    key: Tensor<3>,
    /// `[heads, hidden, width]`: head `h`'s block of `W_2 W_v`, turning its pooled `g` into its value share.
    value: Tensor<3>,
    /// `[1, hidden]`: what every value carries whatever its neighbour, `b_2 W_v + b_v`.
    value_bias: Tensor<2>,
}

/// One chunk of queries during refinement.
struct Queries {
    points: Tensor<2>,
    host_points: Vec<[f32; 3]>,
    /// The chunk's first row in the query cloud (for errors).
    first_row: usize,
    state: Tensor<2>,
    displacement: Tensor<2>,
}

impl FlowHeadConfig {
    /// A fresh head on `device`: random weights, except the last layer of the update, which is zero, so that
    /// the head predicts no motion until it is trained.
    pub fn init(&self, device: &Device) -> Result<FlowHead, ConfigError> {
        self.validate()?;
        Ok(FlowHead::new(self, device))
    }
}

impl FlowHead {
    fn new(config: &FlowHeadConfig, device: &Device) -> Self {
        let shape = &config.shape;
        let hidden = shape.hidden;
        let linear = |input: usize, output: usize| LinearConfig::new(input, output).init(device);
        Self {
            feature_in: linear(config.feature_width(), hidden),
            state_in: Mlp::new(3, hidden, hidden, OutputInit::Random, device),
            offset_in: Mlp::new(3, hidden, hidden, OutputInit::Random, device),
            query: linear(hidden, hidden),
            // A key bias would shift all of a query's scores alike, which the softmax ignores.
            key: LinearConfig::new(hidden, hidden).with_bias(false).init(device),
            value: linear(hidden, hidden),
            merge: linear(hidden + 3 * shape.heads, hidden),
            update: Mlp::new(hidden, hidden, 3, OutputInit::Zero, device),
            feature_width: config.feature_width(),
            heads: shape.heads,
            neighbours: shape.neighbours,
            iterations: shape.iterations,
            chunk: shape.chunk,
            inputs: shape.inputs,
        }
    }

    /// `[Nq, 3]`: the displacement, in world units, of each query point from the query's time to the target's.
    /// Zero for every query when the target cloud is empty; `[0, 3]` for an empty query cloud. A cloud taking part
    /// in several pairs is better prepared once ([`Self::prepare`], [`Self::forward_prepared`]).
    pub fn forward(&self, query: &FrameCloud, target: &FrameCloud) -> Result<Tensor<2>, FlowError> {
        let query = self.prepare(query, CloudRole::Query)?;
        let target = self.prepare(target, CloudRole::Target)?;
        self.forward_prepared(&query, &target)
    }

    /// Checks `cloud` (its errors name it as `role`), reads its points and projects its features.
    pub fn prepare(&self, cloud: &FrameCloud, role: CloudRole) -> Result<PreparedCloud, FlowError> {
        cloud.check_shapes(role, self.feature_width)?;
        let host_points = cloud.host_points(role)?;
        let projected = (!cloud.is_empty()).then(|| {
            let tokens = self.feature_tokens(cloud.features.clone());
            let keys = tokens.clone().matmul(self.key.weight.val());
            let values = tokens.clone().matmul(self.value.weight.val());
            let search = NeighbourSearch::new(&host_points);
            let spacing = ScaleSource::of_target(&host_points, &search);
            Projected { tokens, keys_values: Tensor::cat(vec![keys, values], 1), search, spacing }
        });
        Ok(PreparedCloud { points: cloud.points.clone(), host_points, projected })
    }

    /// [`Self::forward`] on clouds prepared by this head.
    pub fn forward_prepared(&self, query: &PreparedCloud, target: &PreparedCloud) -> Result<Tensor<2>, FlowError> {
        let (Some(query_projected), Some(target_projected)) = (&query.projected, &target.projected) else {
            return Ok(query.points.zeros_like());
        };
        let target = Target {
            points: target.points.clone(),
            keys_values: target_projected.keys_values.clone(),
            folded: self.folded_offsets(),
            scale: target_projected.spacing.length(&query.points, &target.points),
            k: self.neighbours.min(target.len()),
            search: &target_projected.search,
            place: SearchPlace::for_points(&target.points),
            extent: extent(&query.host_points, &target.host_points),
        };
        let chunks = (0..query.len())
            .step_by(self.chunk)
            .map(|start| {
                let len = self.chunk.min(query.len() - start);
                let queries = Queries {
                    points: query.points.clone().narrow(0, start, len),
                    host_points: query.host_points[start..start + len].to_vec(),
                    first_row: start,
                    state: query_projected.tokens.clone().narrow(0, start, len),
                    displacement: Tensor::zeros([len, 3], (&query.points.device(), query.points.dtype())),
                };
                self.refine(&target, queries)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Tensor::cat(chunks, 0))
    }

    /// `[N, hidden]`: the points' projected features (`features` `[N, C]`), or the projection's bias alone when
    /// the head ignores them.
    fn feature_tokens(&self, features: Tensor<2>) -> Tensor<2> {
        match self.inputs {
            HeadInputs::FeaturesAndOffsets => self.feature_in.forward(features),
            HeadInputs::OffsetsOnly => self.feature_in.forward(features.zeros_like()),
        }
    }

    /// The chunk's displacement after every iteration. Every iteration's result but the last is checked finite:
    /// where the search runs on the host, as its positions are read back for the next search; where it runs on
    /// the device, all at once after the last iteration (one read-back of a flag per chunk, not one of the
    /// displacements per iteration), the same error either way.
    fn refine(&self, target: &Target, mut queries: Queries) -> Result<Tensor<2>, FlowError> {
        let mut positions = queries.host_points.clone();
        let mut unchecked = Vec::new();
        for iteration in 0..self.iterations {
            queries = self.step(target, queries, &positions);
            if iteration + 1 == self.iterations {
                break;
            }
            if target.place == SearchPlace::Host {
                positions = moved(&queries, iteration)?;
            } else {
                unchecked.push(queries.displacement.clone());
            }
        }
        check_finite(&unchecked, queries.first_row)?;
        Ok(queries.displacement)
    }

    /// One refinement iteration of the queries now at `host_positions` (on the host, as the device has them).
    fn step(&self, target: &Target, queries: Queries, host_positions: &[[f32; 3]]) -> Queries {
        let scale = target.scale.clone().reshape([1, 1]);
        let position = queries.points.clone() + queries.displacement.clone();
        let rows = neighbour_rows(target, host_positions, &position);
        let neighbourhood = self.neighbourhood(target, rows, position, scale.clone());
        let query = queries.state.clone() + self.state_in.forward(queries.displacement.clone() / scale.clone());
        let attended = self.attend(query, neighbourhood, target);
        let state = queries.state + self.merge.forward(attended);
        let displacement = capped(queries.displacement + self.update.forward(state.clone()) * scale, target.extent);
        Queries { state, displacement, ..queries }
    }

    /// `W_2` of the offset encoding folded into the key and value matrices, split by head.
    fn folded_offsets(&self) -> FoldedOffsets {
        let fc2 = &self.offset_in.fc2;
        let hidden = fc2.weight.dims()[0];
        let (heads, width) = (self.heads, hidden / self.heads);
        let value_weight = self.value.weight.val();
        let key = fc2.weight.val().matmul(self.key.weight.val()).reshape([hidden, heads, width]).permute([1, 2, 0]);
        let value = fc2.weight.val().matmul(value_weight.clone()).reshape([hidden, heads, width]).swap_dims(0, 1);
        let bias = |linear: &Linear| linear.bias.as_ref().map(|b| b.val().reshape([1, hidden]));
        let carried = bias(fc2).map(|b| b.matmul(value_weight));
        let value_bias = [carried, bias(&self.value)]
            .into_iter()
            .flatten()
            .fold(Tensor::zeros([1, hidden], &fc2.weight.device()), |sum, b| sum + b);
        FoldedOffsets { key, value, value_bias }
    }

    /// The neighbours at `rows` `[N, k]` of the queries at `position` `[N, 3]`: their rows and offsets
    /// `(p_j - x_q) / s`, `[N, k, 3]`.
    fn neighbourhood(
        &self,
        target: &Target,
        rows: Tensor<2, Int>,
        position: Tensor<2>,
        scale: Tensor<2>,
    ) -> Neighbourhood {
        let [n, k] = rows.dims();
        let neighbours = target.points.clone().select(0, rows.clone().reshape([n * k])).reshape([n, k, 3]);
        let offsets = (neighbours - position.unsqueeze_dim::<3>(1)) / scale.unsqueeze_dim::<3>(0);
        Neighbourhood { rows, offsets }
    }

    /// Multi-head attention of each query token `[N, hidden]` over its neighbourhood (factored, see the module's
    /// doc): `[N, hidden + 3 heads]`, the attended values, then each head's attention-weighted offset.
    fn attend(&self, query: Tensor<2>, neighbourhood: Neighbourhood, target: &Target) -> Tensor<2> {
        let [n, hidden] = query.dims();
        let (heads, width) = (self.heads, hidden / self.heads);
        let folded = &target.folded;
        let kernel = AttentionKernel::for_queries(&query, target.k, heads);
        // Scaled once here rather than every score.
        let q = self.query.forward(query).reshape([n, heads, width]) / (width as f64).sqrt();
        let turned = q.clone().swap_dims(0, 1).matmul(folded.key.clone()).swap_dims(0, 1);
        let encoder = &self.offset_in.fc1;
        let encoder_bias = match &encoder.bias {
            Some(bias) => bias.val(),
            None => Tensor::zeros([hidden], &q.device()),
        };
        let inputs = AttentionTensors {
            offsets: neighbourhood.offsets,
            rows: neighbourhood.rows,
            keys_values: target.keys_values.clone(),
            encoder_weight: encoder.weight.val(),
            encoder_bias,
            queries: q,
            turned,
        };
        let attended = attention::attend(inputs, kernel);
        let offset_values = attended.pooled.swap_dims(0, 1).matmul(folded.value.clone()).swap_dims(0, 1);
        let values = (attended.values + offset_values).reshape([n, hidden]) + folded.value_bias.clone();
        Tensor::cat(vec![values, attended.matched.reshape([n, 3 * heads])], 1)
    }
}

/// One query chunk's neighbourhood, `k` target points per query.
struct Neighbourhood {
    /// `[N, k]`: the neighbours' target rows.
    rows: Tensor<2, Int>,
    /// `[N, k, 3]`: offsets `(p_j - x_q) / s`.
    offsets: Tensor<3>,
}

/// `[N, k]`: the rows of the `k` target points nearest each query, looked up where the target's points are
/// searched ([`SearchPlace`]): on the device from `position` `[N, 3]`, or on the host from `host_positions`.
fn neighbour_rows(target: &Target, host_positions: &[[f32; 3]], position: &Tensor<2>) -> Tensor<2, Int> {
    match target.place {
        #[cfg(any(feature = "wgpu", feature = "cuda"))]
        SearchPlace::Device => crate::neighbours::device::k_nearest(position.clone(), target.points.clone(), target.k),
        SearchPlace::Host => {
            let rows = target.search.k_nearest(host_positions, target.k);
            let data = TensorData::new(rows.into_iter().map(|r| r as i64).collect(), [host_positions.len(), target.k]);
            Tensor::from_data(data, &position.device())
        }
    }
}

/// `displacement` `[N, 3]` with each row no longer than `limit`: rows within it unchanged (and their gradient), longer
/// ones shortened to it along their direction.
fn capped(displacement: Tensor<2>, limit: f32) -> Tensor<2> {
    // `1 / sqrt(max(|d|^2 / limit^2, 1))`: exactly 1 within the limit, where the maximum passes no gradient (and
    // no square root of zero is differentiated).
    let relative = displacement.clone().powi_scalar(2).sum_dim(1).div_scalar(limit * limit);
    displacement * relative.clamp_min(1.0).sqrt().recip()
}

/// The diagonal of the axis-aligned box holding every point of both clouds; at least 1e-18 (coincident points),
/// so that its square is a normal float.
fn extent(query: &[[f32; 3]], target: &[[f32; 3]]) -> f32 {
    let (mut low, mut high) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for point in query.iter().chain(target) {
        for axis in 0..3 {
            low[axis] = low[axis].min(point[axis]);
            high[axis] = high[axis].max(point[axis]);
        }
    }
    let diagonal = (0..3).map(|axis| (high[axis] - low[axis]).powi(2)).sum::<f32>().sqrt();
    diagonal.max(1e-18)
}

/// The chunk's current positions `p_q + d_q` on the host, refused if a displacement is not finite.
fn moved(queries: &Queries, iteration: usize) -> Result<Vec<[f32; 3]>, FlowError> {
    let displacement = read_displacement(queries.displacement.clone())?;
    refuse_non_finite(&displacement, queries.first_row, iteration)?;
    Ok(queries.host_points.iter().zip(&displacement).map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]]).collect())
}

/// Checks the displacements of the first iterations of a chunk starting at `first_row`, one per entry of
/// `iterations`, on their device: one flag read back, and each iteration's rows only when it is raised (to name the
/// first row and iteration that is not finite).
fn check_finite(iterations: &[Tensor<2>], first_row: usize) -> Result<(), FlowError> {
    if iterations.is_empty() {
        return Ok(());
    }
    let finite = Tensor::cat(iterations.to_vec(), 0).is_finite().all();
    let finite = finite
        .try_into_vec_as::<bool>()
        .map_err(|e| FlowError::Readback { cloud: CloudRole::Query, reason: e.to_string() })?;
    if finite.iter().all(|&flag| flag) {
        return Ok(());
    }
    for (iteration, displacement) in iterations.iter().enumerate() {
        refuse_non_finite(&read_displacement(displacement.clone())?, first_row, iteration)?;
    }
    Ok(())
}

/// A chunk's displacements `[N, 3]` on the host.
fn read_displacement(displacement: Tensor<2>) -> Result<Vec<[f32; 3]>, FlowError> {
    read_rows(displacement).map_err(|reason| FlowError::Readback { cloud: CloudRole::Query, reason })
}

/// The error naming the first row (counted in the whole query cloud) of `displacement` that is not finite.
fn refuse_non_finite(displacement: &[[f32; 3]], first_row: usize, iteration: usize) -> Result<(), FlowError> {
    match displacement.iter().position(|d| !d.iter().all(|v| v.is_finite())) {
        Some(row) => Err(FlowError::NonFiniteDisplacement { row: first_row + row, iteration }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::FlowHeadShape;

    fn rows(values: &[f32]) -> Tensor<2> {
        Tensor::from_data(TensorData::new(values.to_vec(), [values.len() / 3, 3]), &Device::flex())
    }

    #[test]
    fn the_check_of_all_iterations_names_the_first_bad_row_and_iteration() {
        let finite = rows(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(check_finite(&[], 0), Ok(()));
        assert_eq!(check_finite(&[finite.clone(), finite.clone()], 0), Ok(()));
        let infinite_second = rows(&[0.0, 1.0, 2.0, 3.0, f32::INFINITY, 5.0]);
        let nan_first = rows(&[f32::NAN, 1.0, 2.0, 3.0, 4.0, 5.0]);
        let error = check_finite(&[finite, infinite_second.clone(), nan_first.clone()], 16);
        assert_eq!(error, Err(FlowError::NonFiniteDisplacement { row: 17, iteration: 1 }));
        let error = check_finite(&[nan_first, infinite_second], 0);
        assert_eq!(error, Err(FlowError::NonFiniteDisplacement { row: 0, iteration: 0 }));
    }

    #[test]
    fn an_invalid_configuration_builds_no_head() {
        let shape = FlowHeadShape { heads: 5, ..FlowHeadShape::default() };
        assert!(FlowHeadConfig { shape, ..FlowHeadConfig::default() }.init(&Device::flex()).is_err());
    }
}
