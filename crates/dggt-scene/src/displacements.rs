//! The flow head's displacements as the per-pixel Gaussians carry them ([`LearntFlow`]): every row's
//! displacement to the next and to the previous input time of its rig camera, and how a view's rows move along
//! them at a target time ([`LearntStep`]). [`crate::learnt`] runs the head and fills them in; assembly moves the
//! dynamic Gaussians along them. Displacements are world vectors in the reconstruction's units.

use burn::tensor::Tensor;

/// Every row's displacement to the neighbouring input times of its rig camera.
#[derive(Debug, Clone)]
pub struct LearntFlow {
    /// `[M, 3]`: to the next input time of the row's camera (zero for rows that were not queries and for a
    /// camera's last input).
    pub to_next: Tensor<2>,
    /// `[M, 3]`: to the previous input time (zero likewise, and for a camera's first input).
    pub to_previous: Tensor<2>,
    pub(crate) host_next: Vec<[f32; 3]>,
    pub(crate) host_previous: Vec<[f32; 3]>,
    /// Per row, whether the head moved it to the next input (it was a query of a pair that ran).
    pub(crate) moved_next: Vec<bool>,
    /// Per row, whether the head moved it to the previous input.
    pub(crate) moved_previous: Vec<bool>,
    /// Per view, the times of the previous and the next input of its camera, when there are.
    pub(crate) neighbours: Vec<(Option<f64>, Option<f64>)>,
}

/// Which way a displacement goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Towards {
    Next,
    Previous,
}

/// How far along its learnt displacement a view's rows are at a target time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LearntStep {
    pub towards: Towards,
    /// `w` in `mu + w F`.
    pub fraction: f32,
    /// `dw / dt` per unit of scene time (negative towards the previous input): the rows' velocity is `F` times it.
    pub rate: f32,
}

impl LearntFlow {
    /// How view `view` (at `view_time`) moves its rows to `time`: the direction and the fraction `w` of the
    /// step, or `None` where they do not move (the view's own time, or outside its camera's inputs).
    pub(crate) fn step(&self, view: usize, view_time: f64, time: f64) -> Option<LearntStep> {
        let step = |towards, span: f64, elapsed: f64, sign: f64| LearntStep {
            towards,
            fraction: (elapsed / span) as f32,
            rate: (sign / span) as f32,
        };
        match self.neighbours[view] {
            (_, Some(next)) if time > view_time => Some(step(Towards::Next, next - view_time, time - view_time, 1.0)),
            (Some(previous), _) if time < view_time => {
                Some(step(Towards::Previous, view_time - previous, view_time - time, -1.0))
            }
            _ => None,
        }
    }

    pub(crate) fn host(&self, towards: Towards) -> &[[f32; 3]] {
        match towards {
            Towards::Next => &self.host_next,
            Towards::Previous => &self.host_previous,
        }
    }

    pub(crate) fn tensor(&self, towards: Towards) -> &Tensor<2> {
        match towards {
            Towards::Next => &self.to_next,
            Towards::Previous => &self.to_previous,
        }
    }

    /// How view `view` (at `time`) reads its rows' velocity off the flow: `v = c_next F_next + c_previous
    /// F_previous` per unit of scene time, from the displacement to the next input, else (a camera's last input)
    /// from the one from the previous input; `None` for a camera with one input.
    pub(crate) fn velocity_rule(&self, view: usize, time: f64) -> Option<(Towards, [f32; 2])> {
        match self.neighbours[view] {
            (_, Some(next)) => Some((Towards::Next, [(1.0 / (next - time)) as f32, 0.0])),
            (Some(previous), None) => Some((Towards::Previous, [0.0, (-1.0 / (time - previous)) as f32])),
            (None, None) => None,
        }
    }

    pub(crate) fn moved(&self, towards: Towards) -> &[bool] {
        match towards {
            Towards::Next => &self.moved_next,
            Towards::Previous => &self.moved_previous,
        }
    }
}

/// Every row's velocity under the learnt flow as a tensor gradients flow through
/// ([`PixelGaussians::learnt_velocity`](crate::PixelGaussians::learnt_velocity)).
#[derive(Debug, Clone)]
pub struct LearntVelocity {
    /// `[M, 3]` world units per unit of scene time (zero where the head did not move the row).
    pub velocity: Tensor<2>,
    /// Per row, whether the head gave it the displacement its velocity is read from: only these rows say
    /// anything about the head.
    pub measured: Vec<bool>,
}
