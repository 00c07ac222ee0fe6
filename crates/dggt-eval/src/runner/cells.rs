//! Depth and motion scored at a view's lidar cells: the cells paired with the render (positive lidar depth, no
//! sky, inside the view), the aligned depth RMSE over them (split into the cells at depth edges and the rest, and
//! of the median depth beside the expected one), and the scene-flow metrics of a predicted flow against the
//! export's.

use std::path::Path;

use dggt_data::{DepthFlowMap, images};
use dggt_geom::ImageSize;
use dggt_geom::glam::DMat3;
use dggt_metrics::{FlowMetrics, MetricError, aligned_depth_rmse, scene_flow_metrics};

use crate::error::EvalError;
use crate::grid::{CellMapping, DEPTH_EDGE_SPAN, cell_has_sky, depth_span};
use crate::motion::{InputFlow, metres_per_unit};
use crate::report::{DepthParts, ViewRecord};

/// The depths of one rendered view, each `[H, W]` row-major: the expected depth (scored as D-RMSE and AbsRel),
/// the median depth (the surface each pixel sees) and each pixel's 3x3 span of the expected depth.
pub(super) struct RenderedDepth {
    expected: Vec<f32>,
    median: Vec<f32>,
    span: Vec<f32>,
}

impl RenderedDepth {
    pub(super) fn new(expected: Vec<f32>, median: Vec<f32>, size: ImageSize) -> Self {
        let span = depth_span(&expected, size.width as usize, size.height as usize);
        Self { expected, median, span }
    }
}

/// The scored cells of one view: rendered depth, lidar depth and true flow, paired, and at an input view of a
/// moving reconstruction the expected flow of its pixels ([`InputFlow::planes`]).
#[derive(Debug, Default)]
pub(super) struct Cells {
    predicted_depth: Vec<f32>,
    median_depth: Vec<f32>,
    at_edge: Vec<bool>,
    true_depth: Vec<f32>,
    true_flow: Vec<[f32; 3]>,
    predicted_flow: Vec<[f32; 3]>,
}

/// Whether the scene's scored cells carry depth and flow, and the longest true flow among them.
#[derive(Debug, Default)]
pub(super) struct FlowSeen {
    pub(super) has_depth_flow: bool,
    pub(super) largest_flow: f64,
}

/// What the predicted flow at a view's cells is.
#[derive(Clone, Copy)]
pub(super) enum CellFlow<'a> {
    /// Zero everywhere: nothing moves.
    Held,
    /// Not known at this view (no time base).
    Unscored,
    /// Sampled from `planes` (an input view's, or the rendered flow of a view between them), in `flow`'s units,
    /// and brought into the log world's axes by `log_from_world`.
    Sampled { flow: &'a InputFlow, planes: &'a [Vec<f32>; 3], log_from_world: DMat3 },
}

/// Pairs the rendered depth (and the flow `planes`, when given) with the lidar cells of `map` that are not sky
/// and fall inside the view.
pub(super) fn collect_cells(
    map: &DepthFlowMap,
    sky: Option<&[u8]>,
    original: ImageSize,
    mapping: &CellMapping,
    depth: &RenderedDepth,
    planes: Option<&[Vec<f32>; 3]>,
) -> Cells {
    let mut cells = Cells::default();
    let (grid_w, grid_h) = (map.size.width as usize, map.size.height as usize);
    let (w, h) = (original.width as usize, original.height as usize);
    for row in 0..grid_h {
        for col in 0..grid_w {
            let i = row * grid_w + col;
            if map.depth[i] <= 0.0 || sky.is_some_and(|mask| cell_has_sky(mask, w, h, row, col)) {
                continue;
            }
            if let Some(predicted) = mapping.sample(&depth.expected, row, col) {
                cells.predicted_depth.push(predicted);
                cells.median_depth.push(mapping.sample(&depth.median, row, col).unwrap_or(predicted));
                cells.at_edge.push(mapping.sample(&depth.span, row, col).is_some_and(|span| span > DEPTH_EDGE_SPAN));
                cells.true_depth.push(map.depth[i]);
                if let Some(flow) = &map.flow {
                    cells.true_flow.push(flow[i]);
                }
                if let Some(planes) = planes {
                    let axis = |a: usize| mapping.sample(&planes[a], row, col).unwrap_or(0.0);
                    cells.predicted_flow.push([axis(0), axis(1), axis(2)]);
                }
            }
        }
    }
    cells
}

/// The export's sky mask of a view at its original size, if it has one.
pub(super) fn read_sky_mask(path: Option<&Path>, original: ImageSize) -> Result<Option<Vec<u8>>, EvalError> {
    let Some(path) = path else { return Ok(None) };
    let mask = images::read_gray(path)?;
    images::expect_size(path, ImageSize { width: mask.width(), height: mask.height() }, original)?;
    Ok(Some(mask.into_raw()))
}

/// D-RMSE of `cells` into `record` (with its parts), and the longest true flow among them into `seen`.
pub(super) fn score_depth(record: &mut ViewRecord, cells: &Cells, seen: &mut FlowSeen) -> Result<(), EvalError> {
    record.depth_cells = cells.true_depth.len();
    match aligned_depth_rmse(&cells.predicted_depth, &cells.true_depth) {
        Ok(alignment) => {
            record.d_rmse = Some(alignment.rmse);
            record.abs_rel = Some(alignment.abs_rel);
            record.depth_scale = Some(alignment.scale);
            record.depth_shift = Some(alignment.shift);
            let median = aligned_depth_rmse(&cells.median_depth, &cells.true_depth)?;
            let part = |edge: bool| {
                let paired = cells.predicted_depth.iter().zip(&cells.true_depth).zip(&cells.at_edge);
                alignment.abs_rel_of(paired.filter(|(_, at)| **at == edge).map(|((&p, &g), _)| (p, g)))
            };
            let edges = cells.at_edge.iter().filter(|at| **at).count();
            record.depth_parts = Some(DepthParts {
                abs_rel_at_edges: part(true),
                abs_rel_elsewhere: part(false),
                edge_fraction: Some(edges as f64 / cells.at_edge.len() as f64),
                median_d_rmse: Some(median.rmse),
                median_abs_rel: Some(median.abs_rel),
            });
        }
        Err(MetricError::Empty { .. }) => {
            record.depth_note = Some("no lidar cell outside the sky inside the view".into());
        }
        Err(other) => return Err(other.into()),
    }
    let longest =
        cells.true_flow.iter().map(|f| f.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max);
    seen.largest_flow = seen.largest_flow.max(longest);
    Ok(())
}

/// The scene-flow metrics of `cells` under `predicted`; a sampled flow is brought to metres by the view's depth
/// scale ([`metres_per_unit`]; not scored without one). `None` without true flow or a prediction.
pub(super) fn score_flow(cells: &Cells, predicted: CellFlow<'_>) -> Result<Option<FlowMetrics>, EvalError> {
    if cells.true_flow.is_empty() {
        return Ok(None);
    }
    let predicted: Option<Vec<[f32; 3]>> = match predicted {
        CellFlow::Held => Some(vec![[0.0; 3]; cells.true_flow.len()]),
        CellFlow::Unscored => None,
        CellFlow::Sampled { flow, log_from_world, .. } => metres_per_unit(&cells.predicted_depth, &cells.true_depth)
            .map(|scale| {
                cells.predicted_flow.iter().map(|&f| flow.in_export_units(f, log_from_world, scale)).collect()
            }),
    };
    predicted.map(|predicted| scene_flow_metrics(&predicted, &cells.true_flow)).transpose().map_err(Into::into)
}
