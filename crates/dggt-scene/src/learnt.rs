//! The learnt scene flow carried by the per-pixel Gaussians: for every rig camera and every pair of its adjacent
//! input views `a` (time `ta`) and `b` (time `tb > ta`), the flow head's displacement `F(ta, tb)` of each dynamic
//! pixel of `a` to time `tb`, and `F(tb, ta)` of each dynamic pixel of `b` back to `ta`.
//!
//! Between the inputs a dynamic Gaussian of view `a` is drawn at `mu + w F(ta, tb)`, `w = (t - ta) / (tb - ta)`,
//! one of view `b` at `mu + w' F(tb, ta)`, `w' = (tb - t) / (tb - ta)`: at an input's own time `w = 0` and the
//! Gaussians are the input's exactly. Outside the span of a camera's inputs nothing moves (there is no flow to
//! extrapolate from). Displacements are world vectors in the reconstruction's units.
//!
//! Queries are the dynamic pixels (probability at least one half, as for the instances), their points the
//! Gaussian means (the head sees the scene the renders see) and their features the Gaussian head's maps at the pixels; a pair in
//! which either view has no dynamic pixel does not run the head (its rows keep zero flow).

use burn::tensor::{IndexingUpdateOp, Int, Tensor, TensorData};
use dggt_flow_head::{CloudRole, FlowHead, FrameCloud, PixelIndex, PreparedCloud, sample_features};
use dggt_model::host::host_f32;

use crate::displacements::{LearntFlow, LearntVelocity};
use crate::error::SceneError;
use crate::pixels::PixelGaussians;

/// The dynamic logit from which a pixel is a query of the flow head (probability one half). A fresh network's
/// dynamic head marks no pixel: the head learns once the dynamic head has found the moving objects.
pub const QUERY_LOGIT: f32 = 0.0;

impl PixelGaussians {
    /// Runs the flow head on every pair of adjacent input views of each rig camera (`features`: the Gaussian
    /// head's maps, `[S, C, h, w]` per scale, frames in the views' order) and keeps the displacements
    /// ([`LearntFlow`]). Without a dynamic head nothing is queried and every row keeps zero flow.
    pub fn with_learnt_flow(self, head: &FlowHead, features: &[Tensor<4>]) -> Result<Self, SceneError> {
        let per_view = self.per_view();
        let queries: Vec<Vec<PixelIndex>> = match &self.dynamic_logit {
            Some(logit) => {
                let logits = host_f32(logit.clone(), "dynamic logit")?;
                logits.chunks(per_view).map(|view| query_pixels(view, self.size.width as usize)).collect()
            }
            None => vec![Vec::new(); self.views.len()],
        };
        tracing::debug!(queries = ?queries.iter().map(Vec::len).collect::<Vec<_>>(), "learnt flow");
        let mut next_parts = Vec::new();
        let mut previous_parts = Vec::new();
        let pairs: Vec<(usize, usize)> = adjacent_views(&self.views)
            .into_iter()
            .filter(|&(a, b)| !queries[a].is_empty() && !queries[b].is_empty())
            .collect();
        // Each view's cloud is built and prepared once, for both of its pairs and both roles.
        let mut clouds: Vec<Option<(PreparedCloud, Tensor<1, Int>)>> = (0..self.views.len()).map(|_| None).collect();
        for view in pairs.iter().flat_map(|&(a, b)| [a, b]) {
            if clouds[view].is_none() {
                let (cloud, rows) = self.cloud(view, &queries[view], features)?;
                clouds[view] = Some((head.prepare(&cloud, CloudRole::View(view))?, rows));
            }
        }
        let mut moved_rows = [vec![false; self.len()], vec![false; self.len()]];
        for (a, b) in pairs {
            if let (Some((cloud_a, rows_a)), Some((cloud_b, rows_b))) = (&clouds[a], &clouds[b]) {
                next_parts.push((rows_a.clone(), head.forward_prepared(cloud_a, cloud_b)?));
                previous_parts.push((rows_b.clone(), head.forward_prepared(cloud_b, cloud_a)?));
                for (moved, view) in moved_rows.iter_mut().zip([a, b]) {
                    queries[view].iter().for_each(|p| moved[self.row(view, *p)] = true);
                }
            }
        }
        let (to_next, to_previous) = (self.scattered(next_parts), self.scattered(previous_parts));
        self.with_known_learnt_flow(to_next, to_previous, Some(moved_rows))
    }

    /// Keeps `to_next` and `to_previous` (`[M, 3]`, as [`LearntFlow`] holds them) as the learnt flow: the flow
    /// head's, a saved scene's, or displacements known otherwise. `moved`: the rows the head moved to the next
    /// and to the previous input; without it (a saved scene) the rows with a non-zero displacement count.
    /// Non-finite displacements are an error naming the view and pixel.
    pub fn with_known_learnt_flow(
        mut self,
        to_next: Tensor<2>,
        to_previous: Tensor<2>,
        moved: Option<[Vec<bool>; 2]>,
    ) -> Result<Self, SceneError> {
        let host_next = self.checked_rows(&to_next, "learnt flow to the next input")?;
        let host_previous = self.checked_rows(&to_previous, "learnt flow to the previous input")?;
        let nonzero = |rows: &[[f32; 3]]| rows.iter().map(|d| d.iter().any(|&v| v != 0.0)).collect();
        let [moved_next, moved_previous] = moved.unwrap_or_else(|| [nonzero(&host_next), nonzero(&host_previous)]);
        let mut neighbours = vec![(None, None); self.views.len()];
        for (a, b) in adjacent_views(&self.views) {
            neighbours[a].1 = Some(self.views[b].time);
            neighbours[b].0 = Some(self.views[a].time);
        }
        let flow =
            LearntFlow { to_next, to_previous, host_next, host_previous, moved_next, moved_previous, neighbours };
        self.learnt = Some(std::sync::Arc::new(flow));
        Ok(self)
    }

    /// The flow found by [`PixelGaussians::with_learnt_flow`].
    pub fn learnt(&self) -> Option<&LearntFlow> {
        self.learnt.as_deref()
    }

    /// Every row's velocity at its own view's time under the learnt flow (world units per unit of scene time):
    /// its displacement to the next input over the step's time, else (a camera's last input) the displacement
    /// from the previous input; zero without either. `None` without a learnt flow.
    pub fn learnt_velocities(&self) -> Option<Vec<[f32; 3]>> {
        let flow = self.learnt()?;
        let per_view = self.per_view();
        let velocity = |row: usize| -> [f32; 3] {
            let view = row / per_view;
            match flow.velocity_rule(view, self.views[view].time) {
                Some((_, [c_next, c_previous])) => {
                    std::array::from_fn(|i| c_next * flow.host_next[row][i] + c_previous * flow.host_previous[row][i])
                }
                None => [0.0; 3],
            }
        };
        Some((0..self.len()).map(velocity).collect())
    }

    /// The velocities of [`Self::learnt_velocities`] as a tensor the gradient flows through, with the rows the
    /// head measured (what a supervision of the head compares); `None` without a learnt flow.
    pub fn learnt_velocity(&self) -> Option<LearntVelocity> {
        let flow = self.learnt()?;
        let per_view = self.per_view();
        let mut coefficients = Vec::with_capacity(2 * self.len());
        let mut measured = Vec::with_capacity(self.len());
        for (view, input) in self.views.iter().enumerate() {
            let rule = flow.velocity_rule(view, input.time);
            let [c_next, c_previous] = rule.map_or([0.0; 2], |(_, c)| c);
            for row in view * per_view..(view + 1) * per_view {
                coefficients.extend([c_next, c_previous]);
                measured.push(rule.is_some_and(|(towards, _)| flow.moved(towards)[row]));
            }
        }
        let coefficients = Tensor::<2>::from_data(TensorData::new(coefficients, [self.len(), 2]), &self.means.device());
        let [c_next, c_previous] = [0, 1].map(|i| coefficients.clone().slice([0..self.len(), i..i + 1]));
        let velocity = flow.to_next.clone() * c_next + flow.to_previous.clone() * c_previous;
        Some(LearntVelocity { velocity, measured })
    }

    /// View `view`'s query pixels as a cloud (means and features) and their rows.
    fn cloud(
        &self,
        view: usize,
        pixels: &[PixelIndex],
        features: &[Tensor<4>],
    ) -> Result<(FrameCloud, Tensor<1, Int>), SceneError> {
        let rows: Vec<i64> = pixels.iter().map(|p| self.row(view, *p) as i64).collect();
        let rows = Tensor::<1, Int>::from_data(TensorData::new(rows, [pixels.len()]), &self.means.device());
        let points = self.means.clone().select(0, rows.clone());
        let features = sample_features(features, view, self.size, pixels)?;
        Ok((FrameCloud::new(points, features), rows))
    }

    /// The row of `view`'s pixel `pixel`.
    fn row(&self, view: usize, pixel: PixelIndex) -> usize {
        view * self.per_view() + pixel.row * self.size.width as usize + pixel.col
    }

    /// `[M, 3]` with each part's displacements at its rows and zeros elsewhere.
    fn scattered(&self, parts: Vec<(Tensor<1, Int>, Tensor<2>)>) -> Tensor<2> {
        let zeros = Tensor::<2>::zeros([self.len(), 3], &self.means.device());
        if parts.is_empty() {
            return zeros;
        }
        let (rows, values): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
        zeros.select_assign(0, Tensor::cat(rows, 0), Tensor::cat(values, 0), IndexingUpdateOp::Add)
    }

    /// The host copy of `[M, 3]` rows, checked to be of this scene's size and finite.
    fn checked_rows(&self, flow: &Tensor<2>, what: &'static str) -> Result<Vec<[f32; 3]>, SceneError> {
        if flow.dims() != [self.len(), 3] {
            let expected = format!("[{}, 3]", self.len());
            return Err(SceneError::Shape { tensor: what, expected, actual: flow.dims().to_vec() });
        }
        let host = host_f32(flow.clone(), what)?;
        if let Some(i) = host.iter().position(|v| !v.is_finite()) {
            let per_view = self.per_view();
            return Err(SceneError::NonFinite {
                tensor: what,
                value: host[i],
                view: i / 3 / per_view,
                pixel: i / 3 % per_view,
            });
        }
        Ok(host.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect())
    }
}

/// The pixels of one view's logits (row-major, `width` wide) that the flow head queries.
fn query_pixels(logits: &[f32], width: usize) -> Vec<PixelIndex> {
    logits
        .iter()
        .enumerate()
        .filter(|&(_, &logit)| logit >= QUERY_LOGIT)
        .map(|(i, _)| PixelIndex { row: i / width, col: i % width })
        .collect()
}

/// Each rig camera's views in time order, as pairs of adjacent views `(earlier, later)` (indices into `views`).
pub(crate) fn adjacent_views(views: &[crate::timeline::InputView]) -> Vec<(usize, usize)> {
    let mut cameras: Vec<usize> = views.iter().map(|v| v.rig_camera).collect();
    cameras.sort_unstable();
    cameras.dedup();
    let mut pairs = Vec::new();
    for camera in cameras {
        let mut of_camera: Vec<usize> = (0..views.len()).filter(|&v| views[v].rig_camera == camera).collect();
        of_camera.sort_by(|&a, &b| views[a].time.total_cmp(&views[b].time));
        pairs.extend(of_camera.windows(2).filter(|w| views[w[0]].time < views[w[1]].time).map(|w| (w[0], w[1])));
    }
    pairs
}
